//! Kinect-like depth corruption: axial Gaussian noise, disparity
//! quantisation, dropouts at depth edges and at random, and a range cut-off.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthNoise {
    /// Depth beyond this is reported missing (metres).
    pub max_depth: f32,
    /// Fraction of pixels dropped at random.
    pub random_dropout: f32,
    /// Probability of dropping a pixel next to a depth discontinuity.
    pub edge_dropout: f32,
    /// Neighbour jump that counts as a discontinuity, relative to depth.
    pub edge_jump: f32,
    /// Focal length × baseline of the simulated stereo pair (pixels·metres).
    pub focal_baseline: f32,
    /// Disparity resolution in pixels (Kinect: 1/8).
    pub disparity_step: f32,
}

impl Default for DepthNoise {
    fn default() -> Self {
        Self {
            max_depth: 4.0,
            random_dropout: 0.005,
            edge_dropout: 0.5,
            edge_jump: 0.05,
            focal_baseline: 525.0 * 0.075,
            disparity_step: 0.125,
        }
    }
}

/// Axial standard deviation of Kinect depth at `z` metres.
pub fn kinect_sigma(z: f32) -> f32 {
    0.0012 + 0.0019 * (z - 0.4) * (z - 0.4)
}

/// Metres → depth units, 0 where missing or beyond the u16 range.
pub fn quantize_depth(depth_m: &[f32], scale: f32) -> Vec<u16> {
    depth_m.iter().map(|&z| to_units(z, scale)).collect()
}

fn to_units(z: f32, scale: f32) -> u16 {
    // +0.5 then truncation rounds positive values without a libm call.
    let units = z * scale + 0.5;
    if z > 0.0 && units < 65535.5 {
        units as u16
    } else {
        0
    }
}

impl DepthNoise {
    /// Corrupts a clean metric depth image; deterministic for (seed, frame).
    pub fn apply(
        &self,
        depth_m: &[f32],
        width: usize,
        scale: f32,
        seed: u64,
        frame: usize,
    ) -> Vec<u16> {
        let height = depth_m.len() / width.max(1);
        let mut out = vec![0u16; depth_m.len()];
        out.par_chunks_mut(width).enumerate().for_each(|(v, row)| {
            // One stream per (seed, frame, row) keeps rayon scheduling irrelevant.
            let stream = seed
                .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                .wrapping_add((frame as u64) << 20)
                .wrapping_add(v as u64);
            let mut rng = ChaCha8Rng::seed_from_u64(stream);
            for (u, px) in row.iter_mut().enumerate() {
                let z = depth_m[v * width + u];
                if z <= 0.0 || z > self.max_depth || rng.gen::<f32>() < self.random_dropout {
                    continue;
                }
                if self.near_edge(depth_m, width, height, u, v)
                    && rng.gen::<f32>() < self.edge_dropout
                {
                    continue;
                }
                let g = gaussian(&mut rng);
                let noisy = z + kinect_sigma(z) * g;
                *px = to_units(self.quantize_disparity(noisy), scale);
            }
        });
        out
    }

    fn quantize_disparity(&self, z: f32) -> f32 {
        if z <= 0.0 {
            return 0.0;
        }
        let disparity = self.focal_baseline / z;
        let q = ((disparity / self.disparity_step + 0.5) as u32) as f32 * self.disparity_step;
        if q <= 0.0 {
            0.0
        } else {
            self.focal_baseline / q
        }
    }

    fn near_edge(&self, depth: &[f32], width: usize, height: usize, u: usize, v: usize) -> bool {
        let z = depth[v * width + u];
        let limit = self.edge_jump * z.max(0.5);
        let neighbours = [
            (u.wrapping_sub(1), v),
            (u + 1, v),
            (u, v.wrapping_sub(1)),
            (u, v + 1),
        ];
        neighbours
            .iter()
            .filter(|(x, y)| *x < width && *y < height)
            .any(|&(x, y)| (depth[y * width + x] - z).abs() > limit)
    }
}

/// Approximately standard normal sample: Irwin–Hall sum of four uniforms
/// taken from one 64-bit draw (no libm ln/cos per pixel; tails cut at ±3.46σ,
/// irrelevant for sensor noise).
fn gaussian(rng: &mut ChaCha8Rng) -> f32 {
    let bits: u64 = rng.gen();
    let sum: u32 = (0..4).map(|i| ((bits >> (16 * i)) & 0xFFFF) as u32).sum();
    // Sum of four U(0,1) has mean 2 and variance 1/3.
    (sum as f32 / 65536.0 - 2.0) * 3f32.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_deterministic_and_bounded() {
        let depth: Vec<f32> = (0..64 * 48).map(|i| 0.5 + (i % 64) as f32 * 0.06).collect();
        let n = DepthNoise::default();
        let a = n.apply(&depth, 64, 5000.0, 7, 3);
        let b = n.apply(&depth, 64, 5000.0, 7, 3);
        assert_eq!(a, b);
        let c = n.apply(&depth, 64, 5000.0, 8, 3);
        assert_ne!(a, c);
        for (z, d) in depth.iter().zip(&a) {
            if *z > 4.0 {
                assert_eq!(*d, 0);
            } else if *d != 0 {
                let err = (*d as f32 / 5000.0 - z).abs();
                assert!(err < 6.0 * kinect_sigma(*z) + 0.02, "z {z} err {err}");
            }
        }
    }

    #[test]
    fn gaussian_has_unit_variance() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let xs: Vec<f32> = (0..100_000).map(|_| gaussian(&mut rng)).collect();
        let mean = xs.iter().sum::<f32>() / xs.len() as f32;
        let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f32>() / xs.len() as f32;
        assert!(
            mean.abs() < 0.01 && (var - 1.0).abs() < 0.02,
            "{mean} {var}"
        );
    }

    #[test]
    fn sigma_matches_model() {
        assert!((kinect_sigma(0.4) - 0.0012).abs() < 1e-7);
        assert!((kinect_sigma(2.4) - (0.0012 + 0.0019 * 4.0)).abs() < 1e-6);
    }
}
