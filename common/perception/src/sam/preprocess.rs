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

/// Encoder input tensor [1, 3, 1024, 1024] from row-major RGB8, written
/// into `out` (reused: reallocated only when it has another shape).
pub fn encoder_input_into(out: &mut Array4<f32>, rgb: &[u8], width: usize, height: usize) {
    let scale = resize_scale(width, height);
    let new_w = ((width as f32 * scale + 0.5) as usize).min(SAM_SIDE);
    let new_h = ((height as f32 * scale + 0.5) as usize).min(SAM_SIDE);
    if out.shape() != [1, 3, SAM_SIDE, SAM_SIDE] {
        *out = Array4::<f32>::zeros((1, 3, SAM_SIDE, SAM_SIDE));
    }
    // Pixel-centre mapping back to the source, clamped at the borders.
    let tap = |i: usize, n: usize| {
        let s = ((i as f32 + 0.5) / scale - 0.5).clamp(0.0, (n - 1) as f32);
        let i0 = s.floor() as usize;
        (i0, (i0 + 1).min(n - 1), s.fract())
    };
    let columns: Vec<(usize, usize, f32)> = (0..new_w).map(|x| tap(x, width)).collect();
    let Some(plane) = out.as_slice_mut() else {
        return;
    };
    let side2 = SAM_SIDE * SAM_SIDE;
    let sample = |x: usize, y: usize, c: usize| rgb[(y * width + x) * 3 + c] as f32;
    for y in 0..SAM_SIDE {
        if y >= new_h {
            // Padding below the image (it may hold an earlier, taller frame).
            for c in 0..3 {
                plane[c * side2 + y * SAM_SIDE..c * side2 + (y + 1) * SAM_SIDE].fill(0.0);
            }
            continue;
        }
        let (y0, y1, fy) = tap(y, height);
        for c in 0..3 {
            let row = &mut plane[c * side2 + y * SAM_SIDE..c * side2 + (y + 1) * SAM_SIDE];
            for (x, &(x0, x1, fx)) in columns.iter().enumerate() {
                let top = sample(x0, y0, c) * (1.0 - fx) + sample(x1, y0, c) * fx;
                let bottom = sample(x0, y1, c) * (1.0 - fx) + sample(x1, y1, c) * fx;
                let v = top * (1.0 - fy) + bottom * fy;
                row[x] = (v - PIXEL_MEAN[c]) / PIXEL_STD[c];
            }
            row[new_w..].fill(0.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_image_normalises_and_pads() {
        let (w, h) = (64, 32);
        let rgb = vec![200u8; w * h * 3];
        let mut t = Array4::zeros((0, 0, 0, 0));
        encoder_input_into(&mut t, &rgb, w, h);
        assert_eq!(t.shape(), &[1, 3, 1024, 1024]);
        let expected = (200.0 - PIXEL_MEAN[0]) / PIXEL_STD[0];
        assert!((t[[0, 0, 511, 1023]] - expected).abs() < 1e-5);
        assert_eq!(t[[0, 0, 512, 0]], 0.0, "padding below the 1024x512 image");
    }
}
