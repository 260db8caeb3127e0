//! Disjoint sets with union by size and path halving, tracking the
//! Felzenszwalb–Huttenlocher merge threshold of every component.

#[derive(Debug, Clone, Default)]
pub struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
    /// Int(C) + k/|C| of each root: the weight an edge may have to merge.
    threshold: Vec<f32>,
}

impl UnionFind {
    /// `n` singletons, each with merge threshold `k` (Int = 0, |C| = 1).
    pub fn reset(&mut self, n: usize, k: f32) {
        self.parent.clear();
        self.parent.extend(0..n as u32);
        self.size.clear();
        self.size.resize(n, 1);
        self.threshold.clear();
        self.threshold.resize(n, k);
    }

    pub fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grand = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grand;
            x = grand;
        }
        x
    }

    pub fn size(&self, root: u32) -> u32 {
        self.size[root as usize]
    }

    pub fn threshold(&self, root: u32) -> f32 {
        self.threshold[root as usize]
    }

    /// Joins two roots; returns the new root.
    pub fn union(&mut self, a: u32, b: u32) -> u32 {
        let (big, small) = if self.size[a as usize] >= self.size[b as usize] {
            (a, b)
        } else {
            (b, a)
        };
        self.parent[small as usize] = big;
        self.size[big as usize] += self.size[small as usize];
        big
    }

    /// Joins the sets of any two elements; returns the root, and whether they were apart.
    pub fn join(&mut self, a: u32, b: u32) -> (u32, bool) {
        let (ra, rb) = (self.find(a), self.find(b));
        match ra == rb {
            true => (ra, false),
            false => (self.union(ra, rb), true),
        }
    }

    pub fn set_threshold(&mut self, root: u32, value: f32) {
        self.threshold[root as usize] = value;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unions_and_sizes() {
        let mut uf = UnionFind::default();
        uf.reset(5, 1.0);
        let r = uf.union(0, 1);
        let r3 = uf.find(3);
        let r2 = uf.union(r3, r);
        assert_eq!(uf.find(3), uf.find(0));
        assert_eq!(uf.size(r2), 3);
        assert_ne!(uf.find(2), uf.find(0));
        let r4 = uf.find(4);
        assert_eq!(uf.threshold(r4), 1.0);
        // `join` takes any elements: 2 and 4 join through their roots, and 3 stays with 0.
        assert!(uf.join(2, 4).1);
        assert!(uf.join(4, 1).1);
        assert!(!uf.join(3, 2).1);
        assert_eq!(uf.find(3), uf.find(0));
    }
}
