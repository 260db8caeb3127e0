//! Render benchmark: deterministic indoor scenes, median ms per frame with and without the
//! semantic outputs (labels + top-K + visible counts).

use std::fmt;
use std::time::Instant;

use opengs_geometry::Intrinsics;

use crate::camera::Camera;
use crate::map::GaussianMap;
use crate::output::{RenderRequest, DEFAULT_TOP_K};
use crate::render::{render, render_into};
use crate::scene::{indoor_poses, indoor_scene};

#[derive(Debug, Clone)]
pub struct BenchConfig {
    pub gaussian_counts: Vec<usize>,
    pub intrinsics: Vec<Intrinsics>,
    /// Timed frames per case (after one warm-up frame); each uses the next pose of an arc.
    pub frames: usize,
    /// Renders of each frame per request; the fastest counts (1: every frame once). More
    /// steady figures on a shared machine, where slow spells only ever add time.
    pub repeat: usize,
    pub top_k: usize,
    /// Also time project / bin+sort / rasterize of one semantic frame per case.
    pub breakdown: bool,
}

/// Pinhole camera for a benchmark image size, principal point at the image centre:
/// Replica's focal (600) at 1200×680, else TUM's (525 at 640 wide) scaled with the width.
pub fn intrinsics_for_size(width: u32, height: u32) -> Intrinsics {
    let f = match (width, height) {
        (1200, 680) => 600.0,
        _ => 525.0 * width as f64 / 640.0,
    };
    let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
    Intrinsics::new(f, f, cx, cy, width, height)
}

impl Default for BenchConfig {
    fn default() -> Self {
        Self {
            gaussian_counts: vec![100_000, 500_000],
            intrinsics: vec![
                intrinsics_for_size(640, 480),
                intrinsics_for_size(1200, 680),
            ],
            frames: 9,
            repeat: 1,
            top_k: DEFAULT_TOP_K,
            breakdown: false,
        }
    }
}

#[derive(Debug, Clone)]
pub struct BenchRow {
    pub gaussians: usize,
    pub width: u32,
    pub height: u32,
    /// Median ms per frame, colour + depth (+ silhouette) only.
    pub ms_color_depth: f64,
    /// Median ms per frame, colour + depth + labels + top-K + visible counts.
    pub ms_semantic: f64,
    /// Median CPU ms per frame summed over all threads (a): robust to a shared machine.
    pub cpu_ms_color_depth: f64,
    /// Median CPU ms per frame summed over all threads (b).
    pub cpu_ms_semantic: f64,
    /// Median over frames of (b) / (a) − 1, each pair rendered back to back.
    pub overhead: f64,
    /// Mean top-K entries stored per pixel.
    pub topk_per_pixel: f64,
    /// Median ms of colour + depth + labels only, and of colour + depth + top-K only: where
    /// (b)'s overhead is.
    pub ms_labels_only: f64,
    pub ms_top_k_only: f64,
    /// Project / bin+sort / rasterize of one (b) frame, when asked for.
    pub breakdown: Option<String>,
}

#[derive(Debug, Clone)]
pub struct BenchReport {
    pub rows: Vec<BenchRow>,
    pub bytes_per_gaussian: usize,
    pub threads: usize,
    /// Renders of each frame per request (the fastest counts).
    pub repeat: usize,
}

impl fmt::Display for BenchReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "render benchmark ({} threads, {} bytes/Gaussian, medians over frames{})",
            self.threads,
            self.bytes_per_gaussian,
            if self.repeat > 1 {
                format!(" of the fastest of {} renders each", self.repeat)
            } else {
                String::new()
            }
        )?;
        writeln!(
            f,
            "{:>9} {:>10} {:>12} {:>8} {:>14} {:>8} {:>9} {:>11} {:>11} {:>8} {:>11} {:>11}",
            "gaussians",
            "size",
            "col+dep ms",
            "fps",
            "+lab+topK ms",
            "fps",
            "overhead",
            "cpu ms (a)",
            "cpu ms (b)",
            "topK/px",
            "a+lab ms",
            "a+topK ms"
        )?;
        for r in &self.rows {
            writeln!(
                f,
                "{:>9} {:>10} {:>12.2} {:>8.1} {:>14.2} {:>8.1} {:>8.1}% {:>11.2} {:>11.2} {:>8.1} {:>11.2} {:>11.2}",
                r.gaussians,
                format!("{}x{}", r.width, r.height),
                r.ms_color_depth,
                1000.0 / r.ms_color_depth,
                r.ms_semantic,
                1000.0 / r.ms_semantic,
                100.0 * r.overhead,
                r.cpu_ms_color_depth,
                r.cpu_ms_semantic,
                r.topk_per_pixel,
                r.ms_labels_only,
                r.ms_top_k_only
            )?;
        }
        for r in &self.rows {
            if let Some(b) = &r.breakdown {
                writeln!(
                    f,
                    "(b), {} Gaussians, {}x{}, one frame:",
                    r.gaussians, r.width, r.height
                )?;
                write!(f, "{b}")?;
            }
        }
        Ok(())
    }
}

/// CPU time of the whole process (all threads), in ms: robust to other processes on a busy box.
pub fn process_cpu_ms() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime only writes the timespec we pass.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return f64::NAN;
    }
    ts.tv_sec as f64 * 1e3 + ts.tv_nsec as f64 * 1e-6
}

/// Wall and CPU ms of each forward stage for one frame, for profiling.
/// `out` is reused across calls, as a SLAM loop would.
pub fn stage_breakdown(
    map: &GaussianMap,
    cam: &Camera,
    req: &RenderRequest,
    out: &mut crate::RenderOutput,
) -> String {
    use crate::{bin_and_sort, project, rasterize_into, TileGrid};
    let grid = TileGrid::new(cam.width(), cam.height());
    let mut lines = String::new();
    let mut t = (Instant::now(), process_cpu_ms());
    let mut lap = |name: &str, lines: &mut String| {
        let now = (Instant::now(), process_cpu_ms());
        lines.push_str(&format!(
            "{name:>10}: wall {:7.2} ms  cpu {:7.2} ms\n",
            (now.0 - t.0).as_secs_f64() * 1e3,
            now.1 - t.1
        ));
        t = (Instant::now(), process_cpu_ms());
    };
    let p = project(map, cam, &grid);
    lap("project", &mut lines);
    let b = bin_and_sort(&p, &grid);
    lap("bin+sort", &mut lines);
    rasterize_into(&p, &b, &grid, &map.labels, req, out);
    lap("rasterize", &mut lines);
    lines.push_str(&format!(
        "visible {} of {}, tile pairs {}, top-K entries {}\n",
        p.tile_rects.iter().filter(|r| !r.is_empty()).count(),
        map.len(),
        b.ids.len(),
        out.top_k.as_ref().map_or(0, |t| t.entries())
    ));
    lines
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Wall and CPU ms of every frame of one request.
#[derive(Default)]
struct Timings {
    wall: Vec<f64>,
    cpu: Vec<f64>,
}

/// Renders every camera with every request, interleaved (camera by camera, the requests in
/// turn, `repeat` rounds), so a shared machine's slow spells hit all requests alike and the
/// per-frame ratios stay meaningful. Returns per request its timings (per camera, the
/// fastest round), and the last top-K entries per pixel.
fn time_interleaved(
    map: &GaussianMap,
    cams: &[Camera],
    reqs: &[RenderRequest],
    repeat: usize,
) -> (Vec<Timings>, f64) {
    // Buffers reused across frames, as a SLAM loop would (the first render is the warm-up).
    let mut outs: Vec<_> = reqs.iter().map(|r| render(map, &cams[0], r)).collect();
    let mut times: Vec<Timings> = reqs.iter().map(|_| Timings::default()).collect();
    let mut topk = 0.0;
    for cam in cams {
        let mut best = vec![(f64::INFINITY, f64::INFINITY); reqs.len()];
        for _ in 0..repeat.max(1) {
            for ((req, out), best) in reqs.iter().zip(&mut outs).zip(&mut best) {
                let (t0, c0) = (Instant::now(), process_cpu_ms());
                render_into(map, cam, req, out);
                let (wall, cpu) = (t0.elapsed().as_secs_f64() * 1e3, process_cpu_ms() - c0);
                *best = (best.0.min(wall), best.1.min(cpu));
                if let Some(tk) = &out.output.top_k {
                    topk = tk.entries() as f64 / tk.count.len() as f64;
                }
            }
        }
        for (t, (wall, cpu)) in times.iter_mut().zip(best) {
            t.wall.push(wall);
            t.cpu.push(cpu);
        }
    }
    (times, topk)
}

/// Runs every (scene size × resolution) case and returns the table.
pub fn run_render_bench(cfg: &BenchConfig) -> BenchReport {
    let poses = indoor_poses(cfg.frames.max(1));
    let mut rows = Vec::new();
    for &n in &cfg.gaussian_counts {
        let map = indoor_scene(n, 7);
        for k in &cfg.intrinsics {
            let cams: Vec<Camera> = poses
                .iter()
                .map(|p| Camera::from_pose(*k, p, 0.05))
                .collect();
            let semantic = RenderRequest::semantic(cfg.top_k);
            let labels_only = RenderRequest {
                labels: true,
                ..RenderRequest::default()
            };
            let top_k_only = RenderRequest {
                top_k: Some(cfg.top_k),
                ..RenderRequest::default()
            };
            let reqs = [
                RenderRequest::color_depth(),
                semantic,
                labels_only,
                top_k_only,
            ];
            let (t, topk) = time_interleaved(&map, &cams, &reqs, cfg.repeat);
            let ratios = t[1].wall.iter().zip(&t[0].wall).map(|(b, a)| b / a);
            let breakdown = cfg.breakdown.then(|| {
                let mut out = crate::RenderOutput::default();
                // The second frame, with warm output buffers as the timed frames have.
                stage_breakdown(&map, &cams[0], &semantic, &mut out);
                stage_breakdown(&map, &cams[0], &semantic, &mut out)
            });
            rows.push(BenchRow {
                gaussians: n,
                width: k.width,
                height: k.height,
                ms_color_depth: median(t[0].wall.clone()),
                ms_semantic: median(t[1].wall.clone()),
                cpu_ms_color_depth: median(t[0].cpu.clone()),
                cpu_ms_semantic: median(t[1].cpu.clone()),
                overhead: median(ratios.collect()) - 1.0,
                topk_per_pixel: topk,
                ms_labels_only: median(t[2].wall.clone()),
                ms_top_k_only: median(t[3].wall.clone()),
                breakdown,
            });
        }
    }
    BenchReport {
        rows,
        bytes_per_gaussian: GaussianMap::bytes_per_gaussian(),
        threads: rayon::current_num_threads(),
        repeat: cfg.repeat.max(1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repeated_renders_keep_one_timing_per_frame() {
        let map = indoor_scene(2000, 7);
        let k = intrinsics_for_size(64, 48);
        let cams: Vec<Camera> = indoor_poses(3)
            .iter()
            .map(|p| Camera::from_pose(k, p, 0.05))
            .collect();
        let reqs = [RenderRequest::color_depth(), RenderRequest::semantic(8)];
        let (t, topk) = time_interleaved(&map, &cams, &reqs, 4);
        for t in &t {
            assert_eq!((t.wall.len(), t.cpu.len()), (3, 3));
            assert!(t.wall.iter().all(|&w| w.is_finite() && w > 0.0));
        }
        assert!(topk > 0.0, "the scene should be seen");
    }

    #[test]
    fn the_report_says_how_figures_were_taken() {
        let cfg = BenchConfig {
            gaussian_counts: vec![2000],
            intrinsics: vec![intrinsics_for_size(64, 48)],
            frames: 2,
            repeat: 3,
            ..BenchConfig::default()
        };
        let report = run_render_bench(&cfg);
        assert_eq!((report.rows.len(), report.repeat), (1, 3));
        let text = report.to_string();
        assert!(text.contains("fastest of 3 renders"), "{text}");
        assert!(text.contains("64x48"), "{text}");
    }
}
