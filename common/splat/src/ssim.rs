//! SSIM with the standard 11×11 Gaussian window (σ = 1.5, C1 = 0.01², C2 = 0.03²), zero
//! padded like 3DGS's `conv2d(padding = 5)`, and its gradient w.r.t. the first image.
//!
//! Per pixel, with μ = G∗x, m_xx = G∗x², m_xy = G∗(x·y):
//! ssim = (2μxμy + C1)(2σxy + C2) / ((μx² + μy² + C1)(σxx + σyy + C2)),
//! σxx = m_xx − μx², σxy = m_xy − μxμy. As G∗ is self-adjoint (symmetric kernel, zero
//! padding): ∂Σssim/∂x = G∗(∂/∂μx) + 2x·G∗(∂/∂m_xx) + y·G∗(∂/∂m_xy).
//!
//! Hand-written: no image crate provides this gradient. [`ssim_plane`] is the plane-by-plane
//! form (seven full-size planes): the mapping loss's reference twin uses it; the loss itself
//! (the hot path) runs the same maths fused with L1 and depth in `fused_loss`.

use rayon::prelude::*;

use crate::cpu::SimdLevel;

pub const SSIM_C1: f32 = 0.01 * 0.01;
pub const SSIM_C2: f32 = 0.03 * 0.03;
pub(crate) const RADIUS: usize = 5;
pub(crate) const TAPS: usize = 2 * RADIUS + 1;
/// Rows per parallel task.
const ROWS: usize = 8;

/// Normalised 1D Gaussian of the window (σ = 1.5).
pub(crate) fn kernel() -> [f32; TAPS] {
    let w: [f64; TAPS] = std::array::from_fn(|i| {
        let d = i as f64 - RADIUS as f64;
        (-d * d / (2.0 * 1.5 * 1.5)).exp()
    });
    let s: f64 = w.iter().sum();
    w.map(|v| (v / s) as f32)
}

/// `dst = G ∗ src` over a `w × h` plane, zero padded, via a horizontal then a vertical pass
/// (both written as "for each tap, for each x" so the inner loops vectorise).
pub fn blur(src: &[f32], w: usize, h: usize, tmp: &mut Vec<f32>, dst: &mut [f32]) {
    // Read on the calling thread: the workers have no cap of their own.
    let simd = SimdLevel::current();
    let k = kernel();
    tmp.resize(w * h, 0.0);
    tmp.par_chunks_mut(ROWS * w)
        .zip(src.par_chunks(ROWS * w))
        .for_each_init(Vec::new, |pad, (t, s)| {
            pad.clear();
            pad.resize(w + 2 * RADIUS, 0.0);
            for (trow, srow) in t.chunks_mut(w).zip(s.chunks(w)) {
                pad[RADIUS..RADIUS + w].copy_from_slice(srow);
                trow.fill(0.0);
                for (tap, &kv) in k.iter().enumerate() {
                    axpy(simd, trow, kv, &pad[tap..tap + w]);
                }
            }
        });
    let tmp = &tmp[..];
    dst.par_chunks_mut(ROWS * w).enumerate().for_each(|(c, d)| {
        for (r, drow) in d.chunks_mut(w).enumerate() {
            let y = c * ROWS + r;
            drow.fill(0.0);
            let lo = y.saturating_sub(RADIUS);
            let hi = (y + RADIUS).min(h - 1);
            for yy in lo..=hi {
                let kv = k[yy + RADIUS - y];
                axpy(simd, drow, kv, &tmp[yy * w..(yy + 1) * w]);
            }
        }
    });
}

/// o += k·v, compiled for the widest vector unit the CPU has.
#[inline]
fn axpy(simd: SimdLevel, o: &mut [f32], k: f32, v: &[f32]) {
    match simd {
        // SAFETY: the Avx512 level has AVX-512F (SimdLevel::detected).
        #[cfg(target_arch = "x86_64")]
        SimdLevel::Avx512 => unsafe { axpy_avx512(o, k, v) },
        // SAFETY: the Avx2 level has AVX2 (SimdLevel::detected).
        #[cfg(target_arch = "x86_64")]
        SimdLevel::Avx2 => unsafe { axpy_avx2(o, k, v) },
        SimdLevel::Portable => axpy_portable(o, k, v),
    }
}

#[inline(always)]
fn axpy_portable(o: &mut [f32], k: f32, v: &[f32]) {
    for (o, &v) in o.iter_mut().zip(v) {
        *o += k * v;
    }
}

/// # Safety
/// The caller must ensure the CPU supports AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
unsafe fn axpy_avx512(o: &mut [f32], k: f32, v: &[f32]) {
    axpy_portable(o, k, v)
}

/// # Safety
/// The caller must ensure the CPU supports AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn axpy_avx2(o: &mut [f32], k: f32, v: &[f32]) {
    axpy_portable(o, k, v)
}

/// Reusable planes for [`ssim_plane`].
#[derive(Debug, Default)]
pub struct SsimScratch {
    planes: [Vec<f32>; 7],
    tmp: Vec<f32>,
}

/// Σ_p ssim_p of planes `x`, `y` (`w × h`). With `grad`, adds `scale · ∂(Σ ssim)/∂x` to it.
pub fn ssim_plane(
    x: &[f32],
    y: &[f32],
    w: usize,
    h: usize,
    scale: f32,
    grad: Option<&mut [f32]>,
    s: &mut SsimScratch,
) -> f64 {
    let n = w * h;
    assert!(x.len() == n && y.len() == n, "plane size mismatch");
    for p in &mut s.planes {
        p.resize(n, 0.0);
    }
    let [mu_x, mu_y, m_xx, m_yy, m_xy, prod, _] = &mut s.planes;
    blur(x, w, h, &mut s.tmp, mu_x);
    blur(y, w, h, &mut s.tmp, mu_y);
    prod.par_iter_mut()
        .zip(x.par_iter())
        .for_each(|(p, &v)| *p = v * v);
    blur(prod, w, h, &mut s.tmp, m_xx);
    prod.par_iter_mut()
        .zip(y.par_iter())
        .for_each(|(p, &v)| *p = v * v);
    blur(prod, w, h, &mut s.tmp, m_yy);
    prod.par_iter_mut()
        .zip(x.par_iter().zip(y.par_iter()))
        .for_each(|(p, (&a, &b))| *p = a * b);
    blur(prod, w, h, &mut s.tmp, m_xy);

    // Per pixel: ssim, and (in place of μx, m_xx, m_xy) scale · ∂ssim/∂(μx, m_xx, m_xy).
    let total: f64 = mu_x
        .par_chunks_mut(ROWS * w)
        .zip(m_xx.par_chunks_mut(ROWS * w))
        .zip(m_xy.par_chunks_mut(ROWS * w))
        .zip(mu_y.par_chunks(ROWS * w).zip(m_yy.par_chunks(ROWS * w)))
        .map(|(((mx, mxx), mxy), (my, myy))| {
            let mut sum = 0.0f64;
            for i in 0..mx.len() {
                let (ux, uy) = (mx[i], my[i]);
                let a1 = 2.0 * ux * uy + SSIM_C1;
                let a2 = 2.0 * (mxy[i] - ux * uy) + SSIM_C2;
                let b1 = ux * ux + uy * uy + SSIM_C1;
                let b2 = (mxx[i] - ux * ux) + (myy[i] - uy * uy) + SSIM_C2;
                let inv = 1.0 / (b1 * b2);
                let ssim = a1 * a2 * inv;
                sum += ssim as f64;
                let d_mu = 2.0 * uy * (a2 - a1) * inv + ssim * 2.0 * ux * (1.0 / b2 - 1.0 / b1);
                mx[i] = scale * d_mu;
                mxx[i] = scale * (-ssim / b2);
                mxy[i] = scale * 2.0 * a1 * inv;
            }
            sum
        })
        .sum();

    if let Some(grad) = grad {
        let [d_mu, _, d_xx, _, d_xy, b_mu, b_xx] = &mut s.planes;
        blur(d_mu, w, h, &mut s.tmp, b_mu);
        blur(d_xx, w, h, &mut s.tmp, b_xx);
        // d_mu is free again: reuse it for G∗(∂/∂m_xy).
        let b_xy = d_mu;
        blur(d_xy, w, h, &mut s.tmp, b_xy);
        grad.par_iter_mut()
            .enumerate()
            .for_each(|(i, g)| *g += b_mu[i] + 2.0 * x[i] * b_xx[i] + y[i] * b_xy[i]);
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_plane(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
        (0..n).map(|_| rng.gen_range(0.0..1.0)).collect()
    }

    #[test]
    fn identical_images_have_ssim_one_away_from_borders_effects() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (w, h) = (24, 20);
        let x = random_plane(&mut rng, w * h);
        let mut s = SsimScratch::default();
        let total = ssim_plane(&x, &x, w, h, 1.0, None, &mut s);
        assert!((total / (w * h) as f64 - 1.0).abs() < 1e-5, "{total}");
    }

    #[test]
    fn every_kernel_level_blurs_alike() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (w, h) = (67, 41);
        let x = random_plane(&mut rng, w * h);
        let blurred = |level| {
            crate::cpu::cap_level(Some(level));
            let (mut tmp, mut out) = (Vec::new(), vec![0.0f32; w * h]);
            blur(&x, w, h, &mut tmp, &mut out);
            crate::cpu::cap_level(None);
            out
        };
        let portable = blurred(SimdLevel::Portable);
        // The blur of a constant-free random plane: interior values near its mean 0.5.
        assert!(
            (portable[20 * w + 30] - 0.5).abs() < 0.2,
            "{}",
            portable[20 * w + 30]
        );
        for level in SimdLevel::available() {
            let other = blurred(level);
            let worst = portable
                .iter()
                .zip(&other)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(worst < 1e-6, "{level:?}: worst difference {worst}");
        }
    }

    #[test]
    fn ssim_gradient_matches_finite_differences() {
        for level in SimdLevel::available() {
            crate::cpu::cap_level(Some(level));
            ssim_gradient_matches_finite_differences_here();
            crate::cpu::cap_level(None);
        }
    }

    fn ssim_gradient_matches_finite_differences_here() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let (w, h) = (23, 19);
        let x = random_plane(&mut rng, w * h);
        let y = random_plane(&mut rng, w * h);
        let mut s = SsimScratch::default();
        let mut grad = vec![0.0f32; w * h];
        ssim_plane(&x, &y, w, h, 1.0, Some(&mut grad), &mut s);
        let eps = 1e-2f32;
        let mut worst = 0.0f64;
        for i in (0..w * h).step_by(7) {
            let mut xp = x.clone();
            xp[i] += eps;
            let mut xm = x.clone();
            xm[i] -= eps;
            let fp = ssim_plane(&xp, &y, w, h, 1.0, None, &mut s);
            let fm = ssim_plane(&xm, &y, w, h, 1.0, None, &mut s);
            let fd = (fp - fm) / (2.0 * eps as f64);
            let err = (fd - grad[i] as f64).abs() / fd.abs().max(1e-2);
            worst = worst.max(err);
        }
        assert!(worst < 1e-2, "worst relative error {worst}");
    }
}
