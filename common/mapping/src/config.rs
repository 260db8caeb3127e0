use opengs_splat::{LossWeights, PruneConfig};

use crate::HoleFilling;

/// Mapper settings; defaults follow docs/METHOD.md §8 for TUM-size images.
#[derive(Debug, Clone, PartialEq)]
pub struct MapperConfig {
    /// A keyframe point becomes a Gaussian only if no Gaussian is within this distance (m).
    pub overlap_distance: f32,
    /// Opacity of new Gaussians. docs/METHOD.md §8 (after GS-ICP SLAM) says 0.1, a value made for
    /// thousands of GPU iterations; the CPU mapper gets about two iterations per keyframe,
    /// and a 0.1-opaque map renders translucent and dark until opacity is learned (synthetic
    /// room, 600 frames, 2 steps per keyframe: end-of-run PSNR 21.0 dB at 0.1, 23.4 at 0.9
    /// with `initial_scale` 0.7).
    pub initial_opacity: f32,
    /// Largest axis of a new Gaussian as a fraction of the local sample spacing (3DGS: 1).
    /// Below 1 the splats overlap less, so edges start sharper; with opaque splats the
    /// surface stays closed down to about 0.5.
    pub initial_scale: f32,
    /// Optimise at half resolution (keeps up on 2 cores).
    pub half_resolution: bool,
    /// Prune every this many iterations.
    pub prune_every: u64,
    pub prune: PruneConfig,
    pub loss: LossWeights,
    /// Where keyframe depth the map leaves open also becomes Gaussians.
    pub holes: HoleFilling,
    /// Gaussians above this opacity are given to the tracker (0.09 TUM, 0.05 Replica).
    pub trackable_opacity: f32,
    /// Extent (m) that scales the online position learning rate (3DGS: 1.6e-4 × extent).
    /// 0: online the means stay where the keyframes' depth put them (the final optimisation
    /// moves them). The tracker registers against these means; moved by the steps, they drag
    /// it, its next keyframes land where it went, and the error grows.
    /// Synthetic loop, 600 frames at 10 Hz, prior segmenter, ATE / PSNR / mIoU: 1 m 0.83 cm /
    /// 23.8 dB / 94.9; 0.5 m 0.52 / 24.6 / 95.5; 0.25 m 0.36 / 25.0 / 95.5; 0.1 m 0.20 / 25.2 /
    /// 95.1. Scene 3's fr2_desk teleport row (`opengs bench slam`, 600 final steps): 0.1 m
    /// drifted 0.5 → 5.8 cm over 25 s of newly mapped space, ATE 2.019 cm; 0 m 0.128 cm.
    pub scene_extent: f32,
    /// Near plane for rendering (m).
    pub near: f32,
    /// Seed of the random keyframe choice.
    pub seed: u64,
}

impl Default for MapperConfig {
    fn default() -> Self {
        Self {
            overlap_distance: 0.02,
            initial_opacity: 0.9,
            initial_scale: 0.7,
            half_resolution: true,
            prune_every: 300,
            prune: PruneConfig::default(),
            holes: HoleFilling::default(),
            loss: LossWeights::default(),
            trackable_opacity: 0.09,
            scene_extent: 0.0,
            near: opengs_splat::DEFAULT_NEAR,
            seed: 0,
        }
    }
}
