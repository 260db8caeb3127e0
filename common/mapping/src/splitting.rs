//! Densification during refinement, after 3D Gaussian Splatting: Gaussians whose mean keeps
//! a large positional gradient (they sit on edges and detail they cannot represent) are
//! split into two smaller ones sampled from their own distribution.
//!
//! The online mapper only adds Gaussians at keyframe points (docs/METHOD.md §8), about one per
//! 2 cm; texture edges finer than that stay blurred however long it optimises. Offline
//! refinement has the time to add Gaussians where the loss asks for them.

use opengs_splat::{quat_to_matrix, Adam, GaussianMap, MapGrads};
use rand::Rng;

/// Per-Gaussian sums of the positional gradient norm over the views that touched it.
#[derive(Debug, Clone, Default)]
pub struct GradientStats {
    sum: Vec<f32>,
    views: Vec<u32>,
}

impl GradientStats {
    /// Starts over for a map of `n` Gaussians.
    pub fn reset(&mut self, n: usize) {
        self.sum.clear();
        self.sum.resize(n, 0.0);
        self.views.clear();
        self.views.resize(n, 0);
    }

    /// Adds one step's gradients (a Gaussian counts as seen when its opacity got a gradient).
    pub fn add(&mut self, grads: &MapGrads) {
        if self.sum.len() != grads.len() {
            self.reset(grads.len());
        }
        for (i, g) in grads.means.iter().enumerate() {
            if grads.opacity_logits[i] != 0.0 {
                self.sum[i] += (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
                self.views[i] += 1;
            }
        }
    }

    /// Mean gradient norm per Gaussian over the views that saw it (0 when none did).
    pub fn mean(&self) -> Vec<f32> {
        self.sum
            .iter()
            .zip(&self.views)
            .map(|(&s, &v)| if v > 0 { s / v as f32 } else { 0.0 })
            .collect()
    }
}

/// 3DGS: children of a split are this much smaller than their parent.
const SPLIT_SHRINK: f32 = 1.6;

/// Splits the `fraction` of Gaussians with the largest mean positional gradient (seen at
/// least `min_views` times) into two, each at a point drawn from the parent's Gaussian with
/// the parent's scales ÷ 1.6 and its rotation, opacity, colour and label. The parents are
/// removed; the children start with fresh Adam moments. Returns how many were split.
pub fn split_largest_gradients(
    map: &mut GaussianMap,
    adam: &mut Adam,
    stats: &GradientStats,
    fraction: f32,
    min_views: u32,
    rng: &mut impl Rng,
) -> usize {
    let n = map.len();
    if n == 0 || stats.sum.len() != n {
        return 0;
    }
    let mean = stats.mean();
    let mut candidates: Vec<usize> = (0..n)
        .filter(|&i| stats.views[i] >= min_views && mean[i] > 0.0)
        .collect();
    let count = ((n as f32 * fraction) as usize).min(candidates.len());
    if count == 0 {
        return 0;
    }
    candidates.select_nth_unstable_by(count - 1, |&a, &b| mean[b].total_cmp(&mean[a]));
    candidates.truncate(count);
    let shrink = SPLIT_SHRINK.ln();
    for &i in &candidates {
        let parent = map.get(i);
        let r = quat_to_matrix(parent.rotation);
        let s = map.scale(i);
        for _ in 0..2 {
            let z: [f32; 3] = std::array::from_fn(|k| normal(rng) * s[k]);
            let mut child = parent;
            for (row, m) in r.iter().zip(child.mean.iter_mut()) {
                *m += row[0] * z[0] + row[1] * z[1] + row[2] * z[2];
            }
            child.log_scale = parent.log_scale.map(|l| l - shrink);
            map.push(child);
        }
    }
    adam.resize(map.len());
    let mut remove = vec![false; map.len()];
    for &i in &candidates {
        remove[i] = true;
    }
    adam.compact(&map.remove_where(&remove));
    count
}

/// A standard normal sample (Box–Muller).
fn normal(rng: &mut impl Rng) -> f32 {
    let u1: f32 = rng.gen_range(f32::EPSILON..1.0);
    let u2: f32 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_splat::{AdamConfig, Gaussian};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn splits_the_largest_gradients_into_smaller_children() {
        let mut map = GaussianMap::new();
        for x in 0..10 {
            map.push(Gaussian::from_values(
                [x as f32, 0.0, 2.0],
                [1.0, 0.0, 0.0, 0.0],
                [0.1, 0.05, 0.01],
                0.8,
                [0.2, 0.4, 0.6],
                7,
            ));
        }
        let mut adam = Adam::new(AdamConfig::default(), map.len());
        let mut grads = MapGrads::zeros(10);
        for i in 0..10 {
            grads.means[i] = [i as f32, 0.0, 0.0];
            grads.opacity_logits[i] = if i == 9 { 0.0 } else { 1.0 };
        }
        let mut stats = GradientStats::default();
        stats.add(&grads);
        stats.add(&grads);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        // 20 % of 10: the two largest gradients among the seen ones (8 and 7; 9 was unseen).
        let split = split_largest_gradients(&mut map, &mut adam, &stats, 0.2, 2, &mut rng);
        assert_eq!(split, 2);
        assert_eq!((map.len(), adam.len()), (12, 12));
        let xs: Vec<f32> = map.means.iter().map(|m| m[0]).collect();
        for kept in [0.0, 1.0, 6.0, 9.0] {
            assert!(xs.contains(&kept), "{kept} kept: {xs:?}");
        }
        assert!(!xs.contains(&7.0) && !xs.contains(&8.0), "{xs:?}");
        // Children: near their parent, 1.6× smaller, same look and label.
        for i in 8..12 {
            let g = map.get(i);
            assert!((g.mean[0] - 7.5).abs() < 1.0, "{:?}", g.mean);
            assert!((map.scale(i)[0] - 0.1 / 1.6).abs() < 1e-6);
            assert!((g.opacity() - 0.8).abs() < 1e-6 && g.label == 7);
        }
    }
}
