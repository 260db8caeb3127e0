//! Block-averaged low-resolution copy of the frame: the classic segmenter
//! works at e.g. half resolution for speed.

/// Colour (0..1 per channel) and metric depth (0 = missing) on a coarse grid.
#[derive(Debug, Clone, Default)]
pub struct CoarseFrame {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<[f32; 3]>,
    pub depth_m: Vec<f32>,
}

/// Relative band above the nearest depth of a block that still averages in:
/// blocks straddling a depth edge keep the foreground depth, not a blend.
const FOREGROUND_BAND: f32 = 0.03;

impl CoarseFrame {
    /// [`CoarseFrame::downscale`] of a validated segmenter input.
    pub fn of_input(input: &crate::SegmenterInput, factor: usize) -> Self {
        Self::downscale(
            input.rgb,
            input.depth,
            input.depth_scale,
            input.width as usize,
            input.height as usize,
            factor,
        )
    }

    /// Averages `factor` × `factor` blocks (partial blocks at the border too).
    /// Buffers must already be validated against `width` × `height`.
    pub fn downscale(
        rgb: &[u8],
        depth: &[u16],
        depth_scale: f32,
        width: usize,
        height: usize,
        factor: usize,
    ) -> Self {
        let factor = factor.max(1);
        let (cw, ch) = (width.div_ceil(factor), height.div_ceil(factor));
        let mut out = CoarseFrame {
            width: cw,
            height: ch,
            rgb: vec![[0.0; 3]; cw * ch],
            depth_m: vec![0.0; cw * ch],
        };
        let inv_units = 1.0 / depth_scale;
        let mut samples = Vec::with_capacity(factor * factor);
        for cy in 0..ch {
            let (y0, y1) = (cy * factor, ((cy + 1) * factor).min(height));
            for cx in 0..cw {
                let (x0, x1) = (cx * factor, ((cx + 1) * factor).min(width));
                let mut sum = [0u32; 3];
                samples.clear();
                for y in y0..y1 {
                    let row = y * width;
                    for x in x0..x1 {
                        let p = row + x;
                        for (c, s) in sum.iter_mut().enumerate() {
                            *s += rgb[p * 3 + c] as u32;
                        }
                        if depth[p] != 0 {
                            samples.push(depth[p]);
                        }
                    }
                }
                let count = ((y1 - y0) * (x1 - x0)) as f32;
                let i = cy * cw + cx;
                out.rgb[i] = sum.map(|s| s as f32 / (255.0 * count));
                out.depth_m[i] = foreground_mean(&samples) * inv_units;
            }
        }
        out
    }
}

/// Mean of the samples within `FOREGROUND_BAND` of the nearest; 0 if none.
fn foreground_mean(samples: &[u16]) -> f32 {
    let Some(&nearest) = samples.iter().min() else {
        return 0.0;
    };
    let limit = nearest as f32 * (1.0 + FOREGROUND_BAND);
    let (sum, n) = samples
        .iter()
        .filter(|&&d| d as f32 <= limit)
        .fold((0.0f32, 0u32), |(s, n), &d| (s + d as f32, n + 1));
    sum / n as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn averages_colour_and_keeps_foreground_depth() {
        // 2x2 frame, one block: depth 1.0 m, 1.01 m, 2.0 m, missing.
        let rgb = [0, 0, 0, 255, 255, 255, 0, 0, 0, 255, 255, 255];
        let depth = [1000, 1010, 2000, 0];
        let c = CoarseFrame::downscale(&rgb, &depth, 1000.0, 2, 2, 2);
        assert_eq!((c.width, c.height), (1, 1));
        assert!((c.rgb[0][0] - 0.5).abs() < 1e-6);
        assert!((c.depth_m[0] - 1.005).abs() < 1e-5);
    }

    #[test]
    fn partial_border_blocks() {
        let rgb = vec![100u8; 3 * 3 * 3];
        let depth = vec![0u16; 9];
        let c = CoarseFrame::downscale(&rgb, &depth, 1000.0, 3, 3, 2);
        assert_eq!((c.width, c.height), (2, 2));
        assert!(c.rgb.iter().all(|p| (p[1] - 100.0 / 255.0).abs() < 1e-6));
        assert!(c.depth_m.iter().all(|&z| z == 0.0));
    }
}
