use opengs_geometry::{Intrinsics, Pose};
use opengs_gicp::{register, sample_depth_grid, Cloud, GicpError, Registration, Target};

use crate::{ConstantVelocity, TrackerConfig};

/// How a frame was tracked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackStatus {
    /// The first frame: its pose is set by convention.
    Initial,
    Tracked,
    /// Registration failed for lack of points or correspondences: constant-velocity guess.
    TooFewPoints,
    /// Registration did not converge or was degenerate: constant-velocity guess.
    NotConverged,
    /// No valid depth at all: constant-velocity guess.
    NoDepth,
}

/// Why a frame is a keyframe.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KeyframeKind {
    /// Overlap with the target fell below the threshold: the target grows.
    Tracking,
    /// The periodic mapping keyframe.
    Mapping,
}

/// The result of tracking one frame.
#[derive(Debug, Clone)]
pub struct TrackOutcome {
    /// Camera-to-world.
    pub pose: Pose,
    pub status: TrackStatus,
    pub keyframe: Option<KeyframeKind>,
    pub iterations: usize,
    pub inliers: usize,
    pub overlap: f64,
    /// The frame's source cloud in the camera frame (points + covariances), when it had depth.
    pub source: Option<Cloud>,
    /// What went wrong, for failed frames.
    pub failure: Option<String>,
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

/// Tracks frames against a growing model of keyframe points (or the map's Gaussians).
pub struct FrameTracker {
    config: TrackerConfig,
    target: Option<Target>,
    motion: ConstantVelocity,
    first_pose: Pose,
    frames: u64,
    last_keyframe: u64,
}

impl FrameTracker {
    pub fn new(config: TrackerConfig) -> Self {
        Self {
            config,
            target: None,
            motion: ConstantVelocity::default(),
            first_pose: Pose::identity(),
            frames: 0,
            last_keyframe: 0,
        }
    }

    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// Pose given to the first frame (identity unless set, e.g. to ground truth).
    pub fn set_first_pose(&mut self, pose: Pose) {
        self.first_pose = pose;
    }

    pub fn target_size(&self) -> usize {
        self.target.as_ref().map_or(0, Target::len)
    }

    /// The current model (keyframe points, or the map's Gaussians).
    pub fn target(&self) -> Option<&Target> {
        self.target.as_ref()
    }

    /// Replaces the model by the map's trackable Gaussians.
    pub fn set_target(&mut self, target: Target) {
        self.target = Some(target);
    }

    fn source_cloud(
        &self,
        depth: &[u16],
        depth_scale: f64,
        k: &Intrinsics,
    ) -> Result<Cloud, GicpError> {
        let samples = sample_depth_grid(
            depth,
            depth_scale,
            k,
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

    /// Tracks one frame; never fails: problems are reported in the status.
    pub fn track(&mut self, depth: &[u16], depth_scale: f64, k: &Intrinsics) -> TrackOutcome {
        let index = self.frames;
        self.frames += 1;
        let source = self.source_cloud(depth, depth_scale, k);
        // Registration starts from the last pose; the constant-velocity prediction is the
        // fallback (it extrapolates trajectory jitter: starting from it drifted in tests).
        let guess = self.motion.last().unwrap_or(self.first_pose);
        let Some(target) = self.target.as_ref() else {
            // First frame (or still no depth): set the pose, start the model.
            let pose = self.first_pose;
            return match source {
                Ok(cloud) => {
                    self.target = Some(Target::new(cloud.transformed(&pose)));
                    self.motion.update(pose);
                    self.last_keyframe = index;
                    TrackOutcome {
                        pose,
                        status: TrackStatus::Initial,
                        keyframe: Some(KeyframeKind::Tracking),
                        iterations: 0,
                        inliers: 0,
                        overlap: 0.0,
                        source: Some(cloud),
                        failure: None,
                    }
                }
                Err(e) => self.failure(guess, &e, None),
            };
        };
        let cloud = match source {
            Ok(c) => c,
            Err(e) => {
                let coast = self.motion.predict().unwrap_or(guess);
                return self.failure(coast, &e, None);
            }
        };
        let result = match self.register_with_fallback(&cloud, target, &guess) {
            Ok(r) => r,
            Err(e) => {
                let coast = self.motion.predict().unwrap_or(guess);
                return self.failure(coast, &e, Some(cloud));
            }
        };
        let status = if result.converged {
            TrackStatus::Tracked
        } else {
            TrackStatus::NotConverged
        };
        // An unconverged result that still explains most points is better than a guess.
        let pose = if result.converged || result.fitness >= 0.5 {
            result.transform
        } else {
            guess
        };
        self.motion.update(pose);
        let keyframe = if result.overlap < self.config.keyframe_overlap {
            Some(KeyframeKind::Tracking)
        } else if index - self.last_keyframe >= self.config.keyframe_every {
            Some(KeyframeKind::Mapping)
        } else {
            None
        };
        if keyframe.is_some() {
            self.last_keyframe = index;
        }
        // Every keyframe extends the model (as the mapper's Gaussians would), so it keeps
        // covering the view; only a converged pose may add points: a bad one would poison it.
        if keyframe.is_some() && status == TrackStatus::Tracked {
            self.grow_target(&cloud, &pose);
        }
        TrackOutcome {
            pose,
            status,
            keyframe,
            iterations: result.iterations,
            inliers: result.inliers,
            overlap: result.overlap,
            source: Some(cloud),
            failure: (!result.converged)
                .then(|| format!("not converged after {} iterations", result.iterations)),
        }
    }

    /// Registers from the last pose; if that does not converge (fast motion),
    /// retries from the constant-velocity prediction and keeps the better.
    fn register_with_fallback(
        &self,
        cloud: &Cloud,
        target: &Target,
        guess: &Pose,
    ) -> Result<Registration, GicpError> {
        let first = register(cloud, target, guess, &self.config.registration);
        if matches!(&first, Ok(r) if r.converged) {
            return first;
        }
        let Some(predicted) = self.motion.predict() else {
            return first;
        };
        let second = register(cloud, target, &predicted, &self.config.registration);
        match (first, second) {
            (Ok(a), Ok(b)) => Ok(if b.converged || b.fitness > a.fitness {
                b
            } else {
                a
            }),
            (Ok(a), Err(_)) => Ok(a),
            (Err(_), second) => second,
        }
    }

    /// Adds the keyframe's points the model does not have yet (farther than the overlap distance).
    fn grow_target(&mut self, cloud: &Cloud, pose: &Pose) {
        let Some(target) = self.target.as_mut() else {
            return;
        };
        let world = cloud.transformed(pose);
        let th = self.config.registration.overlapped_th;
        let mut novel = Cloud::default();
        for (p, c) in world.points.iter().zip(&world.covariances) {
            if target.grid().nearest_within(p, th).is_none() {
                novel.points.push(*p);
                novel.covariances.push(*c);
            }
        }
        if !novel.points.is_empty() {
            target.add(&novel);
        }
    }

    fn failure(&mut self, guess: Pose, e: &GicpError, source: Option<Cloud>) -> TrackOutcome {
        let status = match e {
            GicpError::EmptyCloud { .. } => TrackStatus::NoDepth,
            GicpError::TooFewPoints { .. } | GicpError::TooFewCorrespondences { .. } => {
                TrackStatus::TooFewPoints
            }
            _ => TrackStatus::NotConverged,
        };
        self.motion.coast(guess);
        TrackOutcome {
            pose: guess,
            status,
            keyframe: None,
            iterations: 0,
            inliers: 0,
            overlap: 0.0,
            source,
            failure: Some(e.to_string()),
        }
    }
}
