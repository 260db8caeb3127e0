//! Absolute trajectory error (docs/METHOD.md §9): associate by timestamp, align the
//! estimated positions to ground truth with Umeyama (rigid, no scale),
//! report RMSE *and* mean (GS-ICP SLAM prints the mean under the name RMSE).

use crate::TimedPose;
use nalgebra::{Isometry3, Point3};

/// TUM's usual association window (seconds).
pub const DEFAULT_MAX_TIME_DIFFERENCE: f64 = 0.02;

#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum AteError {
    #[error("only {found} associated poses, at least {needed} are needed")]
    TooFewPairs { found: usize, needed: usize },
    #[error("the two point lists have different lengths ({0} and {1})")]
    LengthMismatch(usize, usize),
    #[error("alignment failed: {0}")]
    Alignment(String),
}

/// ATE statistics in metres after rigid alignment.
#[derive(Debug, Clone, PartialEq)]
pub struct AteResult {
    pub rmse: f64,
    pub mean: f64,
    pub median: f64,
    pub max: f64,
    /// Number of associated pose pairs.
    pub pairs: usize,
    /// Estimated → ground-truth alignment that was applied.
    pub alignment: Isometry3<f64>,
}

/// Pairs `(estimated index, ground-truth index)` whose timestamps differ by
/// at most `max_dt`, each pose used once, closest pairs first.
pub fn associate(
    estimated: &[TimedPose],
    ground_truth: &[TimedPose],
    max_dt: f64,
) -> Vec<(usize, usize)> {
    let mut gt_order: Vec<usize> = (0..ground_truth.len()).collect();
    gt_order.sort_by(|&a, &b| {
        ground_truth[a]
            .timestamp
            .total_cmp(&ground_truth[b].timestamp)
    });
    // Candidate: each estimate with its nearest ground truth on either side.
    let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
    for (i, e) in estimated.iter().enumerate() {
        let at = gt_order.partition_point(|&j| ground_truth[j].timestamp < e.timestamp);
        for k in [at.wrapping_sub(1), at] {
            if let Some(&j) = gt_order.get(k) {
                let dt = (ground_truth[j].timestamp - e.timestamp).abs();
                if dt <= max_dt {
                    candidates.push((dt, i, j));
                }
            }
        }
    }
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut used_e = vec![false; estimated.len()];
    let mut used_g = vec![false; ground_truth.len()];
    let mut pairs = Vec::new();
    for (_, i, j) in candidates {
        if !used_e[i] && !used_g[j] {
            used_e[i] = true;
            used_g[j] = true;
            pairs.push((i, j));
        }
    }
    pairs.sort_unstable();
    pairs
}

/// Umeyama without scale: the rigid `T` minimising `Σ |dst_i − T src_i|²`
/// ([`opengs_geometry::rigid_fit`]), with the reason when there is none.
pub fn umeyama_rigid(src: &[Point3<f64>], dst: &[Point3<f64>]) -> Result<Isometry3<f64>, AteError> {
    if src.len() != dst.len() {
        return Err(AteError::LengthMismatch(src.len(), dst.len()));
    }
    if src.len() < 3 {
        return Err(AteError::TooFewPairs {
            found: src.len(),
            needed: 3,
        });
    }
    opengs_geometry::rigid_fit(src, dst)
        .ok_or_else(|| AteError::Alignment("no finite rigid fit (SVD failed)".into()))
}

/// ATE of already paired positions.
pub fn ate_of_positions(
    estimated: &[Point3<f64>],
    ground_truth: &[Point3<f64>],
) -> Result<AteResult, AteError> {
    let alignment = umeyama_rigid(estimated, ground_truth)?;
    let mut errors: Vec<f64> = estimated
        .iter()
        .zip(ground_truth)
        .map(|(e, g)| (alignment * e - g).norm())
        .collect();
    let n = errors.len() as f64;
    let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
    let mean = errors.iter().sum::<f64>() / n;
    errors.sort_by(f64::total_cmp);
    let median = if errors.len() % 2 == 1 {
        errors[errors.len() / 2]
    } else {
        0.5 * (errors[errors.len() / 2 - 1] + errors[errors.len() / 2])
    };
    Ok(AteResult {
        rmse,
        mean,
        median,
        max: errors.last().copied().unwrap_or(0.0),
        pairs: errors.len(),
        alignment,
    })
}

/// Associates by timestamp (within `max_dt` s), aligns, and reports ATE.
pub fn absolute_trajectory_error(
    estimated: &[TimedPose],
    ground_truth: &[TimedPose],
    max_dt: f64,
) -> Result<AteResult, AteError> {
    let pairs = associate(estimated, ground_truth, max_dt);
    let est: Vec<Point3<f64>> = pairs
        .iter()
        .map(|&(i, _)| Point3::from(estimated[i].pose.translation.vector))
        .collect();
    let gt: Vec<Point3<f64>> = pairs
        .iter()
        .map(|&(_, j)| Point3::from(ground_truth[j].pose.translation.vector))
        .collect();
    ate_of_positions(&est, &gt)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::Vector3;
    use std::f64::consts::FRAC_PI_2;

    fn timed(t: f64, p: Point3<f64>) -> TimedPose {
        TimedPose {
            timestamp: t,
            pose: Isometry3::translation(p.x, p.y, p.z),
        }
    }

    #[test]
    fn umeyama_recovers_90_degrees_about_z_exactly() {
        // Rz(90°): (x, y, z) ↦ (−y, x, z), then + (1, 2, 3).
        let src = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 2.0, 0.0),
            Point3::new(0.0, 0.0, 3.0),
        ];
        let dst = [
            Point3::new(1.0, 2.0, 3.0),
            Point3::new(1.0, 3.0, 3.0),
            Point3::new(-1.0, 2.0, 3.0),
            Point3::new(1.0, 2.0, 6.0),
        ];
        let t = umeyama_rigid(&src, &dst).expect("aligns");
        let expected = Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::z() * FRAC_PI_2);
        assert_relative_eq!(
            t.to_homogeneous(),
            expected.to_homogeneous(),
            epsilon = 1e-12
        );
        let ate = ate_of_positions(&src, &dst).expect("aligns");
        assert!(ate.rmse < 1e-12 && ate.mean < 1e-12);
    }

    #[test]
    fn noise_orthogonal_to_rigid_motions_gives_rmse_e() {
        // Ground truth: (±1, 0, 0), (0, ±1, 0). Estimate: z-noise +e, +e, −e, −e.
        // C = diag(½, ½, 0) ⇒ R = I, t = 0, every residual is e ⇒ RMSE = mean = e.
        // The estimate is also moved by an arbitrary rigid motion, which Umeyama removes.
        let e = 0.01;
        let gt = [
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(-1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, -1.0, 0.0),
        ];
        let noise = [e, e, -e, -e];
        let motion = Isometry3::new(Vector3::new(0.5, -2.0, 1.0), Vector3::new(0.3, 0.2, -0.4));
        let est: Vec<_> = gt
            .iter()
            .zip(noise)
            .map(|(p, dz)| motion * Point3::new(p.x, p.y, p.z + dz))
            .collect();
        let ate = ate_of_positions(&est, &gt).expect("aligns");
        assert_relative_eq!(ate.rmse, e, epsilon = 1e-12);
        assert_relative_eq!(ate.mean, e, epsilon = 1e-12);
        assert_relative_eq!(ate.max, e, epsilon = 1e-12);
    }

    #[test]
    fn rmse_and_mean_differ_when_errors_differ() {
        // Ground truth (±1, 0, 0), (0, ±1, 0); the estimate stretches the
        // x pair by s each way. The stretch is symmetric with zero sum, so no
        // rigid motion absorbs it: R = I, t = 0, residuals (s, s, 0, 0):
        // RMSE = √(2s²/4) = s/√2, mean = s/2.
        let s = 0.02;
        let gt = [
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(-1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, -1.0, 0.0),
        ];
        let est = [
            Point3::new(1.0 + s, 0.0, 0.0),
            Point3::new(-1.0 - s, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, -1.0, 0.0),
        ];
        let ate = ate_of_positions(&est, &gt).expect("aligns");
        assert_relative_eq!(ate.rmse, s / 2f64.sqrt(), epsilon = 1e-12);
        assert_relative_eq!(ate.mean, s / 2.0, epsilon = 1e-12);
    }

    #[test]
    fn a_mirrored_trajectory_is_aligned_by_a_rotation_not_a_reflection() {
        let gt = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 2.0, 0.0),
            Point3::new(0.0, 0.0, 3.0),
        ];
        let mirrored: Vec<_> = gt.iter().map(|p| Point3::new(-p.x, p.y, p.z)).collect();
        let t = umeyama_rigid(&mirrored, &gt).expect("aligns");
        assert_relative_eq!(
            t.rotation.to_rotation_matrix().matrix().determinant(),
            1.0,
            epsilon = 1e-12
        );
        assert!(ate_of_positions(&mirrored, &gt).expect("aligns").rmse > 0.1);
    }

    #[test]
    fn association_by_nearest_timestamp_within_window() {
        let gt: Vec<_> = (0..5)
            .map(|i| timed(i as f64 * 0.1, Point3::origin()))
            .collect();
        let est = vec![
            timed(0.005, Point3::origin()), // → 0
            timed(0.19, Point3::origin()),  // → 2 (0.01 away)
            timed(0.25, Point3::origin()),  // 0.05 from both: none
            timed(0.31, Point3::origin()),  // → 3
        ];
        assert_eq!(
            associate(&est, &gt, DEFAULT_MAX_TIME_DIFFERENCE),
            vec![(0, 0), (1, 2), (3, 3)]
        );
    }

    #[test]
    fn trajectory_ate_end_to_end_and_too_few_pairs() {
        let gt: Vec<_> = (0..10)
            .map(|i| timed(i as f64, Point3::new(i as f64, (i * i) as f64 * 0.1, 0.0)))
            .collect();
        let shift = Isometry3::new(Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 0.0, 0.5));
        let est: Vec<_> = gt
            .iter()
            .map(|p| TimedPose {
                timestamp: p.timestamp + 0.01,
                pose: shift * p.pose,
            })
            .collect();
        let ate =
            absolute_trajectory_error(&est, &gt, DEFAULT_MAX_TIME_DIFFERENCE).expect("aligns");
        assert_eq!(ate.pairs, 10);
        assert!(ate.rmse < 1e-9, "{}", ate.rmse);
        let far: Vec<_> = est
            .iter()
            .map(|p| TimedPose {
                timestamp: p.timestamp + 5.5,
                ..*p
            })
            .collect();
        assert!(matches!(
            absolute_trajectory_error(&far[..2], &gt, DEFAULT_MAX_TIME_DIFFERENCE),
            Err(AteError::TooFewPairs { .. })
        ));
    }
}
