//! Where to look while lost. Registration from the last verified pose failed;
//! the camera is somewhere near it, or back near a place it has mapped. The
//! relocaliser hands out starting guesses, a few per frame so a lost frame
//! costs about what a tracked one does: the last verified pose, that pose
//! panned, tilted and moved along each camera axis (one ring, then one twice
//! as wide), then the poses of every keyframe, nearest first (a camera that
//! comes back to where it mapped is near one of them). Each guess goes
//! through the coarse stages; one whose estimate does not see through the
//! model goes on to the fine registration and the verification, with a
//! stricter fitness since no motion prior vouches for the answer. A camera that comes
//! back far from every keyframe (fr2_desk after its 12 s gap: 2–4.5 m + rad from the
//! nearest) is out of reach of all of them; off the tracking path, global registration
//! of the frame against the model ([`opengs_gicp::register_global`]) proposes poses too.

use opengs_geometry::nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};
use opengs_geometry::Pose;
use opengs_gicp::GlobalConfig;

use crate::{SettleConfig, VerifyConfig};

/// Relocalisation settings.
#[derive(Debug, Clone, PartialEq)]
pub struct RelocaliseConfig {
    /// Guesses tried per attempt …
    pub guesses_per_frame: usize,
    /// … and attempts at most this often (s of the frames' clock): a guess costs more than
    /// a tracked frame, and a camera at 30 Hz must not fall behind while lost.
    pub attempt_every_s: f64,
    /// Translation (m) and rotation (rad) of the inner ring of guesses.
    pub step: f64,
    pub turn: f64,
    /// Iterations of the fine registration from a screened guess.
    pub fine_iterations: usize,
    /// A guess goes on to the fine registration only when, after the coarse stages, at
    /// most this share of the model in view lies in front of the frame's depth.
    pub screen_violation: f64,
    /// The verification a relocalised pose must pass (no motion prior).
    pub verify: VerifyConfig,
    /// Global registration against the model, and the verification of a pose it proposed.
    pub global: GlobalConfig,
    pub global_verify: VerifyConfig,
    /// How a pose relocalised after the spell's first attempt is settled, and refused when
    /// the view does not determine it ([`crate::ambiguity`]).
    pub settle: SettleConfig,
    /// A pose found off the tracking path is tracked on over the lost frames for this long
    /// (s) before it ends the spell ([`crate::relocalise_worker`]) … Scene 1's teleport: poses
    /// found 2.84 and 2.67 cm off came within 0.3 cm 0.70 and 0.83 s on.
    pub track_on_s: f64,
    /// … or until a view fits less of the model than this: with no keyframe added, a camera
    /// moving on leaves the map behind (the fitness fell 0.70 → 0.50 over 0.9 s in
    /// `the_threaded_tracker_relocalises_…`), and the tracker must add keyframes to follow.
    pub track_on_min_fitness: f64,
}

impl Default for RelocaliseConfig {
    fn default() -> Self {
        Self {
            guesses_per_frame: 1,
            attempt_every_s: 0.15,
            step: 0.15,
            turn: 12f64.to_radians(),
            screen_violation: 0.3,
            fine_iterations: 15,
            // No motion prior vouches for a relocalised pose, and a wrong one poisons the
            // map: stricter than tracking (fr2_desk along scene 1: a pose 3.8 m off fitted
            // 82 % of a floor-filled view and saw through 9 % of the model).
            verify: VerifyConfig {
                min_fitness: 0.7,
                max_violation: 0.05,
                ..VerifyConfig::default()
            },
            global: GlobalConfig::default(),
            // Right after a teleport much of the view is not mapped yet: the true pose fits
            // 0.56–0.68 of the frame (scene 5 along fr2_desk, frames 671–911), under the 0.7
            // above; what rules out wrong poses is how little of the model they see through
            // (the true one 0.2–2 %, wrong hypotheses 13–40 % but one, which fitted 0.49).
            global_verify: VerifyConfig {
                min_fitness: 0.6,
                max_violation: 0.05,
                ..VerifyConfig::default()
            },
            settle: SettleConfig::default(),
            track_on_s: 1.5,
            track_on_min_fitness: 0.6,
        }
    }
}

/// Hands out the guesses of one lost spell, cycling through them.
#[derive(Debug, Clone, Default)]
pub struct Relocaliser {
    guesses: Vec<Pose>,
    next: usize,
    /// Where the keyframes were taken (the model's surfaces face them).
    viewpoints: Vec<Point3<f64>>,
}

impl Relocaliser {
    /// A new lost spell: guesses around `anchor` (the last verified pose), then every
    /// keyframe pose, nearest to it first.
    pub fn start(anchor: &Pose, keyframe_poses: &[Pose], config: &RelocaliseConfig) -> Self {
        let mut guesses = vec![*anchor];
        for scale in [1.0, 2.0] {
            let (step, turn) = (config.step * scale, config.turn * scale);
            // Camera axes: x right, y down (pan about it), z forward.
            for (axis, angle) in [(Vector3::y(), turn), (Vector3::x(), turn)] {
                for sign in [1.0, -1.0] {
                    let r = UnitQuaternion::from_scaled_axis(axis * angle * sign);
                    guesses.push(anchor * Pose::from_parts(Translation3::identity(), r));
                }
            }
            for axis in [Vector3::x(), Vector3::z(), Vector3::y()] {
                for sign in [1.0, -1.0] {
                    let t = Translation3::from(axis * step * sign);
                    guesses.push(anchor * Pose::from_parts(t, UnitQuaternion::identity()));
                }
            }
        }
        let viewpoints = keyframe_poses
            .iter()
            .map(|k| Point3::from(k.translation.vector))
            .collect();
        let mut nearest: Vec<(f64, Pose)> = keyframe_poses
            .iter()
            .map(|k| {
                let d = anchor.inverse() * k;
                // Metres plus radians: a 10° turn weighs like 17 cm.
                (d.translation.vector.norm() + d.rotation.angle(), *k)
            })
            .filter(|(distance, _)| *distance > 1e-6)
            .collect();
        nearest.sort_by(|a, b| a.0.total_cmp(&b.0));
        guesses.extend(nearest.into_iter().map(|(_, p)| p));
        Self {
            guesses,
            next: 0,
            viewpoints,
        }
    }

    /// Where the keyframes were taken.
    pub fn viewpoints(&self) -> &[Point3<f64>] {
        &self.viewpoints
    }

    /// The next `n` guesses (cycling), empty when there are none.
    pub fn next_guesses(&mut self, n: usize) -> Vec<Pose> {
        if self.guesses.is_empty() {
            return Vec::new();
        }
        (0..n.min(self.guesses.len()))
            .map(|_| {
                let g = self.guesses[self.next % self.guesses.len()];
                self.next += 1;
                g
            })
            .collect()
    }

    pub fn len(&self) -> usize {
        self.guesses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.guesses.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn guesses_ring_the_anchor_then_visit_keyframes_and_cycle() {
        let anchor = Pose::translation(1.0, 2.0, 3.0);
        let keyframes = [
            Pose::translation(1.0, 2.0, 3.0), // the anchor itself: not repeated
            Pose::translation(5.0, 2.0, 3.0),
            Pose::translation(1.5, 2.0, 3.0),
        ];
        let c = RelocaliseConfig::default();
        let mut r = Relocaliser::start(&anchor, &keyframes, &c);
        // 1 anchor + 2 rings × (4 turns + 6 moves) + 2 keyframes.
        assert_eq!(r.len(), 1 + 2 * 10 + 2);
        let first = r.next_guesses(2);
        assert_eq!(first[0], anchor);
        let pan = anchor.inverse() * first[1];
        assert!((pan.rotation.angle() - c.turn).abs() < 1e-12);
        let rest = r.next_guesses(100);
        assert_eq!(rest.len(), r.len());
        // The nearest keyframe comes before the far one, and the cycle goes on.
        assert_eq!(rest[19], keyframes[2]);
        assert_eq!(rest[20], keyframes[1]);
        assert_eq!(rest[21], anchor);
    }
}
