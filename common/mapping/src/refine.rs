//! Offline refinement of a finished map: more Adam steps of the mapping loss (docs/METHOD.md §8) on
//! a run's keyframes in random order, with periodic pruning and, in the first half,
//! splitting of the Gaussians with the largest positional gradients ([`crate::splitting`]).

use std::ops::ControlFlow;
use std::time::Instant;

use opengs_datasets::RgbdFrame;
use opengs_geometry::{Intrinsics, Pose};
use opengs_splat::{
    downscale_camera2, prune, train_step, Adam, AdamConfig, Camera, GaussianMap, LossWeights,
    PruneConfig, TrainConfig, TrainWorkspace, DEFAULT_NEAR,
};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::pose_refinement::{
    refine_pose, PoseRefinement, PoseRefinementConfig, PoseRefinementWorkspace,
};
use crate::scene_extent::scene_extent;
use crate::splitting::{split_largest_gradients, GradientStats};
use crate::target_frame::target_frame;

/// Why a refinement could not start.
#[derive(Debug, thiserror::Error)]
pub enum RefineError {
    #[error("no keyframes to refine on")]
    NoKeyframes,
    /// A keyframe whose buffers do not match its size or the camera's.
    #[error("frame {index}: {message}")]
    Frame { index: usize, message: String },
}

/// Fewest steps between two rounds of splitting (3DGS: 100 at 15 000 steps). A 30-step
/// final optimisation split five times in 15 steps ended with a higher loss than it began.
pub const MIN_STEPS_BETWEEN_SPLITS: usize = 50;

/// How to refine.
#[derive(Debug, Clone, PartialEq)]
pub struct RefineConfig {
    pub iters: usize,
    /// Optimise at half resolution (4× cheaper per step; what the online mapper does).
    pub downscale: bool,
    /// Seed of the keyframe order.
    pub seed: u64,
    /// Prune every this many iterations (and once at the end).
    pub prune_every: usize,
    /// Rounds of splitting, evenly spread over the first half of the steps (0: never).
    /// Five, not one every 250 steps: sharp texture edges need the small Gaussians, and
    /// at the final optimisation's 600 steps one round split a tenth of the map once
    /// (scene 1's loop: 24.8 dB with one round, 25.7 with three, 26.1 with five, 26.4
    /// with ten at 1.6× the Gaussians and 1.3× the time of five).
    pub split_rounds: usize,
    /// Fraction of the map split each time (those with the largest positional gradients).
    pub densify_fraction: f32,
    /// The position learning rate decays log-linearly to this fraction of its start over
    /// the run (3DGS: 0.01 over 30k steps), so means settle instead of jittering.
    pub final_mean_lr: f32,
    /// Learning rate of the log-scales: 5× 3DGS's 0.005, which is paced for 30 000 steps;
    /// in a few hundred, each Gaussian seen in about one step of ten, edges and split
    /// children do not shrink far enough. `opengs refine --iters 600 --every 9` from the
    /// online map, PSNR at 0.005 → 0.025: chosen on scene 1's loop (24.31 → 24.93 dB; 3×
    /// 24.83, 8× 24.94) and scene 2's fr2_desk (23.78 → 24.01), both with noise; held out,
    /// with noise: scene 3's loop 31.84 → 31.95, fr2_desk scenes 1 26.63 → 26.85 and 6
    /// 28.44 → 28.55. Steps cost about 12 % more (docs/METHOD.md §8).
    pub lr_log_scale: f32,
    pub near: f32,
    pub loss: LossWeights,
    /// Smallest scene extent (m) used for the learning rate and size pruning, so a nearly
    /// static camera does not make every Gaussian "too large".
    pub min_scene_extent: f32,
    /// Times the keyframe poses are aligned photometrically to the map being optimised
    /// ([`refine_pose`]), evenly spread over the steps (0: never). One, halfway, when the
    /// map is already sharp: scene 1's loop with noise, 600 steps from the online map,
    /// held-out frames aligned afterwards: 0 rounds 26.07 dB, 1 round 26.98 (ATE of the
    /// scored poses 0.27 cm), 2 rounds 27.05 (0.34 cm); aligned before the first step, to
    /// the blurred online map, 26.70 with the ATE worse (0.54 cm).
    pub pose_rounds: usize,
    /// How each keyframe pose is aligned.
    pub poses: PoseRefinementConfig,
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self {
            iters: 1000,
            downscale: true,
            seed: 0,
            prune_every: 300,
            split_rounds: 5,
            densify_fraction: 0.1,
            final_mean_lr: 0.01,
            lr_log_scale: 0.025,
            near: DEFAULT_NEAR,
            loss: LossWeights::default(),
            min_scene_extent: 1.0,
            pose_rounds: 1,
            poses: PoseRefinementConfig::default(),
        }
    }
}

/// What a refinement did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RefineStats {
    pub iterations: usize,
    pub keyframes: usize,
    pub scene_extent: f32,
    pub gaussians_before: usize,
    pub gaussians_after: usize,
    pub pruned: usize,
    /// Gaussians split in two by densification.
    pub split: usize,
    /// Mean training loss over the first and the last tenth of the steps.
    pub first_loss: f32,
    pub last_loss: f32,
    pub seconds: f64,
    /// Mean wall-clock ms per step of its stages (what a faster step would have to cut).
    pub step_ms: RefineStepMs,
    /// What the keyframe pose refinements did.
    pub poses: PoseRoundStats,
}

/// Keyframe pose refinements over a whole refinement.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct PoseRoundStats {
    /// Poses refined (keyframes × rounds), and of those accepted.
    pub refined: usize,
    pub accepted: usize,
    /// Mean accepted correction (mm, degrees).
    pub mean_translation_mm: f64,
    pub mean_rotation_deg: f64,
    pub seconds: f64,
}

impl std::fmt::Display for PoseRoundStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "keyframe poses aligned to the map: {} of {} accepted, mean correction {:.2} mm \
             {:.3}°, {:.1} s",
            self.accepted,
            self.refined,
            self.mean_translation_mm,
            self.mean_rotation_deg,
            self.seconds
        )
    }
}

impl PoseRoundStats {
    fn add(&mut self, r: &PoseRefinement) {
        self.refined += 1;
        if r.accepted {
            let n = self.accepted as f64;
            self.mean_translation_mm =
                (self.mean_translation_mm * n + r.translation * 1e3) / (n + 1.0);
            self.mean_rotation_deg = (self.mean_rotation_deg * n + r.rotation_deg) / (n + 1.0);
            self.accepted += 1;
        }
    }
}

/// Mean wall-clock ms per refinement step: the training step's stages, and the rest (the
/// target built from the keyframe, splitting and pruning).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct RefineStepMs {
    pub render: f64,
    pub loss: f64,
    pub backward: f64,
    pub adam: f64,
    pub other: f64,
}

impl std::fmt::Display for RefineStepMs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "render {:.1}, loss {:.1}, backward {:.1}, adam {:.1}, other {:.1} ms/step",
            self.render, self.loss, self.backward, self.adam, self.other
        )
    }
}

/// Optimises `map` for `config.iters` steps on `keyframes` (frame, camera-to-world pose;
/// frames are `intrinsics`-sized), shuffling their order every pass. `progress(i, loss)`
/// is called after step i (1-based); when a pose round follows step i, also after each of its
/// keyframes, before step i's own call. `ControlFlow::Break` ends the refinement there (the
/// map is pruned and kept as it is, e.g. on Ctrl-C).
pub fn refine(
    map: &mut GaussianMap,
    keyframes: &mut [(RgbdFrame, Pose)],
    intrinsics: Intrinsics,
    config: &RefineConfig,
    mut progress: impl FnMut(usize, f32) -> ControlFlow<()>,
) -> Result<RefineStats, RefineError> {
    if keyframes.is_empty() {
        return Err(RefineError::NoKeyframes);
    }
    for (frame, _) in keyframes.iter() {
        frame
            .check_buffers(&intrinsics)
            .map_err(|message| RefineError::Frame {
                index: frame.index,
                message,
            })?;
    }
    let t0 = Instant::now();
    let extent = scene_extent(
        keyframes.iter().map(|(_, p)| *p),
        &map.means,
        config.min_scene_extent,
    );
    let camera_of = |pose: &Pose| {
        let cam = Camera::from_pose(intrinsics, pose, config.near);
        if config.downscale {
            downscale_camera2(&cam)
        } else {
            cam
        }
    };
    let mut cameras: Vec<Camera> = keyframes.iter().map(|(_, p)| camera_of(p)).collect();
    let pose_steps = pose_round_steps(config.iters, config.pose_rounds);
    let mut pose_ws = PoseRefinementWorkspace::default();
    let mut poses = PoseRoundStats::default();
    let prune_config = PruneConfig {
        scene_extent: extent,
        ..PruneConfig::default()
    };
    let gaussians_before = map.len();
    let adam_config = AdamConfig {
        lr_log_scale: config.lr_log_scale,
        ..AdamConfig::gs_defaults(extent)
    };
    let mut adam = Adam::new(adam_config, map.len());
    let mean_lr = adam.config.lr_mean;
    let mut ws = TrainWorkspace::new();
    let train = TrainConfig { loss: config.loss };
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut order: Vec<usize> = Vec::new();
    let mut losses = Vec::with_capacity(config.iters);
    let mut stats = GradientStats::default();
    stats.reset(map.len());
    let mut split = 0;
    let mut stage_sum = RefineStepMs::default();
    // Steps between rounds: the first half holds `split_rounds` of them, at least
    // `MIN_STEPS_BETWEEN_SPLITS` apart so the children of one round settle before the next.
    let split_every = (config.iters / 2)
        .checked_div(config.split_rounds)
        .unwrap_or(0)
        .max(MIN_STEPS_BETWEEN_SPLITS);
    for i in 0..config.iters {
        if order.is_empty() {
            // A fresh shuffled pass: every keyframe once per pass.
            order = (0..keyframes.len()).collect();
            order.shuffle(&mut rng);
        }
        let k = order.pop().unwrap_or(0);
        let t = i as f32 / config.iters.max(2).saturating_sub(1) as f32;
        adam.config.lr_mean = mean_lr * config.final_mean_lr.max(1e-6).powf(t);
        // Targets are built per step so only the compact RGB-D frames stay in memory.
        let full = target_frame(&keyframes[k].0);
        let target = if config.downscale {
            full.downscale2()
        } else {
            full
        };
        let step = train_step(map, &mut adam, &cameras[k], &target, &train, &mut ws);
        stage_sum.render += step.wall.render;
        stage_sum.loss += step.wall.loss;
        stage_sum.backward += step.wall.backward;
        stage_sum.adam += step.wall.adam;
        losses.push(step.loss.total);
        stats.add(&ws.grads);
        let densify = config.split_rounds > 0 && (i + 1) % split_every == 0 && i < config.iters / 2;
        if densify {
            // Seen from at least a few keyframes, so one view's noise does not decide.
            let min_views = (split_every / keyframes.len().max(1)).clamp(1, 3) as u32;
            split += split_largest_gradients(
                map,
                &mut adam,
                &stats,
                config.densify_fraction,
                min_views,
                &mut rng,
            );
        }
        let pruning = config.prune_every > 0 && (i + 1) % config.prune_every == 0;
        if pruning {
            prune(map, Some(&mut adam), &prune_config);
        }
        if densify || pruning {
            stats.reset(map.len());
        }
        if pose_steps.contains(&(i + 1)) {
            let t = Instant::now();
            let mut stopped = false;
            for ((frame, pose), camera) in keyframes.iter_mut().zip(&mut cameras) {
                let r = refine_pose(map, intrinsics, frame, pose, &config.poses, &mut pose_ws);
                poses.add(&r);
                *pose = r.pose;
                *camera = camera_of(pose);
                // A round takes 0.16 s a keyframe (10 s for 61 on 2 cores): the caller hears
                // from it after each, or a watchdog takes it for hung and a Ctrl-C waits.
                if progress(i + 1, step.loss.total).is_break() {
                    stopped = true;
                    break;
                }
            }
            poses.seconds += t.elapsed().as_secs_f64();
            if stopped {
                break;
            }
        }
        if progress(i + 1, step.loss.total).is_break() {
            break;
        }
    }
    prune(map, Some(&mut adam), &prune_config);
    let seconds = t0.elapsed().as_secs_f64();
    let steps = losses.len().max(1) as f64;
    let staged = stage_sum.render + stage_sum.loss + stage_sum.backward + stage_sum.adam;
    let step_ms = RefineStepMs {
        render: stage_sum.render / steps,
        loss: stage_sum.loss / steps,
        backward: stage_sum.backward / steps,
        adam: stage_sum.adam / steps,
        other: ((seconds * 1e3 - staged) / steps).max(0.0),
    };
    let tenth = (losses.len() / 10).max(1);
    let mean = |s: &[f32]| {
        if s.is_empty() {
            f32::NAN
        } else {
            s.iter().sum::<f32>() / s.len() as f32
        }
    };
    Ok(RefineStats {
        iterations: losses.len(),
        keyframes: keyframes.len(),
        scene_extent: extent,
        gaussians_before,
        gaussians_after: map.len(),
        pruned: (gaussians_before + split).saturating_sub(map.len()),
        split,
        first_loss: mean(&losses[..tenth.min(losses.len())]),
        last_loss: mean(&losses[losses.len().saturating_sub(tenth)..]),
        seconds,
        step_ms,
        poses,
    })
}

/// The steps after which the keyframe poses are refined: `rounds` of them, evenly spread
/// (for 600 steps and 2 rounds: after 200 and 400), never after the last step.
fn pose_round_steps(iters: usize, rounds: usize) -> Vec<usize> {
    (1..=rounds)
        .map(|r| r * iters / (rounds + 1))
        .filter(|&s| s > 0 && s < iters)
        .collect()
}
