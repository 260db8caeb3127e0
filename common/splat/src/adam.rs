//! Adam with one learning rate per parameter group (3DGS defaults), whose moment buffers
//! follow the map when Gaussians are removed ([`Adam::compact`]) or appended ([`Adam::resize`]).

use rayon::prelude::*;

use crate::grads::MapGrads;
use crate::map::{normalize_quat, GaussianMap};

/// Learning rates and Adam constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdamConfig {
    /// Position lr in metres (3DGS: 1.6e-4 × scene extent).
    pub lr_mean: f32,
    pub lr_rotation: f32,
    /// lr of the log-scale.
    pub lr_log_scale: f32,
    /// lr of the opacity logit.
    pub lr_opacity: f32,
    /// lr of the SH DC colour coefficients.
    pub lr_sh_dc: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
}

impl AdamConfig {
    /// 3DGS defaults; the position lr is scaled by the scene extent (metres).
    pub fn gs_defaults(scene_extent: f32) -> Self {
        Self {
            lr_mean: 1.6e-4 * scene_extent,
            lr_rotation: 1e-3,
            lr_log_scale: 5e-3,
            lr_opacity: 5e-2,
            lr_sh_dc: 2.5e-3,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        }
    }
}

impl Default for AdamConfig {
    fn default() -> Self {
        Self::gs_defaults(1.0)
    }
}

/// Adam state: first and second moments per parameter, one shared step count (as PyTorch
/// keeps per tensor; appended Gaussians start with zero moments, as 3DGS densification does).
#[derive(Debug, Clone, Default)]
pub struct Adam {
    pub config: AdamConfig,
    pub step: u32,
    m: MapGrads,
    v: MapGrads,
}

impl Adam {
    /// State for a map of `n` Gaussians.
    pub fn new(config: AdamConfig, n: usize) -> Self {
        Self {
            config,
            step: 0,
            m: MapGrads::zeros(n),
            v: MapGrads::zeros(n),
        }
    }

    pub fn len(&self) -> usize {
        self.m.len()
    }

    pub fn is_empty(&self) -> bool {
        self.m.is_empty()
    }

    /// Follows `GaussianMap::remove_where`: pass the old→new index map it returned.
    pub fn compact(&mut self, old_to_new: &[Option<u32>]) {
        self.m.compact(old_to_new);
        self.v.compact(old_to_new);
    }

    /// Follows appends (or truncation) of the map: new Gaussians get zero moments.
    pub fn resize(&mut self, n: usize) {
        self.m.resize(n);
        self.v.resize(n);
    }

    /// One Adam update of `map` with `grads`; quaternions are re-normalised afterwards.
    pub fn update(&mut self, map: &mut GaussianMap, grads: &MapGrads) {
        assert_eq!(grads.len(), map.len(), "gradients are not of this map");
        assert!(
            self.len() <= map.len(),
            "map shrank under Adam: call Adam::compact with remove_where's index map"
        );
        // Gaussians appended since the last step start with zero moments.
        self.resize(map.len());
        self.step += 1;
        let c = self.config;
        let t = self.step as i32;
        // Bias corrections folded into the step size: lr·√(1−β2ᵗ)/(1−β1ᵗ), ε·√(1−β2ᵗ).
        let bc1 = 1.0 - (c.beta1 as f64).powi(t);
        let bc2 = 1.0 - (c.beta2 as f64).powi(t);
        let k = Step {
            beta1: c.beta1,
            beta2: c.beta2,
            eps: (c.eps as f64 * bc2.sqrt()) as f32,
            scale: (bc2.sqrt() / bc1) as f32,
        };
        let (m, v) = (&mut self.m, &mut self.v);
        adam_group(
            map.means.as_flattened_mut(),
            grads.means.as_flattened(),
            m.means.as_flattened_mut(),
            v.means.as_flattened_mut(),
            c.lr_mean,
            &k,
        );
        adam_group(
            map.rotations.as_flattened_mut(),
            grads.rotations.as_flattened(),
            m.rotations.as_flattened_mut(),
            v.rotations.as_flattened_mut(),
            c.lr_rotation,
            &k,
        );
        map.rotations
            .par_iter_mut()
            .with_min_len(4096)
            .for_each(|q| *q = normalize_quat(*q));
        adam_group(
            map.log_scales.as_flattened_mut(),
            grads.log_scales.as_flattened(),
            m.log_scales.as_flattened_mut(),
            v.log_scales.as_flattened_mut(),
            c.lr_log_scale,
            &k,
        );
        adam_group(
            &mut map.opacity_logits,
            &grads.opacity_logits,
            &mut m.opacity_logits,
            &mut v.opacity_logits,
            c.lr_opacity,
            &k,
        );
        adam_group(
            map.sh_dc.as_flattened_mut(),
            grads.sh_dc.as_flattened(),
            m.sh_dc.as_flattened_mut(),
            v.sh_dc.as_flattened_mut(),
            c.lr_sh_dc,
            &k,
        );
    }
}

struct Step {
    beta1: f32,
    beta2: f32,
    eps: f32,
    scale: f32,
}

/// θ −= lr·m̂/(√v̂ + ε) over one parameter group (flattened).
fn adam_group(p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], lr: f32, k: &Step) {
    let step = lr * k.scale;
    const CHUNK: usize = 8192;
    p.par_chunks_mut(CHUNK)
        .zip(g.par_chunks(CHUNK))
        .zip(m.par_chunks_mut(CHUNK).zip(v.par_chunks_mut(CHUNK)))
        .for_each(|((p, g), (m, v))| {
            for i in 0..p.len() {
                m[i] = k.beta1 * m[i] + (1.0 - k.beta1) * g[i];
                v[i] = k.beta2 * v[i] + (1.0 - k.beta2) * g[i] * g[i];
                p[i] -= step * m[i] / (v[i].sqrt() + k.eps);
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::Gaussian;

    #[test]
    fn first_step_moves_each_parameter_by_its_learning_rate() {
        let mut map = GaussianMap::new();
        map.push(Gaussian::from_values(
            [0.0, 0.0, 2.0],
            [1.0, 0.0, 0.0, 0.0],
            [0.1; 3],
            0.5,
            [0.5; 3],
            1,
        ));
        let before = map.clone();
        let mut g = MapGrads::zeros(1);
        g.means[0] = [2.0, -3.0, 0.0];
        g.opacity_logits[0] = -0.5;
        g.sh_dc[0] = [1e-3, 0.0, 0.0];
        let cfg = AdamConfig::gs_defaults(2.0);
        let mut adam = Adam::new(cfg, 1);
        adam.update(&mut map, &g);
        // Step 1: m̂ = g, v̂ = g², so θ moves by lr·sign(g).
        let close = |a: f32, b: f32| (a - b).abs() < 1e-6 * b.abs().max(1.0);
        assert!(close(map.means[0][0], before.means[0][0] - cfg.lr_mean));
        assert!(close(map.means[0][1], before.means[0][1] + cfg.lr_mean));
        assert_eq!(map.means[0][2], before.means[0][2]);
        assert!(close(
            map.opacity_logits[0],
            before.opacity_logits[0] + cfg.lr_opacity
        ));
        assert!(close(map.sh_dc[0][0], before.sh_dc[0][0] - cfg.lr_sh_dc));
        assert_eq!(map.rotations[0], [1.0, 0.0, 0.0, 0.0]);
        // Appending grows the state with zero moments; removing needs compact.
        map.push(before.get(0));
        let g2 = MapGrads::zeros(2);
        adam.update(&mut map, &g2);
        assert_eq!(adam.len(), 2);
        adam.compact(&map.remove_where(&[true, false]));
        assert_eq!(adam.len(), 1);
    }
}
