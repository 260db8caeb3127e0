//! Pruning (docs/METHOD.md §8): transparent Gaussians and Gaussians too large for the scene.

use crate::adam::Adam;
use crate::map::GaussianMap;

/// What pruning removes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PruneConfig {
    /// Opacity below this is removed (3DGS: 0.005).
    pub min_opacity: f32,
    /// Largest scale above `max_scale_fraction · scene_extent` is removed (3DGS: 0.1).
    pub max_scale_fraction: f32,
    /// Scene extent in metres (e.g. radius of the camera centres, or of the map).
    pub scene_extent: f32,
}

impl Default for PruneConfig {
    fn default() -> Self {
        Self {
            min_opacity: 0.005,
            max_scale_fraction: 0.1,
            scene_extent: 5.0,
        }
    }
}

/// True for every Gaussian that pruning would remove.
pub fn prune_mask(map: &GaussianMap, cfg: &PruneConfig) -> Vec<bool> {
    // Compare in log space: no exp per Gaussian.
    let max_log_scale = (cfg.max_scale_fraction * cfg.scene_extent).ln();
    let min_logit = crate::map::logit(cfg.min_opacity);
    map.opacity_logits
        .iter()
        .zip(&map.log_scales)
        .map(|(&o, s)| o < min_logit || s[0].max(s[1]).max(s[2]) > max_log_scale)
        .collect()
}

/// Removes what [`prune_mask`] flags from `map` and, if given, from the Adam state.
/// Returns the old→new index map (for any other per-Gaussian state the caller keeps).
pub fn prune(
    map: &mut GaussianMap,
    adam: Option<&mut Adam>,
    cfg: &PruneConfig,
) -> Vec<Option<u32>> {
    let mask = prune_mask(map, cfg);
    let old_to_new = map.remove_where(&mask);
    if let Some(a) = adam {
        a.compact(&old_to_new);
    }
    old_to_new
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adam::AdamConfig;
    use crate::map::Gaussian;

    #[test]
    fn prunes_transparent_and_huge_and_compacts_adam() {
        let mut map = GaussianMap::new();
        let g = |opacity: f32, scale: f32| {
            Gaussian::from_values(
                [0.0; 3],
                [1.0, 0.0, 0.0, 0.0],
                [scale; 3],
                opacity,
                [0.5; 3],
                1,
            )
        };
        map.push(g(0.5, 0.01));
        map.push(g(0.001, 0.01)); // transparent
        map.push(g(0.5, 1.0)); // > 0.1 · 5 m
        map.push(g(0.9, 0.02));
        let mut adam = Adam::new(AdamConfig::default(), map.len());
        let old_to_new = prune(&mut map, Some(&mut adam), &PruneConfig::default());
        assert_eq!(old_to_new, vec![Some(0), None, None, Some(1)]);
        assert_eq!(map.len(), 2);
        assert_eq!(adam.len(), 2);
    }
}
