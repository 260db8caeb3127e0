use crate::cloud::check_registrable;
use crate::covariance::Regularization;
use crate::{Cloud, GicpError, NeighbourGrid, PointTree};
use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use std::sync::OnceLock;

/// One map Gaussian as the tracker sees it (docs/METHOD.md §7: mean, rotation, scale).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gaussian {
    pub mean: Point3<f64>,
    /// Rotation quaternion `(w, x, y, z)`, normalised on use.
    pub rotation: [f64; 4],
    /// Per-axis standard deviations (not log-scales).
    pub scale: Vector3<f64>,
}

/// Radius (m) of the target's fast correspondence grid: √1e-3 covers
/// docs/METHOD.md §7's TUM and Replica correspondence and overlap thresholds.
pub const DEFAULT_SEARCH_RADIUS: f64 = 0.031_7;

/// What a source is registered against: points, their precomputed
/// covariances, a kd-tree (any distance) and a hashed grid (fast, exact up
/// to `search_radius`) for the correspondence search.
pub struct Target {
    cloud: Cloud,
    /// Built on first use: searches within the grid radius never need it.
    tree: OnceLock<PointTree>,
    grid: NeighbourGrid,
    search_radius: f64,
    /// Whether the points can fix a pose (checked once per change, not per frame).
    registrable: Result<(), GicpError>,
}

impl Target {
    /// A target from points whose covariances are known.
    pub fn new(cloud: Cloud) -> Self {
        Self::with_search_radius(cloud, DEFAULT_SEARCH_RADIUS)
    }

    /// Like [`Target::new`], with the grid sized for correspondences up to
    /// `radius` metres (farther searches fall back to the kd-tree).
    pub fn with_search_radius(cloud: Cloud, radius: f64) -> Self {
        let radius = if radius > 0.0 {
            radius
        } else {
            DEFAULT_SEARCH_RADIUS
        };
        Self {
            tree: OnceLock::new(),
            grid: NeighbourGrid::new(&cloud.points, radius),
            registrable: check_registrable("target", &cloud.points),
            cloud,
            search_radius: radius,
        }
    }

    /// A target from bare points (e.g. the first keyframe before any map).
    pub fn from_points(
        points: Vec<Point3<f64>>,
        k: usize,
        regularization: Regularization,
    ) -> Result<Self, GicpError> {
        Ok(Self::new(Cloud::with_covariances(
            points,
            k,
            regularization,
        )?))
    }

    /// A target from the map's Gaussians ([`Cloud::from_gaussians`]).
    pub fn from_gaussians(
        gaussians: &[Gaussian],
        regularization: Regularization,
    ) -> Result<Self, GicpError> {
        Ok(Self::new(Cloud::from_gaussians(gaussians, regularization)?))
    }

    /// Appends points already in the target frame, then rebuilds the tree.
    pub fn add(&mut self, cloud: &Cloud) {
        self.cloud.points.extend_from_slice(&cloud.points);
        self.cloud.covariances.extend_from_slice(&cloud.covariances);
        *self = Self::with_search_radius(std::mem::take(&mut self.cloud), self.search_radius);
    }

    /// `Ok` unless the target is empty, tiny, non-finite or collinear.
    pub fn check_registrable(&self) -> Result<(), GicpError> {
        self.registrable.clone()
    }

    /// Appends a keyframe's source cloud seen from `pose` (source → target).
    pub fn add_transformed(&mut self, cloud: &Cloud, pose: &Isometry3<f64>) {
        self.add(&cloud.transformed(pose));
    }

    pub fn cloud(&self) -> &Cloud {
        &self.cloud
    }

    pub fn points(&self) -> &[Point3<f64>] {
        &self.cloud.points
    }

    pub fn covariances(&self) -> &[Matrix3<f64>] {
        &self.cloud.covariances
    }

    /// The kd-tree (built on the first call after a change).
    pub fn tree(&self) -> &PointTree {
        self.tree.get_or_init(|| PointTree::new(&self.cloud.points))
    }

    pub fn grid(&self) -> &NeighbourGrid {
        &self.grid
    }

    /// Searches up to this distance use the grid.
    pub fn search_radius(&self) -> f64 {
        self.search_radius
    }

    pub fn len(&self) -> usize {
        self.cloud.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cloud.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn gaussians_become_points_with_r_s2_rt() {
        let g = Gaussian {
            mean: Point3::new(1.0, 2.0, 3.0),
            rotation: [1.0, 0.0, 0.0, 0.0],
            scale: Vector3::new(0.1, 0.2, 0.3),
        };
        let t = Target::from_gaussians(&[g], Regularization::None).expect("valid");
        assert_eq!(t.points()[0], g.mean);
        assert_relative_eq!(
            t.covariances()[0],
            Matrix3::from_diagonal(&Vector3::new(0.01, 0.04, 0.09)),
            epsilon = 1e-12
        );
        let bad = Gaussian {
            rotation: [0.0; 4],
            ..g
        };
        assert!(Target::from_gaussians(&[bad], Regularization::None).is_err());
    }

    #[test]
    fn adding_a_keyframe_grows_the_target_and_its_tree() {
        let first = Cloud::from_parts(vec![Point3::origin()], vec![Matrix3::identity()])
            .expect("same length");
        let mut t = Target::new(first.clone());
        t.add_transformed(&first, &Isometry3::translation(5.0, 0.0, 0.0));
        assert_eq!(t.len(), 2);
        let near = Point3::new(4.99, 0.0, 0.0);
        let by_tree = t.tree().nearest(&near).map(|r| r.0);
        let by_grid = t.grid().nearest_within(&near, 1e-3).map(|r| r.0);
        assert_eq!(by_tree, by_grid);
        assert_eq!(
            by_tree.map(|i| t.points()[i]),
            Some(Point3::new(5.0, 0.0, 0.0))
        );
    }
}
