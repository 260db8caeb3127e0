//! Masked SSIM (docs/METHOD.md §9): the standard 11×11 Gaussian window (σ = 1.5, C1 = 0.01²,
//! C2 = 0.03²), with window statistics taken over valid pixels only.
//!
//! Normalised convolution: with mask m and window G, μx = G∗(m·x) / G∗m, and likewise for
//! E[x²], E[y²], E[xy]. Masked pixels never enter any statistic (their values cannot change
//! the result), and pixels outside the image are treated as masked, so there is no
//! zero-padding bias at the borders. With every pixel valid this equals 3DGS's `ssim`
//! except in the 5-pixel border ring (3DGS pads with zeros there).

use opengs_splat::{ssim_blur, SSIM_C1, SSIM_C2};
use rayon::prelude::*;

use crate::image_pair::check_sizes;

/// Mean SSIM over the valid pixels and the three channels of `rendered` (RGB in [0, 1],
/// clamped) against `target_rgb8` (interleaved RGB8), both `width × height`.
/// NaN when no pixel is valid.
///
/// # Panics
/// When a buffer does not hold `width × height` pixels.
pub fn ssim_masked(
    rendered: &[[f32; 3]],
    target_rgb8: &[u8],
    valid: &[bool],
    width: u32,
    height: u32,
) -> f64 {
    check_sizes(rendered, target_rgb8, valid);
    let (w, h) = (width as usize, height as usize);
    assert_eq!(rendered.len(), w * h, "render is not width × height");
    let n_valid = valid.iter().filter(|&&v| v).count();
    if n_valid == 0 {
        return f64::NAN;
    }
    let mut tmp = Vec::new();
    let blur = |src: &[f32], tmp: &mut Vec<f32>| {
        let mut dst = vec![0.0f32; w * h];
        ssim_blur(src, w, h, tmp, &mut dst);
        dst
    };
    let mask: Vec<f32> = valid.iter().map(|&v| v as u8 as f32).collect();
    let weight = blur(&mask, &mut tmp);
    let mut total = 0.0f64;
    for c in 0..3 {
        // Masked pixels are zeroed here, so their values cannot reach any window statistic.
        let x: Vec<f32> = rendered
            .iter()
            .zip(&mask)
            .map(|(p, &m)| m * p[c].clamp(0.0, 1.0))
            .collect();
        let y: Vec<f32> = target_rgb8
            .chunks_exact(3)
            .zip(&mask)
            .map(|(p, &m)| m * p[c] as f32 / 255.0)
            .collect();
        let product =
            |a: &[f32], b: &[f32]| -> Vec<f32> { a.iter().zip(b).map(|(&a, &b)| a * b).collect() };
        let sum_x = blur(&x, &mut tmp);
        let sum_y = blur(&y, &mut tmp);
        let sum_xx = blur(&product(&x, &x), &mut tmp);
        let sum_yy = blur(&product(&y, &y), &mut tmp);
        let sum_xy = blur(&product(&x, &y), &mut tmp);
        total += (0..w * h)
            .into_par_iter()
            .filter(|&i| valid[i])
            .map(|i| {
                let k = 1.0 / weight[i] as f64;
                let (mx, my) = (sum_x[i] as f64 * k, sum_y[i] as f64 * k);
                let vxx = sum_xx[i] as f64 * k - mx * mx;
                let vyy = sum_yy[i] as f64 * k - my * my;
                let vxy = sum_xy[i] as f64 * k - mx * my;
                let (c1, c2) = (SSIM_C1 as f64, SSIM_C2 as f64);
                (2.0 * mx * my + c1) * (2.0 * vxy + c2)
                    / ((mx * mx + my * my + c1) * (vxx + vyy + c2))
            })
            .sum::<f64>();
    }
    total / (3 * n_valid) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_image(rng: &mut ChaCha8Rng, n: usize) -> Vec<u8> {
        (0..3 * n).map(|_| rng.gen()).collect()
    }

    fn as_render(rgb8: &[u8]) -> Vec<[f32; 3]> {
        rgb8.chunks_exact(3)
            .map(|p| [0, 1, 2].map(|c| p[c] as f32 / 255.0))
            .collect()
    }

    #[test]
    fn identical_images_score_one() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (w, h) = (31u32, 17u32);
        let target = random_image(&mut rng, (w * h) as usize);
        let valid: Vec<bool> = (0..w * h).map(|i| i % 7 != 0).collect();
        let s = ssim_masked(&as_render(&target), &target, &valid, w, h);
        assert!((s - 1.0).abs() < 1e-6, "{s}");
    }

    #[test]
    fn constant_images_give_the_luminance_term() {
        // σ = 0 everywhere, so SSIM = (2ab + C1) / (a² + b² + C1) at every pixel.
        let (w, h) = (20u32, 15u32);
        let n = (w * h) as usize;
        let (a, b8) = (0.6f32, 77u8);
        let b = b8 as f64 / 255.0;
        let a64 = a as f64;
        let c1 = (0.01f64).powi(2);
        let expected = (2.0 * a64 * b + c1) / (a64 * a64 + b * b + c1); // 0.8405…
        let s = ssim_masked(&vec![[a; 3]; n], &vec![b8; 3 * n], &vec![true; n], w, h);
        assert!((s - expected).abs() < 1e-4, "{s} vs {expected}");
    }

    #[test]
    fn masked_corruption_changes_nothing() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let (w, h) = (40u32, 30u32);
        let n = (w * h) as usize;
        let target = random_image(&mut rng, n);
        let mut rendered = as_render(&target);
        for p in rendered.iter_mut() {
            p[1] = (p[1] + 0.05).min(1.0); // some genuine error everywhere
        }
        // A masked block in the middle.
        let masked =
            |i: usize| (10..20).contains(&(i % w as usize)) && (8..18).contains(&(i / w as usize));
        let valid: Vec<bool> = (0..n).map(|i| !masked(i)).collect();
        let clean = ssim_masked(&rendered, &target, &valid, w, h);
        let (mut bad_render, mut bad_target) = (rendered.clone(), target.clone());
        for i in (0..n).filter(|&i| masked(i)) {
            bad_render[i] = [rng.gen(), rng.gen(), rng.gen()];
            bad_target[3 * i] = rng.gen();
        }
        let corrupted = ssim_masked(&bad_render, &bad_target, &valid, w, h);
        assert_eq!(clean, corrupted);
        assert!(clean < 0.999, "{clean}");
        // Unmasked, the corruption does lower SSIM.
        let all = vec![true; n];
        assert!(ssim_masked(&bad_render, &bad_target, &all, w, h) < clean - 0.01);
    }
}
