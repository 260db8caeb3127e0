//! Mapping loss (docs/METHOD.md §8): `w_l1·L1(C) + w_ssim·(1 − SSIM(C)) + w_depth·L1(D)`, with
//! pixels of invalid (0) target depth left out of the depth term; value and dL/dC, dL/dD.

use rayon::prelude::*;

use crate::ssim::{ssim_plane, SsimScratch};
use crate::target::TargetFrame;

/// Loss weights; defaults are the paper's 0.8 / 0.2 / 0.1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossWeights {
    pub l1: f32,
    pub ssim: f32,
    pub depth: f32,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            l1: 0.8,
            ssim: 0.2,
            depth: 0.1,
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

/// Reusable planes of the loss.
#[derive(Debug, Default)]
pub struct Loss {
    ssim: SsimScratch,
    render_plane: Vec<f32>,
    grad_plane: Vec<f32>,
}

impl Loss {
    pub fn new() -> Self {
        Self::default()
    }

    /// Evaluates the loss of a render (`color`, `depth`) against `target`; writes dL/dC and
    /// dL/dD (resized to one entry per pixel).
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
        dl_dcolor.clear();
        dl_dcolor.resize(n, [0.0; 3]);
        dl_ddepth.clear();
        dl_ddepth.resize(n, 0.0);
        let (wd, hd) = (target.width as usize, target.height as usize);
        let inv_n3 = 1.0 / (3 * n) as f32;

        let (mut l1, mut sq_err, mut ssim_sum) = (0.0f64, 0.0f64, 0.0f64);
        for c in 0..3 {
            let tp = &target.rgb[c];
            self.render_plane.resize(n, 0.0);
            self.grad_plane.resize(n, 0.0);
            // One pass: the render's plane, the L1 subgradient sign(C − Ĉ) (0 at equality),
            // and the L1 and squared-error sums.
            let (a, s): (f64, f64) = self
                .render_plane
                .par_iter_mut()
                .zip(self.grad_plane.par_iter_mut())
                .zip(color.par_iter().zip(tp.par_iter()))
                .with_min_len(4096)
                .map(|((x, g), (p, &y))| {
                    *x = p[c];
                    *g = w.l1 * inv_n3 * sign(*x - y);
                    let e = x.clamp(0.0, 1.0) - y;
                    ((*x - y).abs() as f64, (e * e) as f64)
                })
                .reduce(|| (0.0, 0.0), |p, q| (p.0 + q.0, p.1 + q.1));
            l1 += a;
            sq_err += s;
            ssim_sum += ssim_plane(
                &self.render_plane,
                tp,
                wd,
                hd,
                -w.ssim * inv_n3,
                Some(&mut self.grad_plane),
                &mut self.ssim,
            );
            dl_dcolor
                .par_iter_mut()
                .zip(self.grad_plane.par_iter())
                .with_min_len(4096)
                .for_each(|(g, &v)| g[c] = v);
        }

        let valid = target.depth.par_iter().filter(|&&d| d > 0.0).count();
        let mut depth_l1 = 0.0f64;
        if valid > 0 {
            let k = w.depth / valid as f32;
            depth_l1 = dl_ddepth
                .par_iter_mut()
                .zip(depth.par_iter().zip(target.depth.par_iter()))
                .with_min_len(4096)
                .filter(|(_, (_, &t))| t > 0.0)
                .map(|(g, (&d, &t))| {
                    *g = k * sign(d - t);
                    (d - t).abs() as f64
                })
                .sum::<f64>()
                / valid as f64;
        }
        let l1 = (l1 / (3 * n) as f64) as f32;
        let ssim = (ssim_sum / (3 * n) as f64) as f32;
        let mse = sq_err / (3 * n) as f64;
        LossValue {
            total: w.l1 * l1 + w.ssim * (1.0 - ssim) + w.depth * depth_l1 as f32,
            l1,
            ssim,
            depth_l1: depth_l1 as f32,
            psnr: (-10.0 * mse.max(1e-20).log10()) as f32,
        }
    }
}

fn sign(v: f32) -> f32 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
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
        let wts = LossWeights::default();
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
