//! Measures synthetic frame generation time: `cargo run --release --example synth_bench`.

use std::time::Instant;

use opengs_datasets::synthetic::raycast::render;
use opengs_datasets::{DepthNoise, RgbdSource, SyntheticOptions, SyntheticSource};

fn main() -> Result<(), opengs_datasets::DatasetError> {
    let frames = 120;
    let mut src = SyntheticSource::new(SyntheticOptions {
        frames: Some(frames),
        ..SyntheticOptions::default()
    })?;
    let k = src.intrinsics();
    let noise = DepthNoise::default();
    let (mut t_render, mut t_noise) = (0.0, 0.0);
    for pose in src.poses().to_vec() {
        let start = Instant::now();
        let view = render(src.scene(), &k, &pose);
        t_render += start.elapsed().as_secs_f64();
        let start = Instant::now();
        let depth = noise.apply(&view.depth, k.width as usize, 5000.0, 1, 0);
        t_noise += start.elapsed().as_secs_f64();
        std::hint::black_box(depth);
    }
    let start = Instant::now();
    for i in 0..src.len() {
        std::hint::black_box(src.frame(i)?);
    }
    let t_frame = start.elapsed().as_secs_f64();
    let per = |t: f64| 1000.0 * t / frames as f64;
    println!(
        "threads={} render {:.2} ms, noise {:.2} ms, clean frame() {:.2} ms per 640x480 frame",
        rayon::current_num_threads(),
        per(t_render),
        per(t_noise),
        per(t_frame)
    );
    Ok(())
}
