use crate::covariance::sample_covariance;
use crate::covariance::{estimate_covariances, Regularization};
use crate::{estimate_covariances_on_grid, DepthSamples, GicpError};
use nalgebra::{Isometry3, Matrix3, Point3, SymmetricEigen};

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

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
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
