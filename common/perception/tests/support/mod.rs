//! Shared helpers: synthetic frames, segmentation-vs-ground-truth metrics, and the tiny ONNX
//! fixtures with the ONNX Runtime check.
#![allow(dead_code)]

use std::collections::HashMap;
use std::path::PathBuf;

use opengs_datasets::{open_dataset, DatasetSpec, DepthNoise, InstanceClass, RgbdFrame};
use opengs_geometry::Intrinsics;
use opengs_perception::SamModelPaths;

/// A committed test fixture (`tests/fixtures/NAME`).
pub fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// The tiny SAM encoder and decoder.
pub fn sam_fixtures() -> SamModelPaths {
    SamModelPaths {
        encoder: fixture("tiny_sam_encoder.onnx"),
        decoder: fixture("tiny_sam_decoder.onnx"),
    }
}

/// True when ONNX Runtime can be loaded. scripts/test.sh fetches it and sets
/// OPENGS_REQUIRE_ORT: there the ONNX tests must run, not skip.
pub fn runtime_available() -> bool {
    let ok = std::env::var_os("ORT_DYLIB_PATH").is_some();
    if !ok && std::env::var_os("OPENGS_REQUIRE_ORT").is_some() {
        panic!("OPENGS_REQUIRE_ORT is set but ORT_DYLIB_PATH is not (run scripts/setup-ort.sh)");
    }
    if !ok {
        eprintln!("skipped: ORT_DYLIB_PATH not set (run scripts/setup-ort.sh, onnxruntime 1.31.1)");
    }
    ok
}

/// Frames `indices` of the embedded synthetic room, with camera and classes.
pub fn synthetic_frames(indices: &[usize]) -> (Vec<RgbdFrame>, Intrinsics, Vec<InstanceClass>) {
    synthetic_frames_with_noise(indices, None)
}

/// Same, with Kinect-like depth corruption when `noise` is given.
pub fn synthetic_frames_with_noise(
    indices: &[usize],
    noise: Option<DepthNoise>,
) -> (Vec<RgbdFrame>, Intrinsics, Vec<InstanceClass>) {
    let kind = "synthetic".parse().expect("synthetic spec");
    let mut spec = DatasetSpec::new(kind);
    spec.synthetic.noise = noise;
    let mut source = open_dataset(&spec).expect("synthetic dataset");
    let frames = indices
        .iter()
        .map(|&i| source.frame(i).expect("synthetic frame"))
        .collect();
    (frames, source.intrinsics(), source.class_table())
}

/// Agreement of a segmentation with ground-truth instances, full resolution.
#[derive(Debug, Clone)]
pub struct Agreement {
    pub segments: usize,
    /// Σ over segments of the pixels of its majority instance, / all pixels.
    pub weighted_purity: f64,
    /// Fraction of pixels lying in segments whose purity is ≥ `pure_at`.
    pub pure_pixel_fraction: f64,
    pub pure_at: f64,
    /// Lowest purity among segments of ≥ `min_instance_pixels` pixels.
    pub worst_large_segment_purity: f64,
    /// Per GT instance with ≥ `min_instance_pixels`: (id, pixels, share of
    /// it in its largest segment, segments needed to cover 80 % of it).
    pub instances: Vec<(u16, usize, f64, usize)>,
}

pub fn agreement(
    label_map: &[u32],
    gt: &[u16],
    pure_at: f64,
    min_instance_pixels: usize,
) -> Agreement {
    // overlap[(segment, instance)] = pixel count
    let mut overlap: HashMap<(u32, u16), usize> = HashMap::new();
    for (&s, &g) in label_map.iter().zip(gt) {
        *overlap.entry((s, g)).or_default() += 1;
    }
    let mut seg_size: HashMap<u32, usize> = HashMap::new();
    let mut seg_major: HashMap<u32, usize> = HashMap::new();
    let mut inst: HashMap<u16, Vec<usize>> = HashMap::new();
    for (&(s, g), &n) in &overlap {
        *seg_size.entry(s).or_default() += n;
        let m = seg_major.entry(s).or_default();
        *m = (*m).max(n);
        inst.entry(g).or_default().push(n);
    }
    let total = label_map.len() as f64;
    let weighted_purity = seg_major.values().sum::<usize>() as f64 / total;
    let pure_pixels: usize = seg_size
        .iter()
        .filter(|(s, &n)| seg_major[*s] as f64 >= pure_at * n as f64)
        .map(|(_, &n)| n)
        .sum();
    let worst_large_segment_purity = seg_size
        .iter()
        .filter(|(_, &n)| n >= min_instance_pixels)
        .map(|(s, &n)| seg_major[s] as f64 / n as f64)
        .fold(1.0, f64::min);
    let mut instances: Vec<(u16, usize, f64, usize)> = inst
        .into_iter()
        .filter_map(|(g, mut parts)| {
            let size: usize = parts.iter().sum();
            if size < min_instance_pixels {
                return None;
            }
            parts.sort_unstable_by(|a, b| b.cmp(a));
            let mut covered = 0;
            let mut needed = 0;
            for p in &parts {
                covered += p;
                needed += 1;
                if covered as f64 >= 0.8 * size as f64 {
                    break;
                }
            }
            Some((g, size, parts[0] as f64 / size as f64, needed))
        })
        .collect();
    instances.sort_unstable_by_key(|i| i.0);
    Agreement {
        segments: seg_size.len(),
        weighted_purity,
        pure_pixel_fraction: pure_pixels as f64 / total,
        pure_at,
        worst_large_segment_purity,
        instances,
    }
}
