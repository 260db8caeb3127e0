//! Per-parameter arrays shaped like a [`GaussianMap`]: gradients, and Adam's moments.

use crate::map::GaussianMap;

/// One value per optimised parameter of every Gaussian (labels are not optimised).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MapGrads {
    pub means: Vec<[f32; 3]>,
    /// w.r.t. the stored (w, x, y, z) quaternion.
    pub rotations: Vec<[f32; 4]>,
    pub log_scales: Vec<[f32; 3]>,
    pub opacity_logits: Vec<f32>,
    pub sh_dc: Vec<[f32; 3]>,
}

impl MapGrads {
    /// Zeros for `n` Gaussians.
    pub fn zeros(n: usize) -> Self {
        let mut g = Self::default();
        g.reset(n);
        g
    }

    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Sets to `n` zeros, keeping allocations.
    pub fn reset(&mut self, n: usize) {
        fn zero<T: Copy + Default>(v: &mut Vec<T>, n: usize) {
            v.clear();
            v.resize(n, T::default());
        }
        zero(&mut self.means, n);
        zero(&mut self.rotations, n);
        zero(&mut self.log_scales, n);
        zero(&mut self.opacity_logits, n);
        zero(&mut self.sh_dc, n);
    }

    /// Grows (with zeros) or shrinks to `n` Gaussians, keeping the first entries.
    pub fn resize(&mut self, n: usize) {
        self.means.resize(n, [0.0; 3]);
        self.rotations.resize(n, [0.0; 4]);
        self.log_scales.resize(n, [0.0; 3]);
        self.opacity_logits.resize(n, 0.0);
        self.sh_dc.resize(n, [0.0; 3]);
    }

    /// Applies an old→new index map (as [`GaussianMap::remove_where`] returns): entry i
    /// moves to `old_to_new[i]`, `None` entries are dropped.
    pub fn compact(&mut self, old_to_new: &[Option<u32>]) {
        assert_eq!(
            old_to_new.len(),
            self.len(),
            "index map length must equal length"
        );
        fn apply<T: Copy>(v: &mut Vec<T>, old_to_new: &[Option<u32>]) {
            let mut n = 0;
            for (i, slot) in old_to_new.iter().enumerate() {
                if let Some(j) = slot {
                    v[*j as usize] = v[i];
                    n = n.max(*j as usize + 1);
                }
            }
            v.truncate(n);
        }
        apply(&mut self.means, old_to_new);
        apply(&mut self.rotations, old_to_new);
        apply(&mut self.log_scales, old_to_new);
        apply(&mut self.opacity_logits, old_to_new);
        apply(&mut self.sh_dc, old_to_new);
    }

    /// Euclidean norm over all entries (for logging and tests).
    pub fn norm(&self) -> f64 {
        let sq = |v: &[f32]| v.iter().map(|&x| (x as f64) * (x as f64)).sum::<f64>();
        (sq(self.means.as_flattened())
            + sq(self.rotations.as_flattened())
            + sq(self.log_scales.as_flattened())
            + sq(&self.opacity_logits)
            + sq(self.sh_dc.as_flattened()))
        .sqrt()
    }

    /// True when this buffer has one entry per Gaussian of `map`.
    pub fn matches(&self, map: &GaussianMap) -> bool {
        self.len() == map.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compact_follows_remove_where_order() {
        let mut g = MapGrads::zeros(4);
        for i in 0..4 {
            g.opacity_logits[i] = i as f32;
        }
        g.compact(&[Some(0), None, Some(1), None]);
        assert_eq!(g.opacity_logits, vec![0.0, 2.0]);
        assert_eq!(g.means.len(), 2);
        g.resize(3);
        assert_eq!(g.opacity_logits, vec![0.0, 2.0, 0.0]);
    }
}
