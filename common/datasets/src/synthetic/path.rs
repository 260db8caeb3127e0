//! Camera paths through the synthetic room: a generated hand-held-like loop,
//! or a real TUM trajectory re-centred into the room (sampled on the camera
//! clock by [`super::timeline`]).

use std::f64::consts::TAU;

use nalgebra::{Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, UnitVector3, Vector3};
use opengs_geometry::Pose;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Camera-to-world pose at `eye` looking at `target` (camera x right, y down,
/// z forward; world z up), rolled by `roll` radians about the view axis.
pub fn look_at(eye: &Point3<f64>, target: &Point3<f64>, roll: f64) -> Pose {
    let forward = (target - eye).normalize();
    let mut right = forward.cross(&Vector3::z());
    if right.norm() < 1e-9 {
        // Looking straight up or down: any horizontal right vector will do.
        right = Vector3::x();
    }
    let right = right.normalize();
    let down = forward.cross(&right);
    let basis = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[right, down, forward]));
    let rolled = basis * Rotation3::from_axis_angle(&Vector3::z_axis(), roll);
    Pose::from_parts(
        Translation3::from(eye.coords),
        UnitQuaternion::from_rotation_matrix(&rolled),
    )
}

/// Smooth pseudo-random wobble: a few sinusoids with seeded frequencies.
#[derive(Debug, Clone)]
struct Wobble {
    terms: Vec<(f64, f64, f64)>, // (amplitude, frequency Hz, phase)
}

impl Wobble {
    fn new(rng: &mut ChaCha8Rng, amplitude: f64) -> Self {
        let terms = (0..3)
            .map(|i| {
                let amp = amplitude / (i as f64 + 1.0);
                (
                    amp,
                    rng.gen_range(0.15..1.2) * (i as f64 + 1.0),
                    rng.gen_range(0.0..TAU),
                )
            })
            .collect();
        Self { terms }
    }

    fn at(&self, t: f64) -> f64 {
        self.terms
            .iter()
            .map(|(a, f, p)| a * (TAU * f * t + p).sin())
            .sum()
    }
}

/// Parameters of the generated loop around the table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopPath {
    pub centre: Point3<f64>,
    pub radius_x: f64,
    pub radius_y: f64,
    pub height: f64,
    pub target: Point3<f64>,
    /// Seconds for one full loop.
    pub period: f64,
    /// Position jitter amplitude (metres) and roll/aim jitter (radians).
    pub jitter: f64,
    pub angular_jitter: f64,
}

impl Default for LoopPath {
    fn default() -> Self {
        Self {
            centre: Point3::new(2.5, 2.0, 0.0),
            radius_x: 1.5,
            radius_y: 1.1,
            height: 1.45,
            target: Point3::new(2.5, 2.0, 0.8),
            period: 20.0,
            jitter: 0.015,
            angular_jitter: 0.02,
        }
    }
}

impl LoopPath {
    /// Poses at `t = i / fps` for `frames` frames; deterministic for `seed`.
    pub fn poses(&self, frames: usize, fps: f64, seed: u64) -> Vec<Pose> {
        let times: Vec<f64> = (0..frames).map(|i| i as f64 / fps).collect();
        self.poses_at(&times, seed)
    }

    /// Poses at the given times (seconds from the loop's start); the same
    /// path as [`LoopPath::poses`] for the same `seed`, sampled anywhere.
    pub fn poses_at(&self, times: &[f64], seed: u64) -> Vec<Pose> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let wob: Vec<Wobble> = (0..6)
            .map(|i| Wobble::new(&mut rng, if i < 3 { self.jitter } else { 0.15 }))
            .collect();
        let roll = Wobble::new(&mut rng, self.angular_jitter);
        let start_angle = rng.gen_range(0.0..TAU);
        times
            .iter()
            .map(|&t| {
                let a = start_angle + TAU * t / self.period;
                let eye = Point3::new(
                    self.centre.x + self.radius_x * a.cos() + wob[0].at(t),
                    self.centre.y + self.radius_y * a.sin() + wob[1].at(t),
                    self.height + 0.12 * (2.0 * a).sin() + wob[2].at(t),
                );
                // The aim point drifts over the table so views are not all centred.
                let target = self.target
                    + Vector3::new(wob[3].at(t * 0.3), wob[4].at(t * 0.3), wob[5].at(t * 0.3));
                look_at(&eye, &target, roll.at(t))
            })
            .collect()
    }
}

/// Preferred first camera of a re-centred trajectory: eye and aim point.
const START_EYE: [f64; 3] = [1.1, 1.6, 1.45];
const START_TARGET: [f64; 3] = [2.7, 2.2, 0.8];

/// Where a re-centred TUM trajectory starts: near the sofa, looking at the table.
pub fn default_start_pose() -> Pose {
    look_at(&Point3::from(START_EYE), &Point3::from(START_TARGET), 0.0)
}

/// First pose for re-centring `poses` into the box `[lo, hi]`: the default
/// viewpoint, translated just enough that the whole path stays inside the
/// box (centred where the path is larger than the box). The orientation is
/// kept, so the shift is exact and the first view still looks into the room.
pub fn fit_start_pose(poses: &[Pose], lo: &Point3<f64>, hi: &Point3<f64>) -> Pose {
    let start = default_start_pose();
    let moved = recentre(poses, &start);
    let mut shift = Vector3::zeros();
    for i in 0..3 {
        let (min, max) = moved.iter().fold((f64::MAX, f64::MIN), |(a, b), p| {
            let x = p.translation.vector[i];
            (a.min(x), b.max(x))
        });
        shift[i] = if max - min > hi[i] - lo[i] {
            (lo[i] + hi[i] - min - max) / 2.0
        } else if min < lo[i] {
            lo[i] - min
        } else if max > hi[i] {
            hi[i] - max
        } else {
            0.0
        };
    }
    Pose::from_parts(
        Translation3::from(start.translation.vector + shift),
        start.rotation,
    )
}

/// Moves a trajectory so its first pose becomes `start`, keeping every pose
/// relative to the first (p'_k = start · p_0⁻¹ · p_k).
pub fn recentre(poses: &[Pose], start: &Pose) -> Vec<Pose> {
    let Some(first) = poses.first() else {
        return Vec::new();
    };
    let offset = start * first.inverse();
    poses.iter().map(|p| offset * p).collect()
}

/// Unit view direction (camera +z) of a camera-to-world pose.
pub fn view_direction(pose: &Pose) -> UnitVector3<f64> {
    UnitVector3::new_normalize(pose.rotation * Vector3::z())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn look_at_points_camera_z_at_target() {
        let eye = Point3::new(1.0, 1.0, 1.0);
        let target = Point3::new(4.0, 1.0, 1.0);
        let p = look_at(&eye, &target, 0.0);
        assert_relative_eq!(
            view_direction(&p).into_inner(),
            Vector3::x(),
            epsilon = 1e-12
        );
        // Image "down" is world −z.
        assert_relative_eq!(p.rotation * Vector3::y(), -Vector3::z(), epsilon = 1e-12);
        assert_relative_eq!(
            p.rotation.to_rotation_matrix().matrix().determinant(),
            1.0,
            epsilon = 1e-12
        );
    }

    #[test]
    fn loop_is_deterministic_and_smooth() {
        let path = LoopPath::default();
        let a = path.poses(120, 30.0, 5);
        let b = path.poses(120, 30.0, 5);
        assert_eq!(a, b);
        for w in a.windows(2) {
            let rel = w[0].inverse() * w[1];
            assert!(rel.translation.vector.norm() < 0.05);
            assert!(rel.rotation.angle() < 0.05);
        }
    }

    #[test]
    fn fitted_start_keeps_a_large_loop_inside() {
        // A 4 m wide circle, much like fr2/desk, starting at the circle's edge.
        let circle: Vec<Pose> = (0..100)
            .map(|i| {
                let a = i as f64 * TAU / 100.0;
                let eye = Point3::new(2.0 * a.cos(), 2.0 * a.sin(), 0.0);
                look_at(&eye, &Point3::origin(), 0.0)
            })
            .collect();
        let (lo, hi) = (Point3::new(0.3, 0.3, 0.3), Point3::new(4.7, 3.7, 2.5));
        let start = fit_start_pose(&circle, &lo, &hi);
        for p in recentre(&circle, &start) {
            let t = p.translation.vector;
            assert!(
                t.x > 0.29 && t.x < 4.71 && t.z > 0.29 && t.z < 2.51,
                "{t:?}"
            );
        }
        // A small path needs no move.
        let small = &circle[..2];
        let start = fit_start_pose(small, &lo, &hi);
        assert_relative_eq!(
            start.translation.vector,
            Vector3::from(START_EYE),
            epsilon = 1e-9
        );
    }

    #[test]
    fn recentre_keeps_relative_motion() {
        let a = look_at(
            &Point3::new(0.3, -1.0, 2.0),
            &Point3::new(1.0, 1.0, 0.0),
            0.1,
        );
        let b = look_at(
            &Point3::new(0.5, -0.8, 2.1),
            &Point3::new(1.2, 1.0, 0.1),
            -0.05,
        );
        let moved = recentre(&[a, b], &default_start_pose());
        assert_relative_eq!(
            moved[0].to_homogeneous(),
            default_start_pose().to_homogeneous(),
            epsilon = 1e-12
        );
        let rel = a.inverse() * b;
        let rel_moved = moved[0].inverse() * moved[1];
        assert_relative_eq!(
            rel.to_homogeneous(),
            rel_moved.to_homogeneous(),
            epsilon = 1e-12
        );
    }
}
