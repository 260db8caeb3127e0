use crate::covariance::{
    covariance_from_gaussian, estimate_covariances, regularize, sample_covariance, Regularization,
};
use crate::{estimate_covariances_on_grid, DepthSamples, Gaussian, GicpError};
use nalgebra::{Isometry3, Matrix3, Point3, Quaternion, SymmetricEigen, UnitQuaternion};

/// Points with one covariance each: a GICP source, or the content of a target.
#[derive(Debug, Clone, Default)]
pub struct Cloud {
    pub points: Vec<Point3<f64>>,
    pub covariances: Vec<Matrix3<f64>>,
}

impl Cloud {
    /// Estimates each point's covariance from its `k` nearest neighbours.
    pub fn with_covariances(
        points: Vec<Point3<f64>>,
        k: usize,
        regularization: Regularization,
    ) -> Result<Self, GicpError> {
        let covariances = estimate_covariances(&points, k, regularization)?;
        Ok(Self {
            points,
            covariances,
        })
    }

    /// Depth-grid samples with covariances from their k nearest neighbours
    /// within a 5×5 grid window (fast path for the tracker's source).
    pub fn from_depth_samples(
        samples: &DepthSamples,
        k: usize,
        regularization: Regularization,
    ) -> Result<Self, GicpError> {
        let covariances = estimate_covariances_on_grid(samples, k, regularization)?;
        Ok(Self {
            points: samples.points.clone(),
            covariances,
        })
    }

    /// The map's Gaussians as points: mean, covariance `R S² Rᵀ` regularised like
    /// the source so both sides have comparable scale.
    pub fn from_gaussians(
        gaussians: &[Gaussian],
        regularization: Regularization,
    ) -> Result<Self, GicpError> {
        let mut points = Vec::with_capacity(gaussians.len());
        let mut covariances = Vec::with_capacity(gaussians.len());
        for (i, g) in gaussians.iter().enumerate() {
            let [w, x, y, z] = g.rotation;
            let q = Quaternion::new(w, x, y, z);
            let finite = q
                .coords
                .iter()
                .chain(g.scale.iter())
                .chain(g.mean.coords.iter())
                .all(|v| v.is_finite());
            if !finite || q.norm() < 1e-12 {
                return Err(GicpError::Invalid(format!(
                    "Gaussian {i} has a non-finite value or a zero quaternion"
                )));
            }
            let cov = covariance_from_gaussian(&UnitQuaternion::from_quaternion(q), &g.scale);
            points.push(g.mean);
            covariances.push(regularize(&cov, regularization));
        }
        Ok(Self {
            points,
            covariances,
        })
    }

    /// Points whose covariances are already known (e.g. from Gaussians).
    pub fn from_parts(
        points: Vec<Point3<f64>>,
        covariances: Vec<Matrix3<f64>>,
    ) -> Result<Self, GicpError> {
        if points.len() != covariances.len() {
            return Err(GicpError::LengthMismatch("points and covariances"));
        }
        Ok(Self {
            points,
            covariances,
        })
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// `Ok` unless the cloud is empty, tiny, non-finite or collinear (`what` names it).
    pub fn check_registrable(&self, what: &'static str) -> Result<(), GicpError> {
        check_registrable(what, &self.points)
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// One point per occupied cubic voxel of side `voxel` (the first met, with its own
    /// covariance): a coarse cloud for the wide first stages of coarse-to-fine registration.
    /// `voxel ≤ 0` (or NaN) keeps every point.
    pub fn voxel_subsample(&self, voxel: f64) -> Self {
        if voxel.is_nan() || voxel <= 0.0 {
            return self.clone();
        }
        let inv = 1.0 / voxel;
        let mut seen = std::collections::HashSet::with_capacity(self.len() / 4);
        let mut out = Self::default();
        for (p, c) in self.points.iter().zip(&self.covariances) {
            let key = [
                (p.x * inv).floor() as i64,
                (p.y * inv).floor() as i64,
                (p.z * inv).floor() as i64,
            ];
            if seen.insert(key) {
                out.points.push(*p);
                out.covariances.push(*c);
            }
        }
        out
    }

    /// The cloud seen from another frame: `p ↦ T p`, `Σ ↦ R Σ Rᵀ`.
    pub fn transformed(&self, t: &Isometry3<f64>) -> Self {
        let r = t.rotation.to_rotation_matrix().into_inner();
        Self {
            points: self.points.iter().map(|p| t * p).collect(),
            covariances: self
                .covariances
                .iter()
                .map(|c| r * c * r.transpose())
                .collect(),
        }
    }
}

/// Refuses empty, tiny and collinear clouds, whose pose is not determined.
pub(crate) fn check_registrable(
    what: &'static str,
    points: &[Point3<f64>],
) -> Result<(), GicpError> {
    const NEEDED: usize = 3;
    if points.is_empty() {
        return Err(GicpError::EmptyCloud { what });
    }
    if points.len() < NEEDED {
        return Err(GicpError::TooFewPoints {
            what,
            found: points.len(),
            needed: NEEDED,
        });
    }
    if points
        .iter()
        .any(|p| !p.coords.iter().all(|v| v.is_finite()))
    {
        return Err(GicpError::Invalid(format!(
            "{what} point cloud has non-finite coordinates"
        )));
    }
    let spread = SymmetricEigen::new(sample_covariance(points.iter())).eigenvalues;
    let mut sorted = [spread.x, spread.y, spread.z];
    sorted.sort_by(f64::total_cmp);
    if sorted[1] <= 1e-12 * sorted[2].max(f64::MIN_POSITIVE) {
        return Err(GicpError::Degenerate(format!(
            "{what} points are all on a line or at one spot"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voxel_subsample_keeps_the_first_point_of_each_voxel_with_its_covariance() {
        let points = vec![
            Point3::new(0.01, 0.01, 0.01),
            Point3::new(0.04, 0.02, 0.0),
            Point3::new(0.06, 0.0, 0.0),
            Point3::new(-0.01, 0.0, 0.0),
        ];
        let covariances = (1..=4).map(|i| Matrix3::identity() * i as f64).collect();
        let cloud = Cloud::from_parts(points, covariances).expect("same length");
        let coarse = cloud.voxel_subsample(0.05);
        assert_eq!(coarse.len(), 3);
        assert_eq!(coarse.points[0], Point3::new(0.01, 0.01, 0.01));
        assert_eq!(coarse.covariances[1], Matrix3::identity() * 3.0);
        assert_eq!(coarse.points[2], Point3::new(-0.01, 0.0, 0.0));
        assert_eq!(cloud.voxel_subsample(0.0).len(), 4);
    }
}
