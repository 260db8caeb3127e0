//! The tracker's state machine.
//!
//! ```text
//!            verified                       a guess verifies
//!   ┌──────────────────┐          ┌───────────────────────────────┐
//!   ▼                  │          ▼                               │
//! TRACKING ── frame fails verification ──► LOST ── guesses fail ──┘ (frame lost)
//! ```
//!
//! Tracking: the fine registration from the constant-velocity prediction (when it
//! slides more than 2.5 cm from it, again after turning the prediction about the camera
//! centre); when one verifies but slid from a prediction with a velocity, fine restarts
//! around it decide; after a gap of a quarter second (or when both fail, or slid from a
//! prediction without a velocity), coarse-to-fine registration from the prediction and
//! from the last verified pose, the best polished by the same restarts. Every result is verified against fitness, residual,
//! conditioning, the motion prior and what the frame sees of the model
//! (nothing in front of the measured depth). A frame that fails is lost: it
//! is reported with the last verified pose and status `Lost`, makes no
//! keyframe and adds nothing to the model. While lost, a relocalisation guess
//! ([`crate::Relocaliser`]; from the spell's second attempt on, global registration's
//! hypotheses too) is tried every 0.15 s until one verifies: in the pipeline on
//! a thread of its own ([`crate::relocalise_worker`]), so a lost frame costs what a
//! tracked one does, and there a found pose is tracked on over the lost frames for
//! 1.5 s, no keyframe taken, before it ends the spell. Until ten frames after the start are verified, the start does not
//! stand: a frame that fails starts tracking again at itself instead of being lost
//! ([`TrackOutcome::started_again`]), and the frames since the start given up have no pose.

use std::sync::Arc;

use opengs_geometry::nalgebra::{Matrix3, Point3};
use opengs_geometry::{Intrinsics, Pose};
use opengs_gicp::{
    estimate_covariances_on_grid, regularize, sample_depth_grid, Cloud, GicpError, NeighbourGrid,
    Registration, Regularization,
};

use crate::attempt::try_guesses;
use crate::from_prior;
use crate::model::{MapGaussians, ModelBuilder, ModelUpdate, TrackingModel};
use crate::relocalise_worker::{GuessJob, LostFrame, RelocaliseWorker};
use crate::{depth_scale, ConstantVelocity, Relocaliser, TrackerConfig};

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
    /// The source points' neighbourhood covariances before regularisation (camera frame;
    /// empty without depth) and the shape a keyframe gives them for the mapper
    /// ([`TrackerConfig::keyframe_shape`]): regularised only when a keyframe is sent.
    pub raw_covariances: Vec<Matrix3<f64>>,
    pub keyframe_shape: Regularization,
    /// What went wrong, for frames without a verified pose.
    pub failure: Option<String>,
    /// Models installed or refused since the previous frame.
    pub model_updates: Vec<ModelUpdate>,
    /// Why the fine registration from the prediction was not enough (a gap, a failed
    /// check, a slide away from the prediction): the wide search ran (after a verified
    /// slide, only its polishing restarts).
    pub wide_search: Option<String>,
    /// Tracking started again at this frame (status `Initial`): the start it replaces.
    pub started_again: Option<StartedAgain>,
    /// How a relocalised frame's pose was found (status `Relocalised`), for the log.
    pub relocalised: Option<String>,
}

/// A start given up for a new one ([`FrameTracker`] starts again): the frames from
/// `given_up` on have no pose any more, and their keyframes belong to no map.
#[derive(Debug, Clone, PartialEq)]
pub struct StartedAgain {
    /// The frame (the tracker's count) of the start given up.
    pub given_up: u64,
    /// Why this frame could not be tracked against it.
    pub why: String,
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
        let source = self.source.as_ref()?;
        let pose = &self.pose;
        let r = pose.rotation.to_rotation_matrix().into_inner();
        let shaped: Vec<Matrix3<f64>> = if self.raw_covariances.len() == source.points.len() {
            self.raw_covariances
                .iter()
                .map(|c| regularize(c, self.keyframe_shape))
                .collect()
        } else {
            source.covariances.clone()
        };
        Some(WorldKeyframeCloud {
            points: source
                .points
                .iter()
                .map(|p| pose * p)
                .map(|p| [p.x as f32, p.y as f32, p.z as f32])
                .collect(),
            covariances: shaped
                .iter()
                .map(|c| r * c * r.transpose())
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
    /// Which spell (answers of the relocalisation thread name it).
    id: u64,
    /// First lost frame (the tracker's count of frames).
    since: u64,
    relocaliser: Relocaliser,
    /// Time of the last relocalisation attempt (s).
    last_attempt: f64,
    /// Why the last attempt failed.
    last_failure: Option<String>,
    /// Relocalisation attempts so far.
    attempts: u32,
}

/// Tracks frames against a model of the map (or of its own keyframes before there is one).
pub struct FrameTracker {
    config: TrackerConfig,
    builder: ModelBuilder,
    /// Shared with the relocalisation thread's job, if one is out.
    model: Option<Arc<TrackingModel>>,
    /// Relocalisation off the tracking path (`None`: guesses are tried inline).
    worker: Option<RelocaliseWorker>,
    /// Lost spells so far (the next spell's id).
    spells: u64,
    motion: ConstantVelocity,
    first_pose: Pose,
    frames: u64,
    last_keyframe: Option<u64>,
    /// The newest keyframe whose points went to the builder.
    pending: Option<PendingKeyframe>,
    keyframe_poses: Vec<Pose>,
    lost: Option<LostSpell>,
    /// Time of the previous frame (s).
    last_timestamp: f64,
    /// A restarted tracker's last published pose and its time, for its first frame.
    resume: Option<(Pose, f64)>,
    /// Whether a map was handed over (a model is coming from the builder).
    map_given: bool,
    /// The frame that started the model in use (none before the first frame with depth) and
    /// the frames verified since.
    start: Option<(u64, u64)>,
    /// Whether the start stands: `start_stands_after` frames after it were verified (or it
    /// was kept, or the tracker went on from a predecessor). Until then a lost frame starts
    /// again.
    start_stands: bool,
}

/// A keyframe's novel points (world frame) sent to the model builder, searchable until a
/// model that holds them is installed.
struct PendingKeyframe {
    seq: u64,
    grid: NeighbourGrid,
}

/// Share of `world` points within `max_sq_dist` of the model's points or of a keyframe's
/// still on their way to it. Until its build is installed, the model alone leaves a newly
/// seen area uncovered on frame after frame, each of which would be a tracking keyframe:
/// with the builder on idle CPU time, the edge deploy's pinned tracker took 94 keyframes
/// instead of 66 on scene 1's noisy loop.
fn overlap_with_pending(
    world: &[Point3<f64>],
    model: Option<&NeighbourGrid>,
    pending: &NeighbourGrid,
    max_sq_dist: f64,
) -> f64 {
    let near = |g: &NeighbourGrid, p: &Point3<f64>| g.nearest_within(p, max_sq_dist).is_some();
    let covered = world
        .iter()
        .filter(|p| model.is_some_and(|m| near(m, p)) || near(pending, p))
        .count();
    covered as f64 / world.len().max(1) as f64
}

impl FrameTracker {
    /// A tracker that builds its models inline (deterministic; tests and offline tools).
    pub fn new(config: TrackerConfig) -> Self {
        let builder = ModelBuilder::inline(config.coarse_to_fine.coarse_voxel);
        Self::with_builder(config, builder)
    }

    /// A tracker that builds its models and tries relocalisation guesses on threads of
    /// their own, so that neither a new map nor a lost camera stalls tracking (the
    /// pipeline's tracker stage).
    pub fn threaded(config: TrackerConfig) -> std::io::Result<Self> {
        let builder = ModelBuilder::background(config.coarse_to_fine.coarse_voxel)?;
        let worker = RelocaliseWorker::spawn(config.clone())?;
        Ok(Self {
            worker: Some(worker),
            ..Self::with_builder(config, builder)
        })
    }

    fn with_builder(config: TrackerConfig, builder: ModelBuilder) -> Self {
        Self {
            config,
            builder,
            model: None,
            worker: None,
            spells: 0,
            motion: ConstantVelocity::default(),
            first_pose: Pose::identity(),
            frames: 0,
            last_keyframe: None,
            pending: None,
            keyframe_poses: Vec::new(),
            lost: None,
            last_timestamp: f64::NAN,
            resume: None,
            map_given: false,
            start: None,
            start_stands: false,
        }
    }

    /// A restarted tracker goes on from its predecessor's last published `pose` at
    /// `timestamp` (s), never from the identity: its first frame is registered against the
    /// map (given with [`Self::set_map`] before it) from there, with the wide search the gap
    /// calls for; if that fails, relocalisation tries the earlier `keyframe_poses`. Without a
    /// map, the first frame starts a new model at that pose.
    pub fn resume_from(&mut self, pose: Pose, timestamp: f64, keyframe_poses: Vec<Pose>) {
        self.resume = Some((pose, timestamp));
        self.keyframe_poses = keyframe_poses;
        // The predecessor's map holds its keyframes: there is no start to give up.
        self.start_stands = true;
    }

    /// Whether the start stands (see [`Self::keep_start`]): a lost frame now begins a lost
    /// spell, not a new start.
    pub fn start_stands(&self) -> bool {
        self.start_stands
    }

    /// Keeps the start whatever comes: from now on a lost frame begins a lost spell. Until
    /// [`TrackerConfig::start_stands_after`] frames after the start are verified, a lost
    /// frame starts tracking again at itself (its outcome's [`TrackOutcome::started_again`]):
    /// whoever holds the keyframes since the start back calls this when it lets them go.
    pub fn keep_start(&mut self) {
        self.start_stands = true;
    }

    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// Pose given to the first frame, and to a frame that starts again (identity unless
    /// set, e.g. to ground truth).
    pub fn set_first_pose(&mut self, pose: Pose) {
        self.first_pose = pose;
    }

    /// Points in the model in use (0 before the first).
    pub fn model_size(&self) -> usize {
        self.model.as_deref().map_or(0, TrackingModel::len)
    }

    /// The model in use.
    pub fn model(&self) -> Option<&TrackingModel> {
        self.model.as_deref()
    }

    /// Whether the last frame was lost.
    pub fn is_lost(&self) -> bool {
        self.lost.is_some()
    }

    /// The map's trackable Gaussians as of keyframe `seq` (docs/METHOD.md §7); the model that
    /// includes them is used from the frame after it is built.
    pub fn set_map(&mut self, seq: u64, gaussians: MapGaussians) {
        if self.start.is_some_and(|(start, _)| seq < start) {
            // A map as of a keyframe before the start in use: of a start given up.
            return;
        }
        let regularization = self.config.regularization;
        self.map_given = true;
        self.builder.set_map(seq, gaussians, regularization);
    }

    /// The frame's samples with covariances regularised for registration, and the raw
    /// covariances a keyframe reshapes (one neighbour search for both).
    pub fn source_cloud(
        &self,
        frame: &DepthFrame,
    ) -> Result<(Cloud, Vec<Matrix3<f64>>), GicpError> {
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
        let raw =
            estimate_covariances_on_grid(&samples, self.config.neighbours, Regularization::None)?;
        let (from, until) = (
            self.config.depth_weight_from,
            self.config.depth_weight_until,
        );
        let covariances = raw
            .iter()
            .zip(&samples.points)
            .map(|(c, p)| regularize(c, self.config.regularization) * depth_scale(p.z, from, until))
            .collect();
        Ok((
            Cloud {
                points: samples.points,
                covariances,
            },
            raw,
        ))
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
                    self.model = Some(Arc::new(model));
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
        let (cloud, raw) = match self.source_cloud(frame) {
            Ok(c) => c,
            Err(e) => return self.without_depth(&e, updates),
        };
        if let Some((pose, timestamp)) = self.resume.take() {
            if self.model.is_none() && self.map_given {
                let first = self.builder.wait();
                updates.extend(self.install(first));
            }
            if self.model.is_some() {
                self.motion.update(pose, timestamp);
                self.last_timestamp = timestamp;
                self.keyframe_poses.push(pose);
            } else {
                self.first_pose = pose;
            }
        }
        if self.motion.last().is_none() {
            self.last_timestamp = frame.timestamp;
            let mut out = self.start(index, frame.timestamp, cloud, updates);
            out.raw_covariances = raw;
            return out;
        }
        if self.model.is_none() {
            // Only before the first model: the second frame cannot do without it.
            let first = self.builder.wait();
            updates.extend(self.install(first));
        }
        let gap = self.after_gap(frame.timestamp);
        let mut out = match self.lost.is_some() {
            false => self.track_from_prior(frame, index, cloud, gap),
            true => self.relocalise(frame, index, cloud),
        };
        out.model_updates = updates;
        out.raw_covariances = raw;
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
        self.start = Some((index, 0));
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
            wide_search: None,
            raw_covariances: Vec::new(),
            keyframe_shape: self.config.keyframe_shape,
            started_again: None,
            relocalised: None,
        }
    }

    /// Whether the time since the previous frame is a gap worth the wide search.
    fn after_gap(&mut self, timestamp: f64) -> bool {
        let interval = timestamp - self.last_timestamp;
        self.last_timestamp = timestamp;
        !(interval.is_finite() && interval <= self.config.wide_search_after_s)
    }

    /// Tracking ([`from_prior::register`]): a verified registration is accepted; a frame
    /// that fails starts again (before the start stands) or begins a lost spell.
    fn track_from_prior(
        &mut self,
        frame: &DepthFrame,
        index: u64,
        cloud: Cloud,
        gap: bool,
    ) -> TrackOutcome {
        let timestamp = frame.timestamp;
        let Some((last, _)) = self.motion.last() else {
            return self.lose(cloud, "no verified pose yet".into());
        };
        let (attempt, wide) = match self.model.as_deref() {
            Some(model) => {
                from_prior::register(model, &self.config, &self.motion, frame, &cloud, gap)
            }
            None => (Err("no model to register against yet".into()), None),
        };
        match attempt {
            Ok(r) => TrackOutcome {
                wide_search: wide,
                ..self.accept(index, timestamp, cloud, &r, TrackStatus::Tracked)
            },
            Err(why) if !self.start_stands => self.start_again(index, timestamp, cloud, why),
            Err(why) => {
                self.spells += 1;
                self.lost = Some(LostSpell {
                    id: self.spells,
                    since: index,
                    last_attempt: timestamp,
                    last_failure: None,
                    attempts: 0,
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

    /// Lost before the start stands: a moment's views are all the model holds, and a camera
    /// that moved on rarely comes back to them (fr2_desk with noise, scene 7: from 40 s, the
    /// frame after a 0.77 s gap fitted 0.64 of the first, under the 0.70 a pose after a gap
    /// needs, and relocalisation failed on 899 of 900 frames; from 31.2 s, five frames then
    /// the 12 s teleport, 237 of 240). So tracking starts again at this frame, as ORB-SLAM resets a
    /// map lost right after its initialisation; the outcome names the start given up.
    fn start_again(
        &mut self,
        index: u64,
        timestamp: f64,
        cloud: Cloud,
        why: String,
    ) -> TrackOutcome {
        let given_up = self.start.map_or(0, |(index, _)| index);
        self.builder.clear();
        self.model = None;
        self.pending = None;
        self.map_given = false;
        self.keyframe_poses.clear();
        self.motion = ConstantVelocity::default();
        let mut out = self.start(index, timestamp, cloud, Vec::new());
        out.started_again = Some(StartedAgain {
            given_up,
            why: format!("tracking lost: {why}"),
        });
        out
    }

    /// Lost: a few relocalisation guesses every `attempt_every_s`; the first that
    /// verifies ends the spell. Inline, the guesses are tried on this frame; with the
    /// relocalisation thread, on an earlier lost frame while this one is reported lost at
    /// once (and handed over, while a job is out, for the thread to track a found pose on),
    /// and an answer puts the camera where the last frame it was tracked on to was: this
    /// frame is tracked from there with the velocity it was tracked on with.
    fn relocalise(&mut self, frame: &DepthFrame, index: u64, cloud: Cloud) -> TrackOutcome {
        let timestamp = frame.timestamp;
        let Some(spell) = self.lost.as_mut() else {
            return self.track_from_prior(frame, index, cloud, true);
        };
        let id = spell.id;
        if let Some(answer) = self.worker.as_mut().and_then(|w| w.answer(id)) {
            match answer.result {
                Ok(found) => {
                    self.lost = None;
                    let answer_pose = found.registration.transform;
                    // Where the pose was tracked on to, and at what velocity.
                    self.motion = answer.motion;
                    let gap = timestamp - answer.timestamp > self.config.wide_search_after_s
                        || !self.motion.has_velocity();
                    let mut out = self.track_from_prior(frame, index, cloud, gap);
                    if out.status == TrackStatus::Tracked {
                        out.status = TrackStatus::Relocalised;
                        let moved = answer_pose.inverse() * out.pose;
                        out.relocalised = Some(format!(
                            "{}, the last {:.2} s before this frame, {:.1} cm and {:.1}° from it",
                            found.how,
                            timestamp - answer.timestamp,
                            moved.translation.vector.norm() * 100.0,
                            moved.rotation.angle().to_degrees()
                        ));
                    }
                    return out;
                }
                Err(why) => spell.last_failure = Some(why),
            }
        }
        let busy = self.worker.as_ref().is_some_and(RelocaliseWorker::is_busy);
        if let (true, Some(worker), Some(model)) = (busy, &self.worker, &self.model) {
            worker.offer(LostFrame::new(id, frame, &cloud, model));
        }
        let due = timestamp - spell.last_attempt >= self.config.relocalise.attempt_every_s;
        if due && !busy {
            if let Some(model) = self.model.clone() {
                spell.last_attempt = timestamp;
                let guesses = spell
                    .relocaliser
                    .next_guesses(self.config.relocalise.guesses_per_frame);
                // The spell's first guess (the last verified pose) is tried on the frame: most
                // spells are one frame after a gap that failed its checks, and end there
                // (fr2_desk rows: one lost frame, not two); the rest go to the thread.
                let first = spell.attempts == 0;
                spell.attempts += 1;
                let submitted = !first
                    && self.worker.as_mut().is_some_and(|w| {
                        w.submit(GuessJob {
                            frame: LostFrame::new(id, frame, &cloud, &model),
                            guesses: guesses.clone(),
                            viewpoints: spell.relocaliser.viewpoints().to_vec(),
                        })
                    });
                if !submitted {
                    // Global registration (a few hundred ms) never on the spell's first
                    // attempt, which most often ends the spell.
                    let viewpoints = (!first).then(|| spell.relocaliser.viewpoints());
                    match try_guesses(&model, &self.config, frame, &cloud, &guesses, viewpoints) {
                        Ok(found) => {
                            self.lost = None;
                            return TrackOutcome {
                                relocalised: Some(found.how),
                                ..self.accept(
                                    index,
                                    timestamp,
                                    cloud,
                                    &found.registration,
                                    TrackStatus::Relocalised,
                                )
                            };
                        }
                        Err(why) => spell.last_failure = Some(why),
                    }
                }
            }
        }
        let why = match &spell.last_failure {
            Some(f) => format!(
                "lost for {} frames; relocalisation: {f}",
                index - spell.since + 1
            ),
            None => format!("lost for {} frames", index - spell.since + 1),
        };
        self.lose(cloud, why)
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
        if let Some((_, verified)) = &mut self.start {
            *verified += 1;
            self.start_stands |= *verified >= self.config.start_stands_after;
        }
        let since_keyframe = self.last_keyframe.map_or(u64::MAX, |k| index - k);
        let th = self.config.registration.overlapped_th;
        let model = self.model.as_deref();
        if let Some(p) = &self.pending {
            if model.is_some_and(|m| m.holds_keyframe(p.seq)) {
                self.pending = None;
            }
        }
        let overlap = match &self.pending {
            Some(p) if r.overlap < self.config.keyframe_overlap => overlap_with_pending(
                &cloud.transformed(&pose).points,
                model.map(|m| m.target().fine().grid()),
                &p.grid,
                th,
            ),
            _ => r.overlap,
        };
        let keyframe = if overlap < self.config.keyframe_overlap {
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
                let grid = NeighbourGrid::new(&novel.points, th.sqrt());
                self.builder.add_keyframe(index, novel);
                // Only a builder on a thread of its own lags; inline, the next frame has it.
                self.pending = Some(PendingKeyframe { seq: index, grid });
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
            wide_search: None,
            raw_covariances: Vec::new(),
            keyframe_shape: self.config.keyframe_shape,
            started_again: None,
            relocalised: None,
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
            wide_search: None,
            raw_covariances: Vec::new(),
            keyframe_shape: self.config.keyframe_shape,
            started_again: None,
            relocalised: None,
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
            wide_search: None,
            raw_covariances: Vec::new(),
            keyframe_shape: self.config.keyframe_shape,
            started_again: None,
            relocalised: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_on_their_way_to_the_model_count_as_overlap() {
        // On the plane z = 2, every centimetre: the model's points at x in [-1, 0), the
        // pending keyframe's in [0, 0.5), the frame's 200 halfway between, over [-1, 1).
        let line = |x0: f64, n: usize| -> Vec<Point3<f64>> {
            (0..n)
                .map(|i| Point3::new(x0 + 0.01 * i as f64, 0.0, 2.0))
                .collect()
        };
        let frame = line(-0.995, 200);
        let r = 0.03;
        let model = NeighbourGrid::new(&line(-1.0, 100), r);
        let pending = NeighbourGrid::new(&line(0.0, 50), r);
        // Covered within 3 cm: the frame's points below x = 0.52, 152 of 200.
        let share = overlap_with_pending(&frame, Some(&model), &pending, r * r);
        assert!((share - 0.76).abs() < 1e-9, "{share}");
        // Before any model, the pending keyframe alone: -0.025 to 0.515, 55 points.
        let share = overlap_with_pending(&frame, None, &pending, r * r);
        assert!((share - 0.275).abs() < 1e-9, "{share}");
    }
}
