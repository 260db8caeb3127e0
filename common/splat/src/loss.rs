//! Mapping loss (docs/METHOD.md §8): `w_l1·L1(C) + w_ssim·(1 − SSIM(C)) + w_depth·L1(D)`, with
//! pixels of invalid (0) target depth left out of the depth term; value and dL/dC, dL/dD.
//! By default the colour of a pixel without target depth is held fixed (no dL/dC there): such
//! a pixel says nothing about where a surface is, and its colour would stretch the nearest
//! Gaussians over it (a far wall beyond the sensor's range painted by the objects before it).

use rayon::prelude::*;

use crate::cpu::SimdLevel;
use crate::fused_loss::{band, band_rows, BandScratch, BandSums, LossInputs};
use crate::target::TargetFrame;

/// Loss weights; defaults are the paper's 0.8 / 0.2 / 0.1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossWeights {
    pub l1: f32,
    pub ssim: f32,
    pub depth: f32,
    /// dL/dC is 0 at pixels whose target depth is invalid: the gradient of the loss with the
    /// render's colour there held fixed (the value is the whole image's). Not in the paper.
    pub colour_needs_depth: bool,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            l1: 0.8,
            ssim: 0.2,
            depth: 0.1,
            colour_needs_depth: true,
        }
    }
}

/// Zeroes dL/dC where the target depth is invalid (`LossWeights::colour_needs_depth`).
pub(crate) fn hold_colour_without_depth(dl_dcolor: &mut [[f32; 3]], target_depth: &[f32]) {
    for (g, &t) in dl_dcolor.iter_mut().zip(target_depth) {
        if t <= 0.0 {
            *g = [0.0; 3];
        }
    }
}

/// Loss terms of one evaluation (unweighted terms, plus the weighted total).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LossValue {
    pub total: f32,
    /// Mean |C − Ĉ| over pixels and channels.
    pub l1: f32,
    /// Mean SSIM over pixels and channels.
    pub ssim: f32,
    /// Mean |D − D̂| over pixels with valid target depth.
    pub depth_l1: f32,
    /// PSNR (dB) of the colour clamped to [0, 1].
    pub psnr: f32,
}

/// The loss evaluator; owns its per-band buffers (a few hundred KB each, reused every step:
/// nothing image-sized is allocated per evaluation).
#[derive(Debug, Default)]
pub struct Loss {
    bands: Vec<BandScratch>,
}

impl Loss {
    pub fn new() -> Self {
        Self::default()
    }

    /// Evaluates the loss of a render (`color`, `depth`) against `target`; writes dL/dC and
    /// dL/dD (resized to one entry per pixel). One fused pass (`fused_loss`): SSIM
    /// with the 11×11 Gaussian window, zero padded, its five moments shared by value and
    /// gradient; L1 and the depth term in the same pass.
    pub fn eval(
        &mut self,
        color: &[[f32; 3]],
        depth: &[f32],
        target: &TargetFrame,
        w: &LossWeights,
        dl_dcolor: &mut Vec<[f32; 3]>,
        dl_ddepth: &mut Vec<f32>,
    ) -> LossValue {
        let n = target.pixels();
        assert!(
            color.len() == n && depth.len() == n,
            "render and target sizes differ"
        );
        // Every entry is written below: no clearing pass.
        dl_dcolor.resize(n, [0.0; 3]);
        dl_ddepth.resize(n, 0.0);
        if n == 0 {
            return LossValue::default();
        }
        let (wd, hd) = (target.width as usize, target.height as usize);
        let inv_n3 = 1.0 / (3 * n) as f32;
        let valid = target
            .depth
            .par_chunks(1 << 14)
            .map(|c| c.iter().filter(|&&d| d > 0.0).count())
            .sum::<usize>();
        let inputs = LossInputs {
            color,
            depth,
            target_rgb: [&target.rgb[0], &target.rgb[1], &target.rgb[2]],
            target_depth: &target.depth,
            width: wd,
            height: hd,
            k_l1: w.l1 * inv_n3,
            k_ssim: -w.ssim * inv_n3,
            k_depth: if valid > 0 {
                w.depth / valid as f32
            } else {
                0.0
            },
        };
        let rows = band_rows(hd, rayon::current_num_threads());
        let bands = hd.div_ceil(rows);
        if self.bands.len() < bands {
            self.bands.resize_with(bands, BandScratch::default);
        }
        // Read on the calling thread: the workers have no cap of their own.
        let simd = SimdLevel::current();
        let sums = dl_dcolor
            .par_chunks_mut(rows * wd)
            .zip(dl_ddepth.par_chunks_mut(rows * wd))
            .zip(self.bands.par_iter_mut())
            .enumerate()
            .map(|(b, ((gc, gd), scratch))| {
                let (r0, r1) = (b * rows, ((b + 1) * rows).min(hd));
                let sums = band(simd, &inputs, r0, r1, gc, gd, scratch);
                if w.colour_needs_depth {
                    hold_colour_without_depth(gc, &target.depth[r0 * wd..r1 * wd]);
                }
                sums
            })
            .reduce(BandSums::default, BandSums::add);

        let depth_l1 = if valid > 0 {
            sums.depth / valid as f64
        } else {
            0.0
        };
        let l1 = (sums.l1 / (3 * n) as f64) as f32;
        let ssim = (sums.ssim / (3 * n) as f64) as f32;
        let mse = sums.sq_err / (3 * n) as f64;
        LossValue {
            total: w.l1 * l1 + w.ssim * (1.0 - ssim) + w.depth * depth_l1 as f32,
            l1,
            ssim,
            depth_l1: depth_l1 as f32,
            psnr: (-10.0 * mse.max(1e-20).log10()) as f32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn loss_gradient_matches_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (w, h) = (24u32, 20u32);
        let n = (w * h) as usize;
        let rgb: Vec<[f32; 3]> = (0..n).map(|_| [rng.gen(), rng.gen(), rng.gen()]).collect();
        let depth: Vec<f32> = (0..n)
            .map(|i| {
                if i % 5 == 0 {
                    0.0
                } else {
                    rng.gen_range(1.0..3.0)
                }
            })
            .collect();
        let target = TargetFrame::from_rgb_f32(w, h, &rgb, &depth);
        let color: Vec<[f32; 3]> = (0..n).map(|_| [rng.gen(), rng.gen(), rng.gen()]).collect();
        let render_depth: Vec<f32> = (0..n).map(|_| rng.gen_range(1.0..3.0)).collect();
        // The exact gradient: no colour held at the pixels without depth.
        let wts = LossWeights {
            colour_needs_depth: false,
            ..LossWeights::default()
        };
        let mut loss = Loss::new();
        let (mut gc, mut gd) = (Vec::new(), Vec::new());
        let v = loss.eval(&color, &render_depth, &target, &wts, &mut gc, &mut gd);
        assert!(v.total > 0.0 && v.psnr.is_finite());
        let (mut sc, mut sd) = (Vec::new(), Vec::new());
        let eps = 1e-2f32;
        let mut worst = 0.0f64;
        for i in (0..n).step_by(11) {
            for c in 0..3 {
                // Skip pixels where the L1 kink is within reach of the step.
                if (color[i][c] - rgb[i][c]).abs() < 2.0 * eps {
                    continue;
                }
                let mut cp = color.clone();
                cp[i][c] += eps;
                let fp = loss
                    .eval(&cp, &render_depth, &target, &wts, &mut sc, &mut sd)
                    .total;
                cp[i][c] -= 2.0 * eps;
                let fm = loss
                    .eval(&cp, &render_depth, &target, &wts, &mut sc, &mut sd)
                    .total;
                let fd = (fp - fm) as f64 / (2.0 * eps as f64);
                let err = (fd - gc[i][c] as f64).abs() / (gc[i][c] as f64).abs().max(1e-4);
                worst = worst.max(err);
            }
        }
        assert!(worst < 0.05, "colour gradient worst relative error {worst}");
        assert_eq!(gd[0], 0.0, "invalid target depth must be masked");
        let valid = depth.iter().filter(|&&d| d > 0.0).count() as f32;
        assert!((gd[1].abs() - 0.1 / valid).abs() < 1e-9);
    }
}
