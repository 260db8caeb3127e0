//! The embedded synthetic dataset: a procedural room ray-cast on the fly,
//! the fixed room (scene 0) or one of the generated scene suite.

pub mod noise;
pub mod path;
pub mod raycast;
pub mod scene;
pub mod scene_suite;
pub mod shape;
pub mod texture;
pub mod timeline;

use std::path::{Path, PathBuf};

use opengs_geometry::{Intrinsics, Pose};

use crate::trajectory::{read_tum_trajectory, StampedPose};
use crate::{DatasetError, InstanceClass, RgbdFrame, RgbdSource};
use nalgebra::Vector3;
use noise::{quantize_depth, DepthNoise};
use path::{fit_start_pose, recentre, LoopPath};
use scene::{indoor_room, Scene};
use scene_suite::{room_around_trajectory, room_with_loop, LoopRoom};
use timeline::{ClockFrame, Gap};

/// Frames of the generated loop when no count is given (one 20 s loop).
pub const DEFAULT_LOOP_FRAMES: usize = 600;

#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticOptions {
    pub intrinsics: Intrinsics,
    pub frame_rate: f64,
    /// Frame count; `None` = one loop, or the whole trajectory file.
    pub frames: Option<usize>,
    pub seed: u64,
    /// Kinect-like depth corruption; `None` renders exact depth.
    pub noise: Option<DepthNoise>,
    /// Drive the camera along this TUM trajectory instead of the loop.
    pub trajectory: Option<PathBuf>,
    /// Depth units per metre of the produced frames.
    pub depth_scale: f32,
    /// Room of the scene suite: 0 is the fixed room, any other seed a room
    /// generated around the camera path (see [`scene_suite`]).
    pub scene: u64,
    /// Fraction of frames dropped at random (from `seed`), in [0, 1).
    pub drop_rate: f64,
    /// Random drops come in bursts of this many consecutive frames (≥ 1).
    pub drop_burst: usize,
    /// Keep every `speed`-th clock tick, so the camera moves `speed` times
    /// faster per frame (≥ 1).
    pub speed: usize,
    /// Skip the first seconds of the path; the room still fits all of it.
    pub start_s: f64,
}

impl Default for SyntheticOptions {
    fn default() -> Self {
        Self {
            intrinsics: Intrinsics::new(525.0, 525.0, 319.5, 239.5, 640, 480),
            frame_rate: 30.0,
            frames: None,
            seed: 0,
            noise: None,
            trajectory: None,
            depth_scale: 5000.0,
            scene: 0,
            drop_rate: 0.0,
            drop_burst: 1,
            speed: 1,
            start_s: 0.0,
        }
    }
}

impl SyntheticOptions {
    /// Checks every value; the errors name the option and its command-line flag.
    pub fn validate(&self) -> Result<(), DatasetError> {
        let positive = |x: f64| x.is_finite() && x > 0.0;
        let k = &self.intrinsics;
        if !positive(self.frame_rate)
            || !positive(self.depth_scale as f64)
            || !positive(k.fx)
            || !positive(k.fy)
            || k.width == 0
            || k.height == 0
        {
            return Err(DatasetError::Spec(
                "synthetic: frame rate, depth scale, focal lengths and image size must be positive"
                    .into(),
            ));
        }
        let bad = |what: String| Err(DatasetError::Spec(format!("synthetic: {what}")));
        if !(self.drop_rate.is_finite() && (0.0..1.0).contains(&self.drop_rate)) {
            return bad(format!(
                "drop rate (--drop-frames) must be in [0, 1), got {}",
                self.drop_rate
            ));
        }
        if self.drop_burst == 0 {
            return bad("drop burst (--drop-burst) must be at least 1 frame, got 0".into());
        }
        if self.speed == 0 {
            return bad("speed (--speed) must be at least 1, got 0".into());
        }
        if !(self.start_s.is_finite() && self.start_s >= 0.0) {
            return bad(format!(
                "start (--start) must be 0 or more seconds, got {}",
                self.start_s
            ));
        }
        Ok(())
    }
}

/// Generates frames of a synthetic room along a precomputed camera path.
pub struct SyntheticSource {
    options: SyntheticOptions,
    scene: Scene,
    poses: Vec<Pose>,
    timestamps: Vec<f64>,
    gaps: Vec<Gap>,
}

impl SyntheticSource {
    /// The room of `options.scene` (0: the fixed room) along the loop or the trajectory.
    pub fn new(options: SyntheticOptions) -> Result<Self, DatasetError> {
        options.validate()?;
        if options.scene == 0 {
            return Self::with_scene(options, indoor_room());
        }
        match options.trajectory.clone() {
            Some(file) => {
                let rows = read_rows(&file)?;
                let all: Vec<Pose> = rows.iter().map(|(_, p)| *p).collect();
                let fitted = room_around_trajectory(options.scene, &all);
                let shift = fitted.shift;
                let clock = timeline::sample_trajectory(&rows, options.frame_rate)
                    .into_iter()
                    .map(|mut f| {
                        f.pose.translation.vector += shift;
                        f
                    })
                    .collect();
                Self::along_trajectory(options, fitted.scene, clock, &file, &rows)
            }
            None => {
                let LoopRoom { scene, path } = room_with_loop(options.scene);
                Self::along_loop(options, scene, &path)
            }
        }
    }

    /// The fixed-room placement over a caller-provided scene (tests, custom
    /// rooms): the default loop, or the trajectory re-centred into the room.
    pub fn with_scene(options: SyntheticOptions, scene: Scene) -> Result<Self, DatasetError> {
        options.validate()?;
        match options.trajectory.clone() {
            Some(file) => {
                let rows = read_rows(&file)?;
                let mut clock = timeline::sample_trajectory(&rows, options.frame_rate);
                let fitted_on = timeline::nearest_per_tick(&rows, options.frame_rate);
                // Keep the camera 0.3 m inside the walls wherever the path allows.
                let margin = Vector3::repeat(0.3);
                let (lo, hi) = (scene.room.min + margin, scene.room.max - margin);
                let start = fit_start_pose(&fitted_on, &lo, &hi);
                // Tick 0 always has the first row, so this is today's re-centring.
                let raw: Vec<Pose> = clock.iter().map(|f| f.pose).collect();
                for (f, pose) in clock.iter_mut().zip(recentre(&raw, &start)) {
                    f.pose = pose;
                }
                Self::along_trajectory(options, scene, clock, &file, &rows)
            }
            None => Self::along_loop(options, scene, &LoopPath::default()),
        }
    }

    /// Applies the window, speed, drops and frame cap to a sampled trajectory.
    fn along_trajectory(
        options: SyntheticOptions,
        scene: Scene,
        clock: Vec<ClockFrame>,
        file: &Path,
        rows: &[StampedPose],
    ) -> Result<Self, DatasetError> {
        let fps = options.frame_rate;
        let windowed = timeline::window(clock, options.start_s, fps);
        if windowed.is_empty() {
            let duration = match (rows.first(), rows.last()) {
                (Some(a), Some(b)) => b.0 - a.0,
                _ => 0.0,
            };
            return Err(DatasetError::invalid(
                file,
                format!(
                    "start {} s (--start) is past the end of the trajectory ({duration:.1} s)",
                    options.start_s
                ),
            ));
        }
        let first_tick = timeline::start_tick(options.start_s, fps);
        let fast = timeline::speed_up(windowed, first_tick, options.speed);
        Ok(Self::finish(options, scene, fast))
    }

    /// The loop sampled from `start_s` on, every `speed`-th tick, then drops
    /// and the frame cap.
    fn along_loop(
        options: SyntheticOptions,
        scene: Scene,
        path: &LoopPath,
    ) -> Result<Self, DatasetError> {
        let fps = options.frame_rate;
        let count = options.frames.unwrap_or(DEFAULT_LOOP_FRAMES);
        let first_tick = timeline::start_tick(options.start_s, fps);
        let speed = options.speed as u64;
        let times: Vec<f64> = (0..count as u64)
            .map(|j| (first_tick + j * speed) as f64 / fps)
            .collect();
        let clock = path
            .poses_at(&times, options.seed)
            .into_iter()
            .zip(0..)
            .map(|(pose, j)| ClockFrame {
                tick: first_tick + j,
                pose,
            })
            .collect();
        Ok(Self::finish(options, scene, clock))
    }

    fn finish(options: SyntheticOptions, scene: Scene, clock: Vec<ClockFrame>) -> Self {
        let mut frames =
            timeline::drop_bursts(clock, options.drop_rate, options.drop_burst, options.seed);
        if let Some(n) = options.frames {
            frames.truncate(n);
        }
        let fps = options.frame_rate;
        let gaps = timeline::gaps(&frames, fps);
        Self {
            poses: frames.iter().map(|f| f.pose).collect(),
            timestamps: frames.iter().map(|f| f.tick as f64 / fps).collect(),
            gaps,
            options,
            scene,
        }
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Ground-truth camera-to-world poses of all frames.
    pub fn poses(&self) -> &[Pose] {
        &self.poses
    }

    /// Clock time of every frame (seconds from the path's start): jumps
    /// where frames were dropped.
    pub fn timestamps(&self) -> &[f64] {
        &self.timestamps
    }

    /// Every run of dropped clock ticks (mocap gaps, random drops), in order.
    pub fn gaps(&self) -> &[Gap] {
        &self.gaps
    }

    /// Clock ticks between the first and last frame that have no frame.
    pub fn dropped_frames(&self) -> usize {
        self.gaps.iter().map(|g| g.dropped).sum()
    }

    pub fn options(&self) -> &SyntheticOptions {
        &self.options
    }
}

/// The trajectory's rows, refused when there are none.
fn read_rows(file: &Path) -> Result<Vec<StampedPose>, DatasetError> {
    let rows = read_tum_trajectory(file)?;
    if rows.is_empty() {
        return Err(DatasetError::invalid(file, "trajectory has no poses"));
    }
    Ok(rows)
}

impl RgbdSource for SyntheticSource {
    fn name(&self) -> String {
        let room = match self.options.scene {
            0 => "synthetic room".to_string(),
            seed => format!("synthetic scene {seed}"),
        };
        match &self.options.trajectory {
            Some(t) => format!("{room} along {}", t.display()),
            None => room,
        }
    }

    fn intrinsics(&self) -> Intrinsics {
        self.options.intrinsics
    }

    fn len(&self) -> usize {
        self.poses.len()
    }

    fn frame_rate(&self) -> f64 {
        self.options.frame_rate
    }

    fn frame(&mut self, index: usize) -> Result<RgbdFrame, DatasetError> {
        let pose = *self.poses.get(index).ok_or(DatasetError::OutOfRange {
            index,
            len: self.poses.len(),
        })?;
        let k = self.options.intrinsics;
        let view = raycast::render(&self.scene, &k, &pose);
        let scale = self.options.depth_scale;
        let depth = match &self.options.noise {
            Some(n) => n.apply(
                &view.depth,
                k.width as usize,
                scale,
                self.options.seed,
                index,
            ),
            None => quantize_depth(&view.depth, scale),
        };
        Ok(RgbdFrame {
            index,
            timestamp: self.timestamps[index],
            width: k.width,
            height: k.height,
            rgb: view.rgb,
            depth,
            depth_scale: scale,
            gt_pose: Some(pose),
            labels: Some(view.labels),
        })
    }

    fn class_table(&self) -> Vec<InstanceClass> {
        self.scene.classes.clone()
    }
}
