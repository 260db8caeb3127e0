use opengs_geometry::Pose;

/// Frames a failed tracker keeps extrapolating before it assumes the camera stopped.
const MAX_COAST_FRAMES: u32 = 3;

/// Constant-velocity motion model: the next pose repeats the last tracked relative motion.
#[derive(Debug, Clone, Default)]
pub struct ConstantVelocity {
    last: Option<Pose>,
    /// Relative motion of the last tracked step, `T_{k−2}⁻¹ · T_{k−1}`.
    velocity: Option<Pose>,
    coasted: u32,
}

impl ConstantVelocity {
    /// A tracked pose.
    pub fn update(&mut self, pose: Pose) {
        self.velocity = self.last.map(|l| l.inverse() * pose);
        self.last = Some(pose);
        self.coasted = 0;
    }

    /// A guessed pose (tracking failed): keep the velocity, for a few frames only.
    pub fn coast(&mut self, pose: Pose) {
        self.last = Some(pose);
        self.coasted += 1;
        if self.coasted >= MAX_COAST_FRAMES {
            self.velocity = None;
        }
    }

    pub fn last(&self) -> Option<Pose> {
        self.last
    }

    /// `T_k ≈ T_{k−1} · v`, or the last pose when no velocity is known.
    pub fn predict(&self) -> Option<Pose> {
        let last = self.last?;
        Some(match self.velocity {
            Some(v) => last * v,
            None => last,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_geometry::nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn step() -> Pose {
        Pose::from_parts(
            Translation3::new(0.1, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.1),
        )
    }

    fn close(a: &Pose, b: &Pose) -> bool {
        (a.translation.vector - b.translation.vector).norm() < 1e-12
            && a.rotation.angle_to(&b.rotation) < 1e-12
    }

    #[test]
    fn repeats_the_last_motion() {
        let mut m = ConstantVelocity::default();
        assert!(m.predict().is_none());
        m.update(Pose::identity());
        assert_eq!(m.predict(), Some(Pose::identity()));
        m.update(step());
        assert!(close(&m.predict().expect("known"), &(step() * step())));
    }

    #[test]
    fn coasting_stops_after_a_few_failures() {
        let mut m = ConstantVelocity::default();
        m.update(Pose::identity());
        m.update(step());
        let mut pose = step();
        for _ in 0..MAX_COAST_FRAMES {
            pose = m.predict().expect("known");
            m.coast(pose);
        }
        // Velocity dropped: the guess now holds still instead of running away.
        assert!(close(&m.predict().expect("known"), &pose));
    }
}
