//! Masked PSNR (docs/METHOD.md §9): over pixels with valid input depth only.

use crate::image_pair::check_sizes;

/// MSE floor: a perfect match reports 100 dB instead of ∞, so means stay finite.
const MIN_MSE: f64 = 1e-10;

/// PSNR in dB of `rendered` (RGB in [0, 1], clamped as when saved) against `target_rgb8`
/// (interleaved RGB8, scaled to [0, 1]), over pixels where `valid` is true:
/// `10·log10(1 / MSE)`, MSE over valid pixels × 3 channels. NaN when no pixel is valid.
///
/// # Panics
/// When the three buffers disagree on the pixel count.
pub fn psnr_masked(rendered: &[[f32; 3]], target_rgb8: &[u8], valid: &[bool]) -> f64 {
    check_sizes(rendered, target_rgb8, valid);
    let (sum, n) = rendered
        .iter()
        .zip(target_rgb8.chunks_exact(3))
        .zip(valid)
        .filter(|(_, &v)| v)
        .fold((0.0f64, 0usize), |(sum, n), ((r, t), _)| {
            let e: f64 = (0..3)
                .map(|c| {
                    let d = r[c].clamp(0.0, 1.0) as f64 - t[c] as f64 / 255.0;
                    d * d
                })
                .sum();
            (sum + e, n + 1)
        });
    if n == 0 {
        return f64::NAN;
    }
    let mse = sum / (3 * n) as f64;
    10.0 * (1.0 / mse.max(MIN_MSE)).log10()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_images_give_the_closed_form() {
        // Render 0.5 vs target 100/255 everywhere: MSE = (0.5 − 100/255)².
        let n = 12;
        let rendered = vec![[0.5f32; 3]; n];
        let target = vec![100u8; 3 * n];
        let valid = vec![true; n];
        let d = 0.5f64 - 100.0 / 255.0;
        let expected = 10.0 * (1.0 / (d * d)).log10(); // d = 0.10784…, 1/d² = 85.98… → 19.3441… dB
        let got = psnr_masked(&rendered, &target, &valid);
        assert!((got - expected).abs() < 1e-5, "{got} vs {expected}");
        assert!((got - 19.3441).abs() < 1e-4, "{got}");
    }

    #[test]
    fn masked_corruption_is_ignored_and_perfect_match_is_capped() {
        let n = 10;
        let target = vec![51u8; 3 * n]; // 0.2
        let mut rendered = vec![[0.2f32; 3]; n];
        let mut valid = vec![true; n];
        rendered[3] = [1.0, 0.0, 1.0];
        valid[3] = false;
        assert_eq!(psnr_masked(&rendered, &target, &valid), 100.0);
        valid[3] = true;
        assert!(psnr_masked(&rendered, &target, &valid) < 20.0);
        assert!(psnr_masked(&rendered, &target, &[false; 10]).is_nan());
    }

    #[test]
    fn render_is_clamped_to_unit_range() {
        let rendered = vec![[1.7f32, -0.3, 1.0]];
        let target = vec![255u8, 0, 255];
        assert_eq!(psnr_masked(&rendered, &target, &[true]), 100.0);
    }
}
