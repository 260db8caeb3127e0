//! Far depth samples count less in registration.
//!
//! The depth noise of a triangulating sensor (structured light, active stereo: Kinect,
//! RealSense) grows with the square of the depth, σ(z) ∝ z² (Khoshelham & Elberink 2012),
//! so a sample's information falls as z⁻⁴. G-ICP weighs a correspondence by
//!
//! ```text
//! Ω = (Σ_t + R Σ_s Rᵀ)⁻¹
//! ```
//!
//! and the regularised frame covariance Σ_s is a unit disc whatever the depth. Beyond
//! `from` it is scaled by
//!
//! ```text
//! s(z) = (z / from)⁴
//! ```
//!
//! which divides the sample's weight by about as much once s(z) Σ_s outweighs Σ_t;
//! nearer samples keep theirs. Beyond `until` it falls no further: far walls are what fix
//! the pose when the near samples are one plane (a desk, the floor). In a frame whose samples
//! all lie beyond `until` every disc is scaled alike, so none outvotes another.
//! A keyframe's new points join the tracker's own model with the scale they were seen with.

/// The factor a covariance of a sample at depth `z` (m) is scaled by: 1 up to `from`,
/// (z / from)⁴ up to `until`, (until / from)⁴ beyond; 1 everywhere when `from` is 0 (off).
pub fn depth_scale(z: f64, from: f64, until: f64) -> f64 {
    if from <= 0.0 || z <= from {
        1.0
    } else {
        (z.min(until.max(from)) / from).powi(4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_geometry::nalgebra::Matrix3;
    use opengs_gicp::factor::information;
    use opengs_gicp::{regularize, Regularization};

    #[test]
    fn near_samples_keep_their_weight_and_far_ones_lose_it_as_depth_to_the_fourth() {
        assert_eq!(depth_scale(0.5, 1.0, 2.0), 1.0);
        assert_eq!(depth_scale(1.0, 1.0, 2.0), 1.0);
        assert!((depth_scale(1.5, 1.0, 2.0) - 5.0625).abs() < 1e-12);
        assert_eq!(depth_scale(2.0, 1.0, 2.0), 16.0);
        assert_eq!(
            depth_scale(4.5, 1.0, 2.0),
            16.0,
            "no further beyond `until`"
        );
        assert!((depth_scale(3.0, 1.5, 4.0) - 16.0).abs() < 1e-12);
        assert_eq!(depth_scale(4.0, 0.0, 2.0), 1.0, "0 turns it off");
        assert_eq!(depth_scale(4.0, 1.0, 0.5), 1.0, "`until` below `from`: off");
    }

    /// The information along a disc's normal, source and target both discs facing the same
    /// way: 1 / (2 × 1e-3) = 500 for a near sample; at twice `from` (the source disc 16×)
    /// 1 / (17 × 1e-3) ≈ 58.8, 8.5 times less.
    #[test]
    fn a_far_samples_information_along_the_normal_falls_from_500_to_59_at_twice_the_depth() {
        let disc = regularize(
            &Matrix3::from_diagonal(&[1.0, 1.0, 1e-6].into()),
            Regularization::Plane,
        );
        let along_normal = |z: f64| {
            let omega = information(
                &Matrix3::identity(),
                &(disc * depth_scale(z, 1.0, 2.0)),
                &disc,
            )
            .expect("invertible");
            omega[(2, 2)]
        };
        assert!(
            (along_normal(0.8) - 500.0).abs() < 1e-6,
            "{}",
            along_normal(0.8)
        );
        assert!(
            (along_normal(2.0) - 1.0 / 0.017).abs() < 1e-6,
            "{}",
            along_normal(2.0)
        );
    }
}
