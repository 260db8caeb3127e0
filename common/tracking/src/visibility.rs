//! Does the frame see what the model says is there? A wrong pose can still
//! fit many of a frame's points (floors and walls overlap however the camera
//! slides), so fitness alone passes it. Seen from the right pose, the model's
//! surfaces lie on the observed depth or behind it (occluded); seen from a
//! wrong one, many lie in front of what the camera measured, in space the
//! camera looks straight through. Counted over the model's coarse points in
//! the view:
//!
//! ```text
//! z_model < z_observed − margin     violation (the camera sees through the model)
//! |z_model − z_observed| ≤ margin   agreement
//! z_model > z_observed + margin     occluded: says nothing
//! margin = max(min_margin, margin_fraction × z_observed)
//! ```

use opengs_geometry::nalgebra::Point3;
use opengs_geometry::Pose;

use crate::DepthFrame;

/// Model points that agree with a frame's depth and that it sees through.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Visibility {
    pub agree: usize,
    pub violate: usize,
}

impl Visibility {
    /// `violate / (agree + violate)`; 0 when the frame shows no model point.
    pub fn violation_ratio(&self) -> f64 {
        let seen = self.agree + self.violate;
        if seen == 0 {
            0.0
        } else {
            self.violate as f64 / seen as f64
        }
    }
}

/// Margins of the comparison (m, and a fraction of the observed depth for sensor noise).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisibilityMargin {
    pub min_margin: f64,
    pub margin_fraction: f64,
}

impl Default for VisibilityMargin {
    fn default() -> Self {
        Self {
            min_margin: 0.05,
            margin_fraction: 0.04,
        }
    }
}

/// Compares `model` (world points) with `frame`'s depth seen from `camera_to_world`.
pub fn check_visibility(
    model: &[Point3<f64>],
    camera_to_world: &Pose,
    frame: &DepthFrame,
    margin: &VisibilityMargin,
) -> Visibility {
    let k = frame.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let mut v = Visibility::default();
    if frame.depth.len() != w * h || frame.depth_scale <= 0.0 {
        return v;
    }
    let world_to_camera = camera_to_world.inverse();
    for p in model {
        let q = world_to_camera * p;
        if q.z <= 0.05 {
            continue;
        }
        let u = (k.fx * q.x / q.z + k.cx).round();
        let r = (k.fy * q.y / q.z + k.cy).round();
        if u < 0.0 || r < 0.0 || u >= w as f64 || r >= h as f64 {
            continue;
        }
        let raw = frame.depth[r as usize * w + u as usize];
        if raw == 0 {
            continue;
        }
        let observed = raw as f64 / frame.depth_scale;
        let m = margin.min_margin.max(margin.margin_fraction * observed);
        if q.z < observed - m {
            v.violate += 1;
        } else if q.z <= observed + m {
            v.agree += 1;
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_geometry::Intrinsics;

    #[test]
    fn points_on_in_front_of_and_behind_the_observed_wall() {
        // A 40×30 camera at the origin looking at a wall 2 m away.
        let k = Intrinsics::new(40.0, 40.0, 19.5, 14.5, 40, 30);
        let depth = vec![2000u16; 40 * 30];
        let frame = DepthFrame {
            depth: &depth,
            depth_scale: 1000.0,
            intrinsics: &k,
            timestamp: 0.0,
        };
        let model = [
            Point3::new(0.0, 0.0, 2.02), // on the wall (within 8 cm = 4 % of 2 m)
            Point3::new(0.1, 0.0, 1.95), // on it too
            Point3::new(0.0, 0.1, 1.5),  // in front: the camera sees through it
            Point3::new(0.0, 0.0, 3.0),  // behind the wall: occluded
            Point3::new(5.0, 0.0, 2.0),  // outside the image
            Point3::new(0.0, 0.0, -1.0), // behind the camera
        ];
        let v = check_visibility(
            &model,
            &Pose::identity(),
            &frame,
            &VisibilityMargin::default(),
        );
        assert_eq!(
            v,
            Visibility {
                agree: 2,
                violate: 1
            }
        );
        assert!((v.violation_ratio() - 1.0 / 3.0).abs() < 1e-12);
        // Posed 0.5 m too close, the model's wall would be at 1.5 m where the frame measured
        // 2 m: the three points in front of 3 m all violate, the one at 3 m stays hidden.
        let closer = Pose::translation(0.0, 0.0, 0.5);
        let v = check_visibility(&model, &closer, &frame, &VisibilityMargin::default());
        assert_eq!(
            v,
            Visibility {
                agree: 0,
                violate: 3
            }
        );
    }
}
