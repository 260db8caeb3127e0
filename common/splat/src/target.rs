//! A training target: one RGB-D frame in the renderer's layout, and 2× downscaling of it
//! (and of its camera) for mapping at reduced resolution.

use crate::camera::Camera;

/// RGB in [0, 1] as three planes (what SSIM filters), depth in metres (0 = invalid).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TargetFrame {
    pub width: u32,
    pub height: u32,
    pub rgb: [Vec<f32>; 3],
    pub depth: Vec<f32>,
}

impl TargetFrame {
    /// From interleaved 8-bit RGB (row-major) and depth in metres.
    pub fn from_rgb8(width: u32, height: u32, rgb: &[[u8; 3]], depth: &[f32]) -> Self {
        Self::from_fn(
            width,
            height,
            depth,
            |i, c| rgb[i][c] as f32 / 255.0,
            rgb.len(),
        )
    }

    /// From interleaved RGB in [0, 1] (row-major) and depth in metres.
    pub fn from_rgb_f32(width: u32, height: u32, rgb: &[[f32; 3]], depth: &[f32]) -> Self {
        Self::from_fn(width, height, depth, |i, c| rgb[i][c], rgb.len())
    }

    fn from_fn(
        width: u32,
        height: u32,
        depth: &[f32],
        value: impl Fn(usize, usize) -> f32,
        len: usize,
    ) -> Self {
        let n = (width * height) as usize;
        assert_eq!(len, n, "rgb must be width × height");
        assert_eq!(depth.len(), n, "depth must be width × height");
        Self {
            width,
            height,
            rgb: std::array::from_fn(|c| (0..n).map(|i| value(i, c)).collect()),
            depth: depth.to_vec(),
        }
    }

    pub fn pixels(&self) -> usize {
        (self.width * self.height) as usize
    }

    /// Half resolution (odd last row/column dropped): RGB is the 2×2 mean, depth the mean
    /// of the valid (> 0) depths of the 2×2 block, 0 when none is valid.
    pub fn downscale2(&self) -> Self {
        let (w, h) = (self.width as usize / 2, self.height as usize / 2);
        let src_w = self.width as usize;
        let block = |y: usize, x: usize| {
            let o = 2 * y * src_w + 2 * x;
            [o, o + 1, o + src_w, o + src_w + 1]
        };
        let rgb = std::array::from_fn(|c| {
            let plane = &self.rgb[c];
            (0..w * h)
                .map(|i| block(i / w, i % w).iter().map(|&j| plane[j]).sum::<f32>() * 0.25)
                .collect()
        });
        let depth = (0..w * h)
            .map(|i| {
                let (sum, n) = block(i / w, i % w)
                    .iter()
                    .map(|&j| self.depth[j])
                    .filter(|&d| d > 0.0)
                    .fold((0.0f32, 0u32), |(s, n), d| (s + d, n + 1));
                if n > 0 {
                    sum / n as f32
                } else {
                    0.0
                }
            })
            .collect();
        Self {
            width: w as u32,
            height: h as u32,
            rgb,
            depth,
        }
    }
}

/// The camera of a [`TargetFrame::downscale2`] image: pixel (u, v) of the half image covers
/// full-size pixels 2u..2u+1, so its centre is at 2u + ½ (OpenCV centres).
pub fn downscale_camera2(cam: &Camera) -> Camera {
    let mut c = *cam;
    let k = &mut c.intrinsics;
    k.fx /= 2.0;
    k.fy /= 2.0;
    k.cx = (k.cx - 0.5) / 2.0;
    k.cy = (k.cy - 0.5) / 2.0;
    k.width /= 2;
    k.height /= 2;
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn downscale_averages_valid_depth_only() {
        let rgb = vec![[255u8, 0, 0]; 4 * 2];
        let depth = vec![1.0, 0.0, 2.0, 2.0, 3.0, 0.0, 0.0, 0.0];
        let f = TargetFrame::from_rgb8(4, 2, &rgb, &depth);
        let h = f.downscale2();
        assert_eq!((h.width, h.height), (2, 1));
        assert_eq!(h.rgb[0], vec![1.0, 1.0]);
        assert_eq!(h.depth, vec![2.0, 2.0]);
        let d2 = TargetFrame::from_rgb8(2, 2, &[[0; 3]; 4], &[0.0; 4]).downscale2();
        assert_eq!(d2.depth, vec![0.0]);
    }

    #[test]
    fn downscaled_camera_keeps_pixel_centres() {
        let k = opengs_geometry::Intrinsics::new(500.0, 500.0, 319.5, 239.5, 640, 480);
        let cam = Camera::from_pose(k, &opengs_geometry::Pose::identity(), 0.05);
        let half = downscale_camera2(&cam).intrinsics;
        assert_eq!((half.width, half.height), (320, 240));
        assert_eq!((half.cx, half.cy, half.fx), (159.5, 119.5, 250.0));
    }
}
