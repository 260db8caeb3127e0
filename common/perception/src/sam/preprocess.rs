//! SAM image preprocessing: resize the longest side to 1024 (bilinear),
//! normalise with the ImageNet pixel mean/std, zero-pad to 1024 × 1024.

use ndarray::Array4;

/// Side of the square SAM encoder input.
pub const SAM_SIDE: usize = 1024;
const PIXEL_MEAN: [f32; 3] = [123.675, 116.28, 103.53];
const PIXEL_STD: [f32; 3] = [58.395, 57.12, 57.375];

/// Scale from original pixels to the 1024 frame (longest side → 1024).
pub fn resize_scale(width: usize, height: usize) -> f32 {
    SAM_SIDE as f32 / width.max(height) as f32
}

/// Encoder input tensor [1, 3, 1024, 1024] from row-major RGB8.
pub fn encoder_input(rgb: &[u8], width: usize, height: usize) -> Array4<f32> {
    let scale = resize_scale(width, height);
    let new_w = ((width as f32 * scale + 0.5) as usize).min(SAM_SIDE);
    let new_h = ((height as f32 * scale + 0.5) as usize).min(SAM_SIDE);
    let mut out = Array4::<f32>::zeros((1, 3, SAM_SIDE, SAM_SIDE));
    let sample = |x: usize, y: usize, c: usize| rgb[(y * width + x) * 3 + c] as f32;
    for y in 0..new_h {
        // Pixel-centre mapping back to the source, clamped at the borders.
        let sy = ((y as f32 + 0.5) / scale - 0.5).clamp(0.0, (height - 1) as f32);
        let (y0, fy) = (sy.floor() as usize, sy.fract());
        let y1 = (y0 + 1).min(height - 1);
        for x in 0..new_w {
            let sx = ((x as f32 + 0.5) / scale - 0.5).clamp(0.0, (width - 1) as f32);
            let (x0, fx) = (sx.floor() as usize, sx.fract());
            let x1 = (x0 + 1).min(width - 1);
            for c in 0..3 {
                let top = sample(x0, y0, c) * (1.0 - fx) + sample(x1, y0, c) * fx;
                let bottom = sample(x0, y1, c) * (1.0 - fx) + sample(x1, y1, c) * fx;
                let v = top * (1.0 - fy) + bottom * fy;
                out[[0, c, y, x]] = (v - PIXEL_MEAN[c]) / PIXEL_STD[c];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_image_normalises_and_pads() {
        let (w, h) = (64, 32);
        let rgb = vec![200u8; w * h * 3];
        let t = encoder_input(&rgb, w, h);
        assert_eq!(t.shape(), &[1, 3, 1024, 1024]);
        let expected = (200.0 - PIXEL_MEAN[0]) / PIXEL_STD[0];
        assert!((t[[0, 0, 511, 1023]] - expected).abs() < 1e-5);
        assert_eq!(t[[0, 0, 512, 0]], 0.0, "padding below the 1024x512 image");
    }
}
