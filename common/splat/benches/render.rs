//! `cargo bench -p opengs-splat`: prints the render benchmark table.
//! `cargo bench -p opengs-splat -- stages` prints a per-stage breakdown at 100k, 640×480.
//! `cargo bench -p opengs-splat -- quick` times only the issue-4 case (100k, 640×480).
//! `cargo bench -p opengs-splat -- loop N [a|labels|topk]` renders case (b) (or the named
//! variant) N times, for a profiler.

use opengs_splat::bench::{run_render_bench, stage_breakdown, BenchConfig};
use opengs_splat::{scene, Camera, RenderRequest};

fn main() {
    if std::env::args().any(|a| a == "stages") {
        let map = scene::indoor_scene(100_000, 7);
        let k = opengs_geometry::Intrinsics::new(525.0, 525.0, 319.5, 239.5, 640, 480);
        let cam = Camera::from_pose(k, &scene::indoor_poses(1)[0], 0.05);
        let only = |labels, top_k, visible_counts| RenderRequest {
            labels,
            top_k,
            visible_counts,
        };
        for req in [
            RenderRequest::color_depth(),
            only(false, None, true),
            only(true, None, false),
            only(false, Some(50), false),
            RenderRequest::semantic(50),
        ] {
            let mut out = opengs_splat::RenderOutput::default();
            for _ in 0..3 {
                println!("{req:?}\n{}", stage_breakdown(&map, &cam, &req, &mut out));
            }
        }
        return;
    }
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "loop") {
        let n: usize = args.get(i + 1).and_then(|s| s.parse().ok()).unwrap_or(100);
        let map = scene::indoor_scene(100_000, 7);
        let k = opengs_splat::bench::intrinsics_for_size(640, 480);
        let cam = Camera::from_pose(k, &scene::indoor_poses(1)[0], 0.05);
        let req = match args.get(i + 2).map(String::as_str) {
            Some("a") => RenderRequest::color_depth(),
            Some("labels") => RenderRequest {
                labels: true,
                ..RenderRequest::default()
            },
            Some("topk") => RenderRequest {
                top_k: Some(50),
                ..RenderRequest::default()
            },
            _ => RenderRequest::semantic(50),
        };
        let mut r = opengs_splat::render(&map, &cam, &req);
        let mut cpu = Vec::with_capacity(n);
        for _ in 0..n {
            let c0 = opengs_splat::bench::process_cpu_ms();
            opengs_splat::render_into(&map, &cam, &req, &mut r);
            cpu.push(opengs_splat::bench::process_cpu_ms() - c0);
        }
        cpu.sort_by(f64::total_cmp);
        if let (Some(min), Some(med)) = (cpu.first(), cpu.get(cpu.len() / 2)) {
            println!("{req:?}: cpu ms per frame min {min:.2} median {med:.2}");
        }
        return;
    }
    if args.iter().any(|a| a == "stats") {
        // Contributions per pixel and saturation of the benchmark scene (scene realism check).
        let map = scene::indoor_scene(100_000, 7);
        let k = opengs_splat::bench::intrinsics_for_size(640, 480);
        for pose in scene::indoor_poses(3) {
            let cam = Camera::from_pose(k, &pose, 0.05);
            let r = opengs_splat::render(&map, &cam, &RenderRequest::semantic(100_000));
            let tk = r.output.top_k.as_ref().expect("asked");
            let mut hist = [0usize; 8];
            for &c in &tk.count {
                hist[(c as usize / 10).min(7)] += 1;
            }
            let n = tk.count.len() as f64;
            let sat = r
                .output
                .final_transmittance
                .iter()
                .filter(|&&t| t < 1e-3)
                .count();
            let mean_t: f64 = r
                .output
                .final_transmittance
                .iter()
                .map(|&t| t as f64)
                .sum::<f64>()
                / n;
            let mean: f64 = tk.count.iter().map(|&c| c as f64).sum::<f64>() / n;
            let maxc = tk.count.iter().max().copied().unwrap_or(0);
            let over32 = tk.count.iter().filter(|&&c| c > 32).count();
            let over50 = tk.count.iter().filter(|&&c| c > 50).count();
            println!(
                "mean contrib {mean:.1}, max {maxc}, >32: {:.2}%, >50: {:.2}%, T<1e-3: {:.1}%, mean T {mean_t:.4}, hist/10 {:?}",
                100.0 * over32 as f64 / n,
                100.0 * over50 as f64 / n,
                100.0 * sat as f64 / n,
                hist
            );
        }
        return;
    }
    let cfg = if args.iter().any(|a| a == "quick") {
        BenchConfig {
            gaussian_counts: vec![100_000],
            intrinsics: vec![opengs_splat::bench::intrinsics_for_size(640, 480)],
            frames: 15,
            ..BenchConfig::default()
        }
    } else {
        BenchConfig::default()
    };
    println!("{}", run_render_bench(&cfg));
}
