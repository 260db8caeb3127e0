//! Is a registration right? G-ICP always returns a pose; after a jump it can
//! converge to a wrong one (sliding along a wall or the floor) and say
//! nothing. Every result is checked before the tracker trusts it:
//!
//! - **fitness**: the share of source points with a model point within the
//!   correspondence distance. Right answers on the synthetic room score
//!   0.64–1.0, the wrong minima 0.01–0.60 (`examples/jump_probe`).
//! - **residual**: the RMS distance of those inliers.
//! - **conditioning**: the smallest ÷ largest eigenvalue of the normal
//!   equations; near 0 a motion is not observed (a bare wall).
//! - **agreement with the motion prior**: no further from the constant-velocity
//!   prediction than a hand-held camera moves in the time since the last
//!   verified frame (with a floor for jitter).
//! - **visibility** ([`verify_visibility`]): few model points in front of the
//!   depth the frame measured.

use opengs_geometry::Pose;
use opengs_gicp::Registration;

use crate::visibility::{Visibility, VisibilityMargin};

/// Thresholds of [`verify`].
#[derive(Debug, Clone, PartialEq)]
pub struct VerifyConfig {
    pub min_fitness: f64,
    /// Largest inlier RMS distance (m).
    pub max_inlier_rmse: f64,
    pub min_conditioning: f64,
    /// Fastest camera motion believed (m/s, rad/s) …
    pub max_speed: f64,
    pub max_angular_speed: f64,
    /// … with these allowances whatever the time (m, rad).
    pub min_jump: f64,
    pub min_turn: f64,
    /// Largest share of the model points in view that may lie in front of the measured
    /// depth ([`crate::visibility`]), and the margins of that comparison.
    pub max_violation: f64,
    pub visibility_margin: VisibilityMargin,
}

impl Default for VerifyConfig {
    fn default() -> Self {
        Self {
            min_fitness: 0.5,
            max_inlier_rmse: 0.02,
            min_conditioning: 1e-6,
            max_speed: 2.0,
            max_angular_speed: 180f64.to_radians(),
            min_jump: 0.15,
            min_turn: 10f64.to_radians(),
            max_violation: 0.1,
            visibility_margin: VisibilityMargin::default(),
        }
    }
}

/// Why a registration was not trusted.
#[derive(Debug, Clone, PartialEq)]
pub enum Rejection {
    LowFitness { fitness: f64, min: f64 },
    LargeResidual { rmse: f64, max: f64 },
    IllConditioned { conditioning: f64, min: f64 },
    FarFromPrediction { metres: f64, radians: f64 },
    SeesThroughModel { ratio: f64, max: f64 },
}

impl std::fmt::Display for Rejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::LowFitness { fitness, min } => {
                write!(f, "fitness {fitness:.2} below {min:.2}")
            }
            Self::LargeResidual { rmse, max } => write!(
                f,
                "inlier RMS {:.1} mm above {:.1} mm",
                rmse * 1e3,
                max * 1e3
            ),
            Self::IllConditioned { conditioning, min } => {
                write!(f, "conditioning {conditioning:.1e} below {min:.1e}")
            }
            Self::SeesThroughModel { ratio, max } => write!(
                f,
                "the frame sees through {:.0} % of the model in view (at most {:.0} %)",
                ratio * 100.0,
                max * 100.0
            ),
            Self::FarFromPrediction { metres, radians } => write!(
                f,
                "{:.1} cm and {:.1}° from the motion prediction",
                metres * 100.0,
                radians.to_degrees()
            ),
        }
    }
}

/// The motion prior a result must agree with: the prediction and the seconds
/// since the last verified frame.
#[derive(Debug, Clone, Copy)]
pub struct MotionPrior {
    pub predicted: Pose,
    pub seconds: f64,
}

/// Checks a registration (see the module doc); `prior: None` skips the motion check.
pub fn verify(
    r: &Registration,
    prior: Option<&MotionPrior>,
    config: &VerifyConfig,
) -> Result<(), Rejection> {
    if r.fitness.is_nan() || r.fitness < config.min_fitness {
        return Err(Rejection::LowFitness {
            fitness: r.fitness,
            min: config.min_fitness,
        });
    }
    if r.inlier_rmse.is_nan() || r.inlier_rmse > config.max_inlier_rmse {
        return Err(Rejection::LargeResidual {
            rmse: r.inlier_rmse,
            max: config.max_inlier_rmse,
        });
    }
    if r.conditioning.is_nan() || r.conditioning < config.min_conditioning {
        return Err(Rejection::IllConditioned {
            conditioning: r.conditioning,
            min: config.min_conditioning,
        });
    }
    if let Some(prior) = prior {
        let offset = prior.predicted.inverse() * r.transform;
        let (metres, radians) = (offset.translation.vector.norm(), offset.rotation.angle());
        let seconds = prior.seconds.max(0.0);
        let max_metres = config.min_jump.max(config.max_speed * seconds);
        let max_radians = config.min_turn.max(config.max_angular_speed * seconds);
        if metres > max_metres || radians > max_radians {
            return Err(Rejection::FarFromPrediction { metres, radians });
        }
    }
    Ok(())
}

/// Checks what the frame sees of the model at the registered pose.
pub fn verify_visibility(seen: &Visibility, config: &VerifyConfig) -> Result<(), Rejection> {
    let ratio = seen.violation_ratio();
    if ratio > config.max_violation {
        return Err(Rejection::SeesThroughModel {
            ratio,
            max: config.max_violation,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_geometry::nalgebra::{Isometry3, Vector3};

    fn result(fitness: f64, rmse: f64, conditioning: f64, at: Isometry3<f64>) -> Registration {
        Registration {
            transform: at,
            iterations: 5,
            converged: true,
            inliers: 1000,
            fitness,
            inlier_rmse: rmse,
            overlap: fitness,
            error: 1.0,
            conditioning,
            hessian: opengs_geometry::nalgebra::Matrix6::identity(),
        }
    }

    #[test]
    fn each_check_rejects_on_its_own() {
        let c = VerifyConfig::default();
        let good = result(0.9, 0.008, 1e-3, Isometry3::identity());
        assert_eq!(verify(&good, None, &c), Ok(()));
        assert!(matches!(
            verify(&result(0.36, 0.008, 1e-3, Isometry3::identity()), None, &c),
            Err(Rejection::LowFitness { .. })
        ));
        assert!(matches!(
            verify(&result(0.9, 0.025, 1e-3, Isometry3::identity()), None, &c),
            Err(Rejection::LargeResidual { .. })
        ));
        assert!(matches!(
            verify(&result(0.9, 0.008, 1e-9, Isometry3::identity()), None, &c),
            Err(Rejection::IllConditioned { .. })
        ));
        let clear = Visibility {
            agree: 90,
            violate: 10,
        };
        assert_eq!(verify_visibility(&clear, &c), Ok(()));
        let through = Visibility {
            agree: 50,
            violate: 50,
        };
        assert!(matches!(
            verify_visibility(&through, &c),
            Err(Rejection::SeesThroughModel { .. })
        ));
    }

    #[test]
    fn the_motion_prior_allows_what_a_camera_can_do_in_the_time_since() {
        let c = VerifyConfig::default();
        // 40 cm from the prediction: too far after one frame (floor 15 cm) …
        let far = result(0.9, 0.008, 1e-3, Isometry3::translation(0.4, 0.0, 0.0));
        let one_frame = MotionPrior {
            predicted: Isometry3::identity(),
            seconds: 1.0 / 30.0,
        };
        assert!(matches!(
            verify(&far, Some(&one_frame), &c),
            Err(Rejection::FarFromPrediction { .. })
        ));
        // … possible after 2 s without a verified frame (2 m/s).
        let two_seconds = MotionPrior {
            seconds: 2.0,
            ..one_frame
        };
        assert_eq!(verify(&far, Some(&two_seconds), &c), Ok(()));
        // 5° and 10 cm after one frame: within the floor.
        let jump = result(
            0.9,
            0.008,
            1e-3,
            Isometry3::new(
                Vector3::new(0.1, 0.0, 0.0),
                Vector3::y() * 5f64.to_radians(),
            ),
        );
        assert_eq!(verify(&jump, Some(&one_frame), &c), Ok(()));
    }
}
