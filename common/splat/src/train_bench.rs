//! Training-step benchmark: median ms of one forward + loss + backward + Adam step on the
//! deterministic indoor scene.

use std::fmt;
use std::time::Instant;

use crate::adam::{Adam, AdamConfig};
use crate::bench::{intrinsics_for_size, process_cpu_ms};
use crate::camera::Camera;
use crate::map::{color_to_sh_dc, sh_dc_to_color};
use crate::output::RenderRequest;
use crate::render::render;
use crate::scene::{indoor_poses, indoor_scene};
use crate::target::TargetFrame;
use crate::train::{train_step, StageMs, StepStats, TrainConfig, TrainWorkspace};

/// Medians over the timed steps of one case.
#[derive(Debug, Clone)]
pub struct TrainBenchRow {
    pub gaussians: usize,
    pub width: u32,
    pub height: u32,
    pub threads: usize,
    pub ms_step: f64,
    /// CPU ms per step summed over all threads (robust to a loaded machine).
    pub cpu_ms_step: f64,
    /// Median wall and CPU ms per stage.
    pub wall: StageMs,
    pub cpu: StageMs,
    /// PSNR before the first and after the last step.
    pub psnr_first: f32,
    pub psnr_last: f32,
}

impl TrainBenchRow {
    pub fn steps_per_s(&self) -> f64 {
        1000.0 / self.ms_step
    }
}

impl fmt::Display for TrainBenchRow {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:>7} G {:>4}x{:<4} {} thr: step {:7.2} ms ({:5.1} steps/s), cpu {:7.2} ms; wall/cpu ms: render {:.1}/{:.1}, loss {:.1}/{:.1}, backward {:.1}/{:.1}, adam {:.1}/{:.1}; PSNR {:.2} → {:.2} dB",
            self.gaussians,
            self.width,
            self.height,
            self.threads,
            self.ms_step,
            self.steps_per_s(),
            self.cpu_ms_step,
            self.wall.render,
            self.cpu.render,
            self.wall.loss,
            self.cpu.loss,
            self.wall.backward,
            self.cpu.backward,
            self.wall.adam,
            self.cpu.adam,
            self.psnr_first,
            self.psnr_last
        )
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Trains `steps` steps (after 2 warm-up steps) of the `n`-Gaussian indoor scene, colours
/// shifted by +0.1, towards its own unshifted render at `width × height`.
pub fn bench_train_steps(n: usize, width: u32, height: u32, steps: usize) -> TrainBenchRow {
    let truth = indoor_scene(n, 7);
    let cam = Camera::from_pose(
        intrinsics_for_size(width, height),
        &indoor_poses(1)[0],
        0.05,
    );
    let r = render(&truth, &cam, &RenderRequest::color_depth());
    let target = TargetFrame::from_rgb_f32(width, height, &r.output.color, &r.output.depth);
    let mut map = truth.clone();
    for f in map.sh_dc.iter_mut() {
        *f = f.map(|v| color_to_sh_dc((sh_dc_to_color(v) + 0.1).min(1.0)));
    }
    let mut adam = Adam::new(AdamConfig::gs_defaults(5.0), map.len());
    let cfg = TrainConfig::default();
    let mut ws = TrainWorkspace::new();
    let mut psnr_first = 0.0;
    for i in 0..2 {
        let s = train_step(&mut map, &mut adam, &cam, &target, &cfg, &mut ws);
        if i == 0 {
            psnr_first = s.loss.psnr;
        }
    }
    let mut wall = Vec::new();
    let mut cpu = Vec::new();
    let mut stats: Vec<StepStats> = Vec::new();
    for _ in 0..steps.max(1) {
        let (t0, c0) = (Instant::now(), process_cpu_ms());
        let s = train_step(&mut map, &mut adam, &cam, &target, &cfg, &mut ws);
        wall.push(t0.elapsed().as_secs_f64() * 1e3);
        cpu.push(process_cpu_ms() - c0);
        stats.push(s);
    }
    let stages = |cpu: bool| {
        let pick = move |s: &StepStats| if cpu { s.cpu } else { s.wall };
        StageMs {
            render: median(stats.iter().map(|s| pick(s).render).collect()),
            loss: median(stats.iter().map(|s| pick(s).loss).collect()),
            backward: median(stats.iter().map(|s| pick(s).backward).collect()),
            adam: median(stats.iter().map(|s| pick(s).adam).collect()),
        }
    };
    TrainBenchRow {
        gaussians: n,
        width,
        height,
        threads: rayon::current_num_threads(),
        ms_step: median(wall),
        cpu_ms_step: median(cpu),
        wall: stages(false),
        cpu: stages(true),
        psnr_first,
        psnr_last: stats.last().map_or(0.0, |s| s.loss.psnr),
    }
}
