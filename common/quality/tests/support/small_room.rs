//! Test scenes shared by the quality tests and the mapping crate's refinement tests (included
//! with `#[path]` by both): the synthetic room at 1/8 size, its frames with their poses, and a
//! map back-projected from one frame.

use opengs_datasets::{RgbdFrame, RgbdSource, SyntheticOptions, SyntheticSource};
use opengs_geometry::{Intrinsics, Pose};
use opengs_splat::{Gaussian, GaussianMap};

/// The synthetic room at 80×60 (the default 640×480 camera scaled by 1/8).
pub fn small_room() -> SyntheticSource {
    let mut o = SyntheticOptions::default();
    o.intrinsics = o.intrinsics.scaled(0.125);
    o.frames = Some(40);
    SyntheticSource::new(o).expect("synthetic room")
}

/// One opaque isotropic Gaussian per pixel with depth, about a pixel wide, in its colour.
pub fn backproject(frame: &RgbdFrame, pose: &Pose, k: &Intrinsics) -> GaussianMap {
    let mut map = GaussianMap::new();
    for v in 0..frame.height {
        for u in 0..frame.width {
            let Some(z) = frame.depth_m(u, v) else {
                continue;
            };
            let p = pose * k.backproject(u as f64, v as f64, z as f64);
            let i = (v * frame.width + u) as usize;
            let color = [0, 1, 2].map(|c| frame.rgb[3 * i + c] as f32 / 255.0);
            let s = 0.5 * z / k.fx as f32;
            map.push(Gaussian::from_values(
                [p.x as f32, p.y as f32, p.z as f32],
                [1.0, 0.0, 0.0, 0.0],
                [s; 3],
                0.95,
                color,
                0,
            ));
        }
    }
    map
}

pub fn posed(source: &mut SyntheticSource, indices: &[usize]) -> Vec<(RgbdFrame, Pose)> {
    indices
        .iter()
        .map(|&i| {
            let f = source.frame(i).expect("frame");
            let pose = f.gt_pose.expect("synthetic frames have poses");
            (f, pose)
        })
        .collect()
}
