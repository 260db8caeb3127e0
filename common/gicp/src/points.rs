use crate::GicpError;
use nalgebra::Point3;
use opengs_geometry::Intrinsics;

/// Points back-projected from a depth image, with the pixel each came from
/// (the mapper colours its new Gaussians from those pixels).
#[derive(Debug, Clone, Default)]
pub struct DepthSamples {
    pub points: Vec<Point3<f64>>,
    pub pixels: Vec<(u32, u32)>,
    /// Sampling stride in pixels: `pixels[i] / stride` is a grid cell.
    pub stride: usize,
    /// Grid size in cells (columns, rows).
    pub grid_size: (usize, usize),
}

/// Back-projects every `stride`-th pixel of a row-major depth image
/// (docs/METHOD.md §7: stride 10 for Replica-size, 5 for TUM-size images).
/// Raw value 0 means "no depth"; depths beyond `max_depth` metres are dropped.
pub fn sample_depth_grid(
    depth: &[u16],
    units_per_metre: f64,
    intrinsics: &Intrinsics,
    stride: usize,
    max_depth: f64,
) -> Result<DepthSamples, GicpError> {
    let (w, h) = (intrinsics.width as usize, intrinsics.height as usize);
    if depth.len() != w * h {
        return Err(GicpError::Invalid(format!(
            "depth image has {} pixels, intrinsics say {w}×{h}",
            depth.len()
        )));
    }
    if stride == 0 || units_per_metre.is_nan() || units_per_metre <= 0.0 {
        return Err(GicpError::Invalid(format!(
            "stride must be ≥ 1 and depth scale > 0 (got {stride}, {units_per_metre})"
        )));
    }
    let mut samples = DepthSamples {
        stride,
        grid_size: (w.div_ceil(stride), h.div_ceil(stride)),
        ..DepthSamples::default()
    };
    for v in (0..h).step_by(stride) {
        for u in (0..w).step_by(stride) {
            let raw = depth[v * w + u];
            let z = raw as f64 / units_per_metre;
            if raw == 0 || z > max_depth {
                continue;
            }
            samples
                .points
                .push(intrinsics.backproject(u as f64, v as f64, z));
            samples.pixels.push((u as u32, v as u32));
        }
    }
    Ok(samples)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn grid_skips_missing_and_far_depth() {
        let k = Intrinsics::new(2.0, 2.0, 1.0, 1.0, 4, 4);
        let mut depth = vec![5000u16; 16]; // 1 m at TUM's 5000 units per metre
        depth[2] = 0; // (u=2, v=0) missing
        depth[8] = 50000; // (u=0, v=2) at 10 m, beyond max depth
        let s = sample_depth_grid(&depth, 5000.0, &k, 2, 5.0).expect("valid");
        assert_eq!(s.pixels, vec![(0, 0), (2, 2)]);
        // (u=0, v=0) at z = 1: x = (0 − 1)·1/2 = −0.5.
        assert_relative_eq!(s.points[0], Point3::new(-0.5, -0.5, 1.0));
        assert!(sample_depth_grid(&depth[..15], 5000.0, &k, 2, 5.0).is_err());
        assert!(sample_depth_grid(&depth, 5000.0, &k, 0, 5.0).is_err());
    }
}
