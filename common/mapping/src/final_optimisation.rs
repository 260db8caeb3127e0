//! The mapper's final optimisation: when the supervisor signals the end of the data
//! (SIGUSR1), the map gets a last round of full-resolution Adam steps with splitting on the
//! keyframes (the offline `opengs refine`, run where the keyframes already are). Online the
//! mapper only affords about one half-resolution step per keyframe per second of data, so
//! texture detail finer than the 2 cm keyframe sampling stays blurred until this pass.

use std::ops::ControlFlow;
use std::time::Instant;

use opengs_datasets::RgbdFrame;
use opengs_geometry::{Intrinsics, Pose};
use opengs_splat::{downscale_camera2, Camera, GaussianMap};

use crate::densify::{gaussians_for_holes, DensifyInput};
use crate::refine::{refine, RefineConfig, RefineStats};
use crate::MapperConfig;

/// Full-resolution keyframes kept for the final optimisation (RGB8 and raw depth: about
/// 1.5 MB per 640×480 keyframe). Past `max` keyframes every other one is dropped, so the
/// kept set still spans the whole trajectory.
#[derive(Debug, Default)]
pub struct KeptKeyframes {
    frames: Vec<(RgbdFrame, Pose)>,
    intrinsics: Option<Intrinsics>,
    max: usize,
}

impl KeptKeyframes {
    pub fn new(max: usize) -> Self {
        Self {
            frames: Vec::new(),
            intrinsics: None,
            max: max.max(2),
        }
    }

    /// Keeps one keyframe. A keyframe from a camera of another size than the first is
    /// refused (the final optimisation runs with one camera model).
    pub fn push(
        &mut self,
        seq: u64,
        pose: Pose,
        k: Intrinsics,
        rgb: &[u8],
        depth: &[u16],
        depth_scale: f32,
    ) -> Result<(), String> {
        match self.intrinsics {
            Some(first) if first != k => {
                return Err(format!(
                    "keyframe #{seq}: camera {k:?} differs from the first keyframe's {first:?}; \
                     not kept for the final optimisation"
                ))
            }
            _ => self.intrinsics = Some(k),
        }
        let frame = RgbdFrame {
            index: seq as usize,
            timestamp: 0.0,
            width: k.width,
            height: k.height,
            rgb: rgb.to_vec(),
            depth: depth.to_vec(),
            depth_scale,
            gt_pose: None,
            labels: None,
        };
        self.frames.push((frame, pose));
        if self.frames.len() > self.max {
            let mut i = 0;
            self.frames.retain(|_| {
                i += 1;
                i % 2 == 1
            });
        }
        Ok(())
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
}

/// Closes what the final optimisation's pruning opened: the depth each kept keyframe sees
/// that the map, rendered there (at half resolution), leaves open becomes new Gaussians
/// ([`crate::HoleFilling`]). `progress(done)` is called after each keyframe (2.4 s for 61
/// on 2 cores, so past 250 kept keyframes a watchdog's 10 s if it heard nothing);
/// `ControlFlow::Break` stops there. Returns how many were added.
pub fn fill_holes(
    map: &mut GaussianMap,
    kept: &KeptKeyframes,
    config: &MapperConfig,
    mut progress: impl FnMut(usize) -> ControlFlow<()>,
) -> usize {
    let Some(k) = kept.intrinsics else {
        return 0;
    };
    let mut added = 0;
    for (done, (frame, pose)) in kept.frames.iter().enumerate() {
        let input = DensifyInput {
            points: &[],
            covariances: &[],
            pose: *pose,
            intrinsics: k,
            rgb: &frame.rgb,
            depth: &frame.depth,
            depth_scale: frame.depth_scale,
        };
        let camera = downscale_camera2(&Camera::from_pose(k, pose, config.near));
        let new = gaussians_for_holes(
            &input,
            map,
            &camera,
            &config.holes,
            config.initial_opacity,
            config.initial_scale,
        );
        added += new.len();
        new.iter().for_each(|g| map.push(*g));
        if progress(done + 1).is_break() {
            break;
        }
    }
    added
}

/// How many final steps `keyframes` kept keyframes get: `min_steps`, or `per_keyframe` for
/// each keyframe when that is more (0 `min_steps`: none). A fixed count spread over a long
/// run's keyframes leaves each too few steps to sharpen.
pub fn final_step_count(min_steps: usize, per_keyframe: usize, keyframes: usize) -> usize {
    if min_steps == 0 {
        return 0;
    }
    min_steps.max(per_keyframe.saturating_mul(keyframes))
}

/// Runs `steps` full-resolution steps on the kept keyframes. `progress(done, loss)` is called
/// after every step; `ControlFlow::Break` (a termination request) stops early, keeping the map as
/// it is then. Returns `None` when there is nothing to optimise.
pub fn optimise_final(
    map: &mut GaussianMap,
    kept: &mut KeptKeyframes,
    steps: usize,
    near: f32,
    progress: impl FnMut(usize, f32) -> ControlFlow<()>,
) -> Result<Option<RefineStats>, crate::RefineError> {
    let Some(k) = kept.intrinsics else {
        return Ok(None);
    };
    if steps == 0 || map.is_empty() || kept.is_empty() {
        return Ok(None);
    }
    let config = RefineConfig {
        iters: steps,
        downscale: false,
        near,
        ..RefineConfig::default()
    };
    let t0 = Instant::now();
    let stats = refine(map, &mut kept.frames, k, &config, progress)?;
    tracing::info!(
        "final optimisation: {} steps on {} keyframes in {:.1} s, loss {:.4} → {:.4}, \
         {} → {} Gaussians ({} split, {} pruned); {}; {}",
        stats.iterations,
        stats.keyframes,
        t0.elapsed().as_secs_f64(),
        stats.first_loss,
        stats.last_loss,
        stats.gaussians_before,
        stats.gaussians_after,
        stats.split,
        stats.pruned,
        stats.step_ms,
        stats.poses
    );
    Ok(Some(stats))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn push(kept: &mut KeptKeyframes, seq: u64, k: Intrinsics) -> Result<(), String> {
        let n = (k.width * k.height) as usize;
        kept.push(
            seq,
            Pose::identity(),
            k,
            &vec![0u8; 3 * n],
            &vec![1000u16; n],
            1000.0,
        )
    }

    #[test]
    fn final_steps_grow_with_the_keyframes_past_the_minimum() {
        // 600 steps, 4 per keyframe: 150 keyframes is where the count starts to grow.
        assert_eq!(final_step_count(600, 4, 61), 600);
        assert_eq!(final_step_count(600, 4, 150), 600);
        assert_eq!(final_step_count(600, 4, 151), 604);
        assert_eq!(final_step_count(600, 4, 225), 900);
        // An explicit count (no per-keyframe share) is kept as given; 0 stays none.
        assert_eq!(final_step_count(600, 0, 225), 600);
        assert_eq!(final_step_count(0, 4, 225), 0);
    }

    #[test]
    fn kept_keyframes_thin_to_span_the_run() {
        let k = Intrinsics::new(4.0, 4.0, 2.0, 2.0, 4, 4);
        let mut kept = KeptKeyframes::new(4);
        for seq in 0..9 {
            push(&mut kept, seq, k).expect("same camera");
        }
        let seqs: Vec<usize> = kept.frames.iter().map(|(f, _)| f.index).collect();
        // 0..4 kept; the 5th halves to 0,2,4; then 5,6 → 0,2,4,5,6 → 0,4,6; 7,8 → 0,4,6,7,8 → 0,6,8.
        assert_eq!(seqs, vec![0, 6, 8]);
        let other = Intrinsics::new(4.0, 4.0, 2.0, 2.0, 8, 4);
        let err = push(&mut kept, 9, other).expect_err("another camera");
        assert!(err.contains("keyframe #9"), "{err}");
        assert_eq!(kept.len(), 3);
    }
}
