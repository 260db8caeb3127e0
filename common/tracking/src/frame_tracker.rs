//! The tracker's state machine.
//!
//! ```text
//!            verified                       a guess verifies
//!   ┌──────────────────┐          ┌───────────────────────────────┐
//!   ▼                  │          ▼                               │
//! TRACKING ── frame fails verification ──► LOST ── guesses fail ──┘ (frame lost)
//! ```
//!
//! Tracking: coarse-to-fine registration from the constant-velocity
//! prediction (then from the last verified pose), verified against fitness,
//! residual, conditioning and the motion prior. A frame that fails is lost:
//! it is reported with the last verified pose and status `Lost`, makes no
//! keyframe and adds nothing to the model. While lost, each frame tries a few
//! relocalisation guesses ([`crate::Relocaliser`]) until one verifies.

use opengs_geometry::{Intrinsics, Pose};
use opengs_gicp::{
    register_coarse_to_fine, sample_depth_grid, Cloud, Gaussian, GicpError, Registration,
};

use crate::model::{ModelBuilder, ModelUpdate, TrackingModel};
use crate::verify::{verify, MotionPrior, Rejection};
use crate::{ConstantVelocity, Relocaliser, TrackerConfig};

/// How a frame was tracked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackStatus {
    /// The first frame: its pose is set by convention.
    Initial,
    /// Registered and verified.
    Tracked,
    /// Registered from a relocalisation guess and verified, after lost frames.
    Relocalised,
    /// Registration failed or was not trusted: the pose is the last verified one.
    Lost,
    /// Fewer valid depth samples than needed (lost for want of data).
    TooFewPoints,
    /// No valid depth at all.
    NoDepth,
}

impl TrackStatus {
    /// Whether the frame's pose was verified (or set, for the first frame).
    pub fn has_pose(self) -> bool {
        matches!(self, Self::Initial | Self::Tracked | Self::Relocalised)
    }
}

/// Why a frame is a keyframe.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KeyframeKind {
    /// Overlap with the target fell below the threshold: the target grows.
    Tracking,
    /// The periodic mapping keyframe.
    Mapping,
}

/// One depth frame to track.
#[derive(Debug, Clone, Copy)]
pub struct DepthFrame<'a> {
    /// Row-major depth, `intrinsics.width × intrinsics.height`; 0 = missing.
    pub depth: &'a [u16],
    /// Depth units per metre.
    pub depth_scale: f64,
    pub intrinsics: &'a Intrinsics,
    /// Capture time (s): the motion model extrapolates over dropped frames with it.
    pub timestamp: f64,
}

/// The result of tracking one frame.
#[derive(Debug, Clone)]
pub struct TrackOutcome {
    /// Camera-to-world (for lost frames: the last verified pose).
    pub pose: Pose,
    pub status: TrackStatus,
    pub keyframe: Option<KeyframeKind>,
    /// Solver iterations of the registration that gave the pose (0 without one).
    pub iterations: usize,
    pub inliers: usize,
    pub fitness: f64,
    pub overlap: f64,
    /// The frame's source cloud in the camera frame (points + covariances), when it had depth.
    pub source: Option<Cloud>,
    /// What went wrong, for frames without a verified pose.
    pub failure: Option<String>,
    /// Models installed or refused since the previous frame.
    pub model_updates: Vec<ModelUpdate>,
}

/// A keyframe's source cloud in the world frame, as messages carry it.
#[derive(Debug, Clone, Default)]
pub struct WorldKeyframeCloud {
    pub points: Vec<[f32; 3]>,
    /// Upper triangles `xx xy xz yy yz zz`.
    pub covariances: Vec<[f32; 6]>,
}

impl TrackOutcome {
    /// The frame's source cloud moved into the world by its pose (what the mapper densifies from).
    pub fn world_cloud(&self) -> Option<WorldKeyframeCloud> {
        let world = self.source.as_ref()?.transformed(&self.pose);
        Some(WorldKeyframeCloud {
            points: world
                .points
                .iter()
                .map(|p| [p.x as f32, p.y as f32, p.z as f32])
                .collect(),
            covariances: world
                .covariances
                .iter()
                .map(|c| {
                    [
                        c[(0, 0)],
                        c[(0, 1)],
                        c[(0, 2)],
                        c[(1, 1)],
                        c[(1, 2)],
                        c[(2, 2)],
                    ]
                    .map(|v| v as f32)
                })
                .collect(),
        })
    }
}

/// A spell of lost frames.
#[derive(Debug, Clone)]
struct LostSpell {
    /// First lost frame.
    since: u64,
    relocaliser: Relocaliser,
}

/// Tracks frames against a model of the map (or of its own keyframes before there is one).
pub struct FrameTracker {
    config: TrackerConfig,
    builder: ModelBuilder,
    model: Option<TrackingModel>,
    motion: ConstantVelocity,
    first_pose: Pose,
    frames: u64,
    last_keyframe: Option<u64>,
    keyframe_poses: Vec<Pose>,
    lost: Option<LostSpell>,
}

/// A registration that passed (or failed) verification.
type Verified = Result<Registration, String>;

impl FrameTracker {
    /// A tracker that builds its models inline (deterministic; tests and offline tools).
    pub fn new(config: TrackerConfig) -> Self {
        let builder = ModelBuilder::inline(config.coarse_to_fine.coarse_voxel);
        Self::with_builder(config, builder)
    }

    /// A tracker whose models are built on a thread of their own, so that a new map
    /// never stalls tracking (the pipeline's tracker stage).
    pub fn with_background_model(config: TrackerConfig) -> std::io::Result<Self> {
        let builder = ModelBuilder::background(config.coarse_to_fine.coarse_voxel)?;
        Ok(Self::with_builder(config, builder))
    }

    fn with_builder(config: TrackerConfig, builder: ModelBuilder) -> Self {
        Self {
            config,
            builder,
            model: None,
            motion: ConstantVelocity::default(),
            first_pose: Pose::identity(),
            frames: 0,
            last_keyframe: None,
            keyframe_poses: Vec::new(),
            lost: None,
        }
    }

    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// Pose given to the first frame (identity unless set, e.g. to ground truth).
    pub fn set_first_pose(&mut self, pose: Pose) {
        self.first_pose = pose;
    }

    /// Points in the model in use (0 before the first).
    pub fn model_size(&self) -> usize {
        self.model.as_ref().map_or(0, TrackingModel::len)
    }

    /// The model in use.
    pub fn model(&self) -> Option<&TrackingModel> {
        self.model.as_ref()
    }

    /// Whether the last frame was lost.
    pub fn is_lost(&self) -> bool {
        self.lost.is_some()
    }

    /// The map's trackable Gaussians as of keyframe `seq` (METHOD §7); the model that
    /// includes them is used from the frame after it is built.
    pub fn set_map(&mut self, seq: u64, gaussians: Vec<Gaussian>) {
        let regularization = self.config.regularization;
        self.builder.set_map(seq, gaussians, regularization);
    }

    fn source_cloud(&self, frame: &DepthFrame) -> Result<Cloud, GicpError> {
        let samples = sample_depth_grid(
            frame.depth,
            frame.depth_scale,
            frame.intrinsics,
            self.config.stride,
            self.config.max_depth,
        )?;
        if samples.points.is_empty() {
            return Err(GicpError::EmptyCloud {
                what: "frame depth",
            });
        }
        if samples.points.len() < self.config.min_points {
            return Err(GicpError::TooFewPoints {
                what: "frame depth",
                found: samples.points.len(),
                needed: self.config.min_points,
            });
        }
        Cloud::from_depth_samples(&samples, self.config.neighbours, self.config.regularization)
    }

    /// Installs the newest finished model; reports what the builder did.
    fn install(&mut self, finished: Vec<Result<TrackingModel, String>>) -> Vec<ModelUpdate> {
        let mut updates = Vec::new();
        for result in finished {
            match result {
                Ok(model) => {
                    updates.push(ModelUpdate::Installed {
                        points: model.len(),
                        map_seq: model.map_seq(),
                        keyframes: model.keyframes(),
                    });
                    self.model = Some(model);
                }
                Err(why) => updates.push(ModelUpdate::Refused(why)),
            }
        }
        updates
    }

    /// Tracks one frame; never fails: problems are reported in the status.
    pub fn track(&mut self, frame: &DepthFrame) -> TrackOutcome {
        let finished = self.builder.finished();
        let mut updates = self.install(finished);
        let index = self.frames;
        self.frames += 1;
        let cloud = match self.source_cloud(frame) {
            Ok(c) => c,
            Err(e) => return self.without_depth(&e, updates),
        };
        if self.motion.last().is_none() {
            return self.start(index, frame.timestamp, cloud, updates);
        }
        if self.model.is_none() {
            // Only before the first model: the second frame cannot do without it.
            let first = self.builder.wait();
            updates.extend(self.install(first));
        }
        let mut out = match self.lost.is_some() {
            false => self.track_from_prior(index, frame.timestamp, cloud),
            true => self.relocalise(index, frame.timestamp, cloud),
        };
        out.model_updates = updates;
        out
    }

    /// The first frame with depth: its pose is set, its points start the model.
    fn start(
        &mut self,
        index: u64,
        timestamp: f64,
        cloud: Cloud,
        model_updates: Vec<ModelUpdate>,
    ) -> TrackOutcome {
        let pose = self.first_pose;
        self.motion.update(pose, timestamp);
        self.last_keyframe = Some(index);
        self.keyframe_poses.push(pose);
        self.builder.add_keyframe(index, cloud.transformed(&pose));
        TrackOutcome {
            pose,
            status: TrackStatus::Initial,
            keyframe: Some(KeyframeKind::Tracking),
            iterations: 0,
            inliers: 0,
            fitness: 0.0,
            overlap: 0.0,
            source: Some(cloud),
            failure: None,
            model_updates,
        }
    }

    /// Coarse-to-fine registration from `guess`, then verification.
    fn register_verified(
        &self,
        cloud: &Cloud,
        guess: &Pose,
        prior: Option<&MotionPrior>,
        relocalising: bool,
    ) -> Verified {
        let Some(model) = &self.model else {
            return Err("no model to register against yet".into());
        };
        let r = register_coarse_to_fine(
            cloud,
            model.target(),
            guess,
            &self.config.registration,
            &self.config.coarse_to_fine,
        )
        .map_err(|e| e.to_string())?;
        let checks = if relocalising {
            &self.config.relocalise.verify
        } else {
            &self.config.verify
        };
        verify(&r, prior, checks).map_err(|e: Rejection| e.to_string())?;
        Ok(r)
    }

    /// Tracking: from the prediction, then from the last verified pose.
    fn track_from_prior(&mut self, index: u64, timestamp: f64, cloud: Cloud) -> TrackOutcome {
        let Some((last, t_last)) = self.motion.last() else {
            return self.lose(cloud, "no verified pose yet".into());
        };
        let predicted = self.motion.predict(timestamp).unwrap_or(last);
        let prior = MotionPrior {
            predicted,
            seconds: timestamp - t_last,
        };
        let mut attempt = self.register_verified(&cloud, &predicted, Some(&prior), false);
        if attempt.is_err() && predicted != last {
            let from_last = self.register_verified(&cloud, &last, Some(&prior), false);
            if from_last.is_ok() {
                attempt = from_last;
            }
        }
        match attempt {
            Ok(r) => self.accept(index, timestamp, cloud, &r, TrackStatus::Tracked),
            Err(why) => {
                self.lost = Some(LostSpell {
                    since: index,
                    relocaliser: Relocaliser::start(
                        &last,
                        &self.keyframe_poses,
                        &self.config.relocalise,
                    ),
                });
                self.motion.stop();
                self.lose(cloud, format!("tracking lost: {why}"))
            }
        }
    }

    /// Lost: a few relocalisation guesses; the first that verifies ends the spell.
    fn relocalise(&mut self, index: u64, timestamp: f64, cloud: Cloud) -> TrackOutcome {
        let per_frame = self.config.relocalise.guesses_per_frame;
        let Some(spell) = self.lost.as_mut() else {
            return self.track_from_prior(index, timestamp, cloud);
        };
        let guesses = spell.relocaliser.next_guesses(per_frame);
        let since = spell.since;
        let mut last_failure = String::from("no relocalisation guesses");
        for guess in &guesses {
            match self.register_verified(&cloud, guess, None, true) {
                Ok(r) => {
                    self.lost = None;
                    return self.accept(index, timestamp, cloud, &r, TrackStatus::Relocalised);
                }
                Err(why) => last_failure = why,
            }
        }
        self.lose(
            cloud,
            format!(
                "lost since frame {since} ({} frames); relocalisation: {last_failure}",
                index - since + 1
            ),
        )
    }

    /// A verified pose: update the motion model; keyframe rule; new points to the model.
    fn accept(
        &mut self,
        index: u64,
        timestamp: f64,
        cloud: Cloud,
        r: &Registration,
        status: TrackStatus,
    ) -> TrackOutcome {
        let pose = r.transform;
        self.motion.update(pose, timestamp);
        let since_keyframe = self.last_keyframe.map_or(u64::MAX, |k| index - k);
        let keyframe = if r.overlap < self.config.keyframe_overlap {
            Some(KeyframeKind::Tracking)
        } else if since_keyframe >= self.config.keyframe_every {
            Some(KeyframeKind::Mapping)
        } else {
            None
        };
        if keyframe.is_some() {
            self.last_keyframe = Some(index);
            self.keyframe_poses.push(pose);
            let novel = self.novel_points(&cloud, &pose);
            if !novel.is_empty() {
                self.builder.add_keyframe(index, novel);
            }
        }
        TrackOutcome {
            pose,
            status,
            keyframe,
            iterations: r.iterations,
            inliers: r.inliers,
            fitness: r.fitness,
            overlap: r.overlap,
            source: Some(cloud),
            failure: None,
            model_updates: Vec::new(),
        }
    }

    /// The keyframe's points (world frame) the model does not have yet (farther than the
    /// overlap distance), so the model keeps covering the view until the map has them.
    fn novel_points(&self, cloud: &Cloud, pose: &Pose) -> Cloud {
        let world = cloud.transformed(pose);
        let Some(model) = &self.model else {
            return world;
        };
        let th = self.config.registration.overlapped_th;
        let grid = model.target().fine().grid();
        let mut novel = Cloud::default();
        for (p, c) in world.points.iter().zip(&world.covariances) {
            if grid.nearest_within(p, th).is_none() {
                novel.points.push(*p);
                novel.covariances.push(*c);
            }
        }
        novel
    }

    /// A lost frame: the last verified pose, no keyframe.
    fn lose(&mut self, cloud: Cloud, why: String) -> TrackOutcome {
        TrackOutcome {
            pose: self.motion.last().map_or(self.first_pose, |(p, _)| p),
            status: TrackStatus::Lost,
            keyframe: None,
            iterations: 0,
            inliers: 0,
            fitness: 0.0,
            overlap: 0.0,
            source: Some(cloud),
            failure: Some(why),
            model_updates: Vec::new(),
        }
    }

    /// A frame without usable depth: lost for want of data; the state is kept, so the
    /// next frame with depth is tracked from the motion prior as after a dropped frame.
    fn without_depth(&mut self, e: &GicpError, model_updates: Vec<ModelUpdate>) -> TrackOutcome {
        let status = match e {
            GicpError::EmptyCloud { .. } => TrackStatus::NoDepth,
            GicpError::TooFewPoints { .. } => TrackStatus::TooFewPoints,
            _ => TrackStatus::NoDepth,
        };
        TrackOutcome {
            pose: self.motion.last().map_or(self.first_pose, |(p, _)| p),
            status,
            keyframe: None,
            iterations: 0,
            inliers: 0,
            fitness: 0.0,
            overlap: 0.0,
            source: None,
            failure: Some(e.to_string()),
            model_updates,
        }
    }
}
