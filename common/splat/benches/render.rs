//! `cargo bench -p opengs-splat`: prints the render benchmark table.
//! `cargo bench -p opengs-splat -- stages` prints a per-stage breakdown at 100k, 640×480.

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
            sort_top_k: true,
        };
        for req in [
            RenderRequest::color_depth(),
            only(false, None, true),
            only(true, None, false),
            only(false, Some(50), false),
            RenderRequest {
                sort_top_k: false,
                ..RenderRequest::semantic(50)
            },
            RenderRequest::semantic(50),
        ] {
            let mut out = opengs_splat::RenderOutput::default();
            for _ in 0..3 {
                println!("{req:?}\n{}", stage_breakdown(&map, &cam, &req, &mut out));
            }
        }
        return;
    }
    println!("{}", run_render_bench(&BenchConfig::default()));
}
