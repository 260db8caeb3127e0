use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Point3;
use std::num::NonZero;

/// A static kd-tree over 3D points (kiddo's cache-friendly immutable tree).
/// Growing the point set means rebuilding; that costs ~10 ms per 100k points.
pub struct PointTree {
    tree: ImmutableKdTree<f64, 3>,
    len: usize,
}

impl PointTree {
    pub fn new(points: &[Point3<f64>]) -> Self {
        let coords: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        Self {
            tree: ImmutableKdTree::new_from_slice(&coords),
            len: points.len(),
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Nearest point: `(index, squared distance)`, `None` for an empty tree.
    #[inline]
    pub fn nearest(&self, q: &Point3<f64>) -> Option<(usize, f64)> {
        if self.len == 0 {
            return None;
        }
        let n = self.tree.nearest_one::<SquaredEuclidean>(&[q.x, q.y, q.z]);
        Some((n.item as usize, n.distance))
    }

    /// Nearest point whose squared distance is at most `max_sq_dist`.
    #[inline]
    pub fn nearest_within(&self, q: &Point3<f64>, max_sq_dist: f64) -> Option<(usize, f64)> {
        self.nearest(q).filter(|&(_, d2)| d2 <= max_sq_dist)
    }

    /// The `k` nearest points (the query itself included when it is in the
    /// tree), closest first, as `(index, squared distance)`.
    pub fn knn(&self, q: &Point3<f64>, k: usize) -> Vec<(usize, f64)> {
        let Some(k) = NonZero::new(k.min(self.len)) else {
            return Vec::new();
        };
        self.tree
            .nearest_n::<SquaredEuclidean>(&[q.x, q.y, q.z], k)
            .into_iter()
            .map(|n| (n.item as usize, n.distance))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_and_knn_on_a_line_of_points() {
        let pts: Vec<_> = (0..100).map(|i| Point3::new(i as f64, 0.0, 0.0)).collect();
        let tree = PointTree::new(&pts);
        assert_eq!(
            tree.nearest(&Point3::new(41.2, 0.1, 0.0)).map(|r| r.0),
            Some(41)
        );
        assert!(tree
            .nearest_within(&Point3::new(41.5, 3.0, 0.0), 4.0)
            .is_none());
        let knn: Vec<usize> = tree
            .knn(&Point3::new(10.0, 0.0, 0.0), 3)
            .iter()
            .map(|r| r.0)
            .collect();
        assert_eq!(knn[0], 10);
        assert!(knn.contains(&9) && knn.contains(&11));
        assert!(PointTree::new(&[]).nearest(&Point3::origin()).is_none());
    }

    #[test]
    fn duplicated_points_do_not_break_the_tree() {
        let pts = vec![Point3::new(1.0, 1.0, 1.0); 500];
        let tree = PointTree::new(&pts);
        assert_eq!(tree.knn(&Point3::new(1.0, 1.0, 1.0), 10).len(), 10);
    }
}
