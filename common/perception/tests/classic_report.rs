mod support;

use opengs_perception::{ClassicParams, ClassicSegmenter, Segmenter, SegmenterInput};
use support::{agreement, synthetic_frames_with_noise};

/// `cargo test -p opengs-perception --test classic_report -- --ignored --nocapture`
#[test]
#[ignore = "prints quality figures; run by hand"]
fn report_classic_quality() {
    let noise = std::env::var("OPENGS_NOISE")
        .is_ok_and(|v| v == "1")
        .then(Default::default);
    let (frames, k, classes) =
        synthetic_frames_with_noise(&[0, 75, 150, 225, 300, 375, 450, 525], noise);
    let mut params = ClassicParams::default();
    // Tuning knobs: OPENGS_K, OPENGS_MIN_SIZE, OPENGS_COLOUR, OPENGS_DEPTH, OPENGS_NORMAL.
    let env = |name: &str| std::env::var(name).ok().and_then(|v| v.parse::<f32>().ok());
    params.k = env("OPENGS_K").unwrap_or(params.k);
    params.min_size = env("OPENGS_MIN_SIZE").map_or(params.min_size, |v| v as u32);
    params.downscale = env("OPENGS_DOWNSCALE").map_or(params.downscale, |v| v as u32);
    params.weights.colour = env("OPENGS_COLOUR").unwrap_or(params.weights.colour);
    params.weights.depth = env("OPENGS_DEPTH").unwrap_or(params.weights.depth);
    params.weights.normal = env("OPENGS_NORMAL").unwrap_or(params.weights.normal);
    params.weights.depth_to_missing =
        env("OPENGS_MISSING").unwrap_or(params.weights.depth_to_missing);
    params.weights.noise_sigmas = env("OPENGS_SIGMAS").unwrap_or(params.weights.noise_sigmas);
    params.smoothing_radius = env("OPENGS_SMOOTH").map_or(params.smoothing_radius, |v| v as u32);
    let quiet = std::env::var("OPENGS_QUIET").is_ok();
    let mut seg = ClassicSegmenter::new(params).expect("params");
    let mut sums = [0.0f64; 6];
    for f in &frames {
        let t = std::time::Instant::now();
        let out = seg
            .segment(&SegmenterInput::from_frame(f, k, &classes))
            .expect("segment");
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let gt = f.labels.as_deref().expect("labels");
        let a = agreement(&out.label_map, gt, 0.9, 2000);
        println!(
            "frame {:3}: {:4} segs {:6.1} ms  purity {:.4}  pure(>=0.9) px {:.4}  worst large-segment purity {:.3}",
            f.index, a.segments, ms, a.weighted_purity, a.pure_pixel_fraction, a.worst_large_segment_purity
        );
        sums[0] += a.segments as f64;
        sums[1] += a.weighted_purity;
        sums[2] += a.pure_pixel_fraction;
        for (_, n, largest, parts) in &a.instances {
            sums[3] += *n as f64 * largest;
            sums[4] += *n as f64 * *parts as f64;
            sums[5] += *n as f64;
        }
        if let Ok(dir) = std::env::var("OPENGS_DUMP_DIR") {
            dump(&dir, f.index, &out.label_map, f.width, f.height, &f.rgb);
        }
        if quiet {
            continue;
        }
        for (id, n, largest, parts) in &a.instances {
            let class = classes
                .iter()
                .find(|c| c.id == *id)
                .map_or("?", |c| c.class.as_str());
            println!("    {id:3} {class:10} {n:7} px  largest {largest:.3}  parts80 {parts}");
        }
    }
    let n = frames.len() as f64;
    println!(
        "mean: {:.0} segs  purity {:.4}  pure px {:.4}  largest-share (px-weighted) {:.3}  parts80 (px-weighted) {:.1}",
        sums[0] / n, sums[1] / n, sums[2] / n, sums[3] / sums[5], sums[4] / sums[5]
    );
}

fn dump(dir: &str, index: usize, labels: &[u32], w: u32, h: u32, rgb: &[u8]) {
    let colour = |l: u32| {
        let x = l.wrapping_mul(2654435761);
        [(x >> 24) as u8, (x >> 16) as u8, (x >> 8) as u8]
    };
    let mut img = Vec::with_capacity(labels.len() * 6);
    for y in 0..h as usize {
        for x in 0..w as usize {
            img.extend_from_slice(&rgb[(y * w as usize + x) * 3..][..3]);
        }
        for x in 0..w as usize {
            img.extend_from_slice(&colour(labels[y * w as usize + x]));
        }
    }
    let path = format!("{dir}/classic_{index:04}.ppm");
    let mut data = format!("P6\n{} {}\n255\n", w * 2, h).into_bytes();
    data.extend(img);
    std::fs::write(path, data).expect("write dump");
}
