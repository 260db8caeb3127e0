use std::collections::VecDeque;

use opengs_geometry::nalgebra::{Matrix3, Translation3, UnitQuaternion, Vector3};
use opengs_geometry::Pose;

/// Gaps longer than this (s) are not extrapolated: the camera may have done anything.
pub const MAX_EXTRAPOLATION_S: f64 = 0.5;

/// Constant-velocity motion model over time: the next pose repeats the verified
/// motion of the last [`VELOCITY_BASELINE_S`], scaled to the time since (so a frame
/// after five dropped ones is predicted six steps ahead, not one).
#[derive(Debug, Clone, Default)]
pub struct ConstantVelocity {
    /// Verified poses of the last `MAX_EXTRAPOLATION_S` and their times (s), oldest
    /// first; the newest is the last verified pose.
    recent: VecDeque<(Pose, f64)>,
    /// Relative motion from the baseline pose to the newest, `T_b⁻¹ · T_k`, and its
    /// duration (s).
    step: Option<(Pose, f64)>,
}

/// The velocity is measured over at least this long (s), not over the last frame: a
/// pose's few millimetres and tenths of a degree of noise, divided by one frame's
/// 33 ms and extrapolated across a gap, sent the fine registration off by up to 2.3°
/// (fr2_desk with Kinect-like noise).
pub const VELOCITY_BASELINE_S: f64 = 0.1;

impl ConstantVelocity {
    /// A verified pose at time `t` (s).
    pub fn update(&mut self, pose: Pose, t: f64) {
        // Time that runs backwards or a long gap: no velocity from before.
        if self
            .recent
            .back()
            .is_some_and(|(_, t_last)| !(t > *t_last && t - t_last <= MAX_EXTRAPOLATION_S))
        {
            self.recent.clear();
        }
        self.recent.retain(|(_, ti)| t - ti <= MAX_EXTRAPOLATION_S);
        let base = self
            .recent
            .iter()
            .rev()
            .find(|(_, ti)| t - ti >= VELOCITY_BASELINE_S)
            .or(self.recent.front());
        self.step = base.map(|(b, tb)| (b.inverse() * pose, t - tb));
        self.recent.push_back((pose, t));
    }

    /// Forgets the velocity (after tracking was lost: the old motion says nothing).
    pub fn stop(&mut self) {
        self.step = None;
        let last = self.recent.back().copied();
        self.recent.clear();
        self.recent.extend(last);
    }

    /// Whether a velocity is known (two verified poses within the horizon, none lost since).
    pub fn has_velocity(&self) -> bool {
        self.step.is_some()
    }

    /// The last verified pose and its time.
    pub fn last(&self) -> Option<(Pose, f64)> {
        self.recent.back().copied()
    }

    /// `T(t) = T_last · step^((t − t_last) / dt)` (the step's screw motion, scaled); the
    /// last pose when no velocity is known or `t` lies beyond the extrapolation horizon.
    pub fn predict(&self, t: f64) -> Option<Pose> {
        let (last, t_last) = self.last()?;
        let ahead = t - t_last;
        let Some((step, dt)) = self.step else {
            return Some(last);
        };
        if !(ahead > 0.0 && ahead <= MAX_EXTRAPOLATION_S) {
            return Some(last);
        }
        Some(last * power(&step, ahead / dt))
    }
}

/// `V(ω) = I + (1 − cos θ)/θ² [ω]× + (θ − sin θ)/θ³ [ω]×²`, which maps a twist's
/// translation part to the translation of its exponential.
fn left_jacobian(omega: &Vector3<f64>) -> Matrix3<f64> {
    let theta = omega.norm();
    let k = omega.cross_matrix();
    if theta < 1e-9 {
        return Matrix3::identity() + k * 0.5;
    }
    let (s, c) = theta.sin_cos();
    Matrix3::identity() + k * ((1.0 - c) / (theta * theta)) + k * k * ((theta - s) / theta.powi(3))
}

/// `T^s = exp(s · log T)` on SE(3).
fn power(t: &Pose, s: f64) -> Pose {
    let omega = t.rotation.scaled_axis();
    let v = left_jacobian(&omega)
        .try_inverse()
        .map_or(t.translation.vector, |inv| inv * t.translation.vector);
    let scaled = omega * s;
    Pose::from_parts(
        Translation3::from(left_jacobian(&scaled) * (v * s)),
        UnitQuaternion::from_scaled_axis(scaled),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step() -> Pose {
        Pose::from_parts(
            Translation3::new(0.01, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.01),
        )
    }

    fn close_within(a: &Pose, b: &Pose, metres: f64) -> bool {
        (a.translation.vector - b.translation.vector).norm() < metres
            && a.rotation.angle_to(&b.rotation) < 1e-12
    }

    fn close(a: &Pose, b: &Pose) -> bool {
        close_within(a, b, 1e-12)
    }

    #[test]
    fn repeats_the_last_motion_scaled_to_the_time_since() {
        let mut m = ConstantVelocity::default();
        assert!(m.predict(0.0).is_none());
        m.update(Pose::identity(), 0.0);
        assert_eq!(m.predict(0.1), Some(Pose::identity()));
        m.update(step(), 0.1);
        // One step ahead: step². Three steps ahead (two frames dropped): step⁴.
        assert!(close(&m.predict(0.2).expect("known"), &(step() * step())));
        let four = step() * step() * step() * step();
        assert!(close_within(&m.predict(0.4).expect("known"), &four, 1e-12));
        // Half a step, twice, is one step.
        let half = power(&step(), 0.5);
        assert!(close(&(half * half), &step()));
    }

    #[test]
    fn the_velocity_spans_a_tenth_of_a_second_so_pose_jitter_is_not_extrapolated() {
        // 30 Hz at 0.3 m/s along x, each verified pose 2 mm and 0.2° off, alternately
        // either way (a tracked pose's noise).
        let fps = 30.0;
        let jitter = |k: i32| {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            Pose::from_parts(
                Translation3::new(0.002 * sign, 0.0, 0.0),
                UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.2f64.to_radians() * sign),
            )
        };
        let truth = |k: i32| Pose::translation(0.3 * f64::from(k) / fps, 0.0, 0.0);
        let mut m = ConstantVelocity::default();
        for k in 0..10 {
            m.update(truth(k) * jitter(k), f64::from(k) / fps);
        }
        // Four frames dropped: the next pose is five frames ahead.
        let predicted = m.predict(14.0 / fps).expect("known");
        let off = truth(14).inverse() * predicted;
        assert!(
            off.translation.vector.norm() < 0.01,
            "{}",
            off.translation.vector
        );
        assert!(off.rotation.angle() < 1f64.to_radians());
        // The last frame's motion alone, five times over: 22 mm and 2.2° off.
        let one_frame = (truth(8) * jitter(8)).inverse() * (truth(9) * jitter(9));
        let from_one = truth(9) * jitter(9) * power(&one_frame, 5.0);
        let off = truth(14).inverse() * from_one;
        assert!(off.translation.vector.norm() > 0.02);
        assert!(off.rotation.angle() > 2f64.to_radians());
    }

    #[test]
    fn long_gaps_and_stops_hold_the_last_pose() {
        let mut m = ConstantVelocity::default();
        m.update(Pose::identity(), 0.0);
        m.update(step(), 0.1);
        assert!(close(&m.predict(5.0).expect("known"), &step()));
        m.stop();
        assert!(close(&m.predict(0.2).expect("known"), &step()));
        // A verified pose after a long gap gives no velocity either.
        m.update(step() * step(), 3.0);
        assert!(close(&m.predict(3.1).expect("known"), &(step() * step())));
    }
}
