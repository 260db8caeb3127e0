//! Per-frame depth-noise estimate. Structured-light and stereo depth has
//! roughly constant noise in inverse depth (σ_z ∝ z²), and 1/z is affine in
//! pixel coordinates on any plane, so the second difference of 1/z along
//! rows is pure noise on planar surfaces: its robust spread gives σ(1/z).

/// Depth-noise model of one frame: σ(z) = `inverse_depth_sigma` · z².
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DepthNoiseModel {
    /// Standard deviation of 1/z (1/m) on the grid it was estimated on.
    pub inverse_depth_sigma: f32,
}

/// Relative step beyond which three samples are not one surface.
const CONTINUITY: f32 = 0.05;

impl DepthNoiseModel {
    /// Robust estimate (median absolute second difference) from a depth grid.
    pub fn estimate(depth_m: &[f32], width: usize, height: usize) -> Self {
        let mut residuals = Vec::with_capacity(depth_m.len());
        for row in depth_m.chunks(width).take(height) {
            for t in row.windows(3) {
                let (a, b, c) = (t[0], t[1], t[2]);
                if a <= 0.0 || b <= 0.0 || c <= 0.0 {
                    continue;
                }
                if (a - b).abs() > CONTINUITY * b || (c - b).abs() > CONTINUITY * b {
                    continue;
                }
                residuals.push((1.0 / a - 2.0 / b + 1.0 / c).abs());
            }
        }
        if residuals.is_empty() {
            return Self::default();
        }
        let mid = residuals.len() / 2;
        let (_, median, _) = residuals.select_nth_unstable_by(mid, f32::total_cmp);
        // MAD → σ for a Gaussian, and var(a − 2b + c) = 6σ².
        Self {
            inverse_depth_sigma: 1.4826 * *median / 6f32.sqrt(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn exact_plane_has_no_noise_and_noisy_plane_is_measured() {
        // A slanted plane: 1/z affine in u.
        let (w, h) = (64, 16);
        let clean: Vec<f32> = (0..w * h)
            .map(|i| 1.0 / (0.5 + 0.002 * (i % w) as f32))
            .collect();
        let m = DepthNoiseModel::estimate(&clean, w, h);
        assert!(m.inverse_depth_sigma < 1e-4, "{m:?}");
        // Gaussian noise of σ = 0.01 in inverse depth (Box–Muller).
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let noisy: Vec<f32> = clean
            .iter()
            .map(|&z| {
                let (u1, u2): (f32, f32) = (rng.gen_range(1e-6..1.0), rng.gen());
                let n = (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos();
                1.0 / (1.0 / z + 0.01 * n)
            })
            .collect();
        let m = DepthNoiseModel::estimate(&noisy, w, h);
        assert!((m.inverse_depth_sigma - 0.01).abs() < 0.0015, "{m:?}");
    }
}
