use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use opengs_splat::{
    prune, train_step, Adam, AdamConfig, Camera, GaussianMap, StepStats, TrainConfig,
    TrainWorkspace,
};

use crate::densify::{gaussians_for_holes, gaussians_from_points, DensifyInput};
use crate::semantic::{
    ConsensusApplied, ConsensusApplyError, ConsensusUpdate, KeyframeRender, PendingRenders,
    SemanticLoop,
};
use crate::{MapperConfig, StoredKeyframe};

/// The trackable Gaussians (opacity above the threshold) in the tracker's terms.
#[derive(Debug, Clone, Default)]
pub struct TrackableGaussians {
    pub means: Vec<[f32; 3]>,
    /// Unit quaternions (w, x, y, z).
    pub rotations: Vec<[f32; 4]>,
    /// Scales in metres.
    pub scales: Vec<[f32; 3]>,
}

/// Owns the map, its optimiser state, the keyframes it optimises against and its side of the
/// semantic loop.
pub struct Mapper {
    config: MapperConfig,
    map: GaussianMap,
    adam: Adam,
    semantic: SemanticLoop,
    keyframes: Vec<StoredKeyframe>,
    workspace: TrainWorkspace,
    rng: ChaCha8Rng,
    iterations: u64,
    /// Keyframes added since the newest one was last optimised (newest first).
    fresh: Vec<usize>,
}

impl Mapper {
    pub fn new(config: MapperConfig) -> Self {
        Self::with_map(config, GaussianMap::new())
    }

    /// Resumes from a checkpointed map (a restarted mapper).
    pub fn with_map(config: MapperConfig, map: GaussianMap) -> Self {
        let adam = Adam::new(AdamConfig::gs_defaults(config.scene_extent), map.len());
        let rng = ChaCha8Rng::seed_from_u64(config.seed);
        Self {
            config,
            map,
            adam,
            semantic: SemanticLoop::default(),
            keyframes: Vec::new(),
            workspace: TrainWorkspace::new(),
            rng,
            iterations: 0,
            fresh: Vec::new(),
        }
    }

    pub fn config(&self) -> &MapperConfig {
        &self.config
    }

    pub fn map(&self) -> &GaussianMap {
        &self.map
    }

    /// The map, for work after mapping ends (the final optimisation keeps its own optimiser).
    pub fn into_map(self) -> GaussianMap {
        self.map
    }

    pub fn keyframes(&self) -> usize {
        self.keyframes.len()
    }

    pub fn iterations(&self) -> u64 {
        self.iterations
    }

    /// Adds a keyframe: new Gaussians at its points where no Gaussian is near (docs/METHOD.md §8),
    /// then at its depth samples the map still leaves open ([`crate::HoleFilling`]), and the
    /// frame as a training target. Returns how many Gaussians were added.
    pub fn add_keyframe(&mut self, input: &DensifyInput, keyframe: StoredKeyframe) -> usize {
        let near = gaussians_from_points(
            input,
            &self.map.means,
            self.config.overlap_distance,
            self.config.initial_opacity,
            self.config.initial_scale,
        );
        for g in &near {
            self.map.push(*g);
        }
        let holes = self.fill_holes(input, &keyframe.camera);
        self.adam.resize(self.map.len());
        self.keyframes.push(keyframe);
        self.fresh.push(self.keyframes.len() - 1);
        near.len() + holes
    }

    /// A keyframe of a resumed map (a restarted mapper's journal): a training target again;
    /// its Gaussians are in the map already, so nothing is added.
    pub fn restore_keyframe(&mut self, keyframe: StoredKeyframe) {
        self.keyframes.push(keyframe);
    }

    /// Gaussians where the map rendered at `camera` (the keyframe's) leaves its depth open;
    /// returns how many were added. The caller resizes the optimiser state.
    fn fill_holes(&mut self, input: &DensifyInput, camera: &Camera) -> usize {
        let new = gaussians_for_holes(
            input,
            &self.map,
            camera,
            &self.config.holes,
            self.config.initial_opacity,
            self.config.initial_scale,
        );
        for g in &new {
            self.map.push(*g);
        }
        new.len()
    }

    /// One optimisation iteration: the newest unoptimised keyframe first, else a random one.
    pub fn step(&mut self) -> Option<StepStats> {
        if self.keyframes.is_empty() || self.map.is_empty() {
            return None;
        }
        let index = match self.fresh.pop() {
            Some(i) => i,
            None => self.rng.gen_range(0..self.keyframes.len()),
        };
        let kf = &self.keyframes[index];
        let config = TrainConfig {
            loss: self.config.loss,
        };
        let stats = train_step(
            &mut self.map,
            &mut self.adam,
            &kf.camera,
            &kf.target,
            &config,
            &mut self.workspace,
        );
        self.iterations += 1;
        if self.iterations.is_multiple_of(self.config.prune_every) {
            let old_to_new = prune(&mut self.map, Some(&mut self.adam), &self.config.prune);
            self.semantic.remap(&old_to_new);
        }
        Some(stats)
    }

    /// Gaussians opaque enough to track against (docs/METHOD.md §7).
    pub fn trackable(&self) -> TrackableGaussians {
        let mut t = TrackableGaussians::default();
        for i in 0..self.map.len() {
            if self.map.opacity(i) > self.config.trackable_opacity {
                t.means.push(self.map.means[i]);
                t.rotations.push(self.map.rotations[i]);
                t.scales.push(self.map.scale(i));
            }
        }
        t
    }

    /// GS Voting render with top-K (K = `k`) and per-label visibility at `camera` (full
    /// resolution); kept for [`Mapper::apply_consensus`] of keyframe `seq`.
    pub fn render_for_consensus(&mut self, seq: u64, camera: &Camera, k: usize) -> &KeyframeRender {
        self.semantic
            .render_for_consensus(&self.map, seq, camera, k)
    }

    /// Renders waiting for their consensus.
    pub fn pending_renders(&self) -> &PendingRenders {
        self.semantic.pending()
    }

    /// Applies one keyframe's consensus through the top-K kept from its render. On error the
    /// map is unchanged.
    pub fn apply_consensus(
        &mut self,
        update: &ConsensusUpdate,
    ) -> Result<ConsensusApplied, ConsensusApplyError> {
        self.semantic
            .apply_consensus(&mut self.map, &mut self.adam, update)
    }
}
