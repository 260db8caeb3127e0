//! Relative cost of rendering parts (textures vs geometry), interleaved so
//! machine load affects both equally.

use std::time::Instant;

use opengs_datasets::synthetic::raycast::render;
use opengs_datasets::synthetic::texture::Texture;
use opengs_datasets::{RgbdSource, SyntheticOptions, SyntheticSource};

fn main() -> Result<(), opengs_datasets::DatasetError> {
    let src = SyntheticSource::new(SyntheticOptions {
        frames: Some(60),
        ..SyntheticOptions::default()
    })?;
    let k = src.intrinsics();
    let full = src.scene().clone();
    let mut solid = full.clone();
    for p in &mut solid.parts {
        p.texture = Texture::Solid([0.5; 3]);
    }
    for f in &mut solid.room.faces {
        f.1 = Texture::Solid([0.5; 3]);
    }
    let mut no_parts = solid.clone();
    no_parts.parts.clear();
    let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
    for pose in src.poses() {
        let s = Instant::now();
        std::hint::black_box(render(&full, &k, pose));
        a += s.elapsed().as_secs_f64();
        let s = Instant::now();
        std::hint::black_box(render(&solid, &k, pose));
        b += s.elapsed().as_secs_f64();
        let s = Instant::now();
        std::hint::black_box(render(&no_parts, &k, pose));
        c += s.elapsed().as_secs_f64();
    }
    let n = src.len() as f64;
    println!(
        "full {:.2} ms, solid {:.2} ms, room only {:.2} ms",
        a * 1e3 / n,
        b * 1e3 / n,
        c * 1e3 / n
    );
    Ok(())
}
