//! One mapping optimisation step: render (colour + depth) → loss → backward → Adam.

use std::time::Instant;

use crate::adam::Adam;
use crate::backward::Backward;
use crate::bench::process_cpu_ms;
use crate::camera::Camera;
use crate::grads::MapGrads;
use crate::loss::{Loss, LossValue, LossWeights};
use crate::map::GaussianMap;
use crate::output::RenderRequest;
use crate::render::{render_into, Rendered};
use crate::target::TargetFrame;

/// Settings of a training step (learning rates live in [`Adam::config`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TrainConfig {
    pub loss: LossWeights,
}

/// What one step did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepStats {
    /// Loss terms before the update.
    pub loss: LossValue,
    /// Gaussians with a non-zero opacity gradient (≈ those that touched a pixel).
    pub touched: usize,
    /// Wall-clock ms per stage.
    pub wall: StageMs,
    /// CPU ms per stage, summed over threads (robust on a loaded machine).
    pub cpu: StageMs,
}

/// Milliseconds per stage of a step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageMs {
    pub render: f64,
    pub loss: f64,
    pub backward: f64,
    pub adam: f64,
}

impl StageMs {
    pub fn total(&self) -> f64 {
        self.render + self.loss + self.backward + self.adam
    }
}

/// Buffers reused across steps (images, gradients): keep one per mapper thread.
#[derive(Debug, Default)]
pub struct TrainWorkspace {
    pub rendered: Rendered,
    pub grads: MapGrads,
    dl_dcolor: Vec<[f32; 3]>,
    dl_ddepth: Vec<f32>,
    loss: Loss,
    backward: Backward,
}

impl TrainWorkspace {
    pub fn new() -> Self {
        Self::default()
    }
}

/// One optimisation step of `map` towards `target` seen from `camera` (same size as the
/// target; for reduced resolution pass `downscale_camera2(cam)` and `target.downscale2()`).
/// Appended Gaussians get fresh Adam moments; after removing Gaussians call
/// [`Adam::compact`] (or use [`crate::prune`], which does).
pub fn train_step(
    map: &mut GaussianMap,
    adam: &mut Adam,
    camera: &Camera,
    target: &TargetFrame,
    config: &TrainConfig,
    ws: &mut TrainWorkspace,
) -> StepStats {
    assert_eq!(
        (camera.width(), camera.height()),
        (target.width, target.height),
        "camera and target sizes differ"
    );
    let mut lap = Lap::new();
    render_into(map, camera, &RenderRequest::color_depth(), &mut ws.rendered);
    let render = lap.ms();
    let out = &ws.rendered.output;
    let loss = ws.loss.eval(
        &out.color,
        &out.depth,
        target,
        &config.loss,
        &mut ws.dl_dcolor,
        &mut ws.dl_ddepth,
    );
    let loss_ms = lap.ms();
    ws.backward.run(
        map,
        camera,
        &ws.rendered,
        &ws.dl_dcolor,
        &ws.dl_ddepth,
        &mut ws.grads,
    );
    let backward = lap.ms();
    let touched = ws
        .grads
        .opacity_logits
        .iter()
        .filter(|&&g| g != 0.0)
        .count();
    adam.update(map, &ws.grads);
    let adam_ms = lap.ms();
    let stage = |i: usize| StageMs {
        render: render[i],
        loss: loss_ms[i],
        backward: backward[i],
        adam: adam_ms[i],
    };
    StepStats {
        loss,
        touched,
        wall: stage(0),
        cpu: stage(1),
    }
}

/// Lap timer: [wall, CPU] ms since the previous lap.
struct Lap(Instant, f64);

impl Lap {
    fn new() -> Self {
        Self(Instant::now(), process_cpu_ms())
    }

    fn ms(&mut self) -> [f64; 2] {
        let (now, cpu) = (Instant::now(), process_cpu_ms());
        let ms = [(now - self.0).as_secs_f64() * 1e3, cpu - self.1];
        (self.0, self.1) = (now, cpu);
        ms
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adam::AdamConfig;
    use crate::prune::{prune, PruneConfig};
    use crate::scene::{indoor_poses, indoor_scene};
    use crate::target::downscale_camera2;

    #[test]
    fn steps_survive_pruning_appending_and_half_resolution() {
        let k = opengs_geometry::Intrinsics::new(262.5, 262.5, 159.5, 119.5, 320, 240);
        let cam = Camera::from_pose(k, &indoor_poses(1)[0], 0.05);
        let truth = indoor_scene(3000, 1);
        let r = crate::render::render(&truth, &cam, &RenderRequest::color_depth());
        let full = TargetFrame::from_rgb_f32(320, 240, &r.output.color, &r.output.depth);
        let (half_cam, half) = (downscale_camera2(&cam), full.downscale2());
        let mut map = truth.clone();
        map.opacity_logits[0] = -8.0; // prunable
        let mut adam = Adam::new(AdamConfig::gs_defaults(5.0), map.len());
        let mut ws = TrainWorkspace::new();
        let cfg = TrainConfig::default();
        let s = train_step(&mut map, &mut adam, &half_cam, &half, &cfg, &mut ws);
        assert!(s.touched > 0 && s.loss.total.is_finite());
        prune(&mut map, Some(&mut adam), &PruneConfig::default());
        assert_eq!(adam.len(), map.len());
        map.push(truth.get(1));
        let s = train_step(&mut map, &mut adam, &cam, &full, &cfg, &mut ws);
        assert_eq!(adam.len(), map.len());
        assert!(s.loss.psnr > 20.0, "{:?}", s.loss);
    }
}
