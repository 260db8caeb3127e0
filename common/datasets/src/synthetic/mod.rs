//! The embedded synthetic dataset: a procedural room ray-cast on the fly.

pub mod noise;
pub mod path;
pub mod raycast;
pub mod scene;
pub mod shape;
pub mod texture;

use std::path::PathBuf;

use opengs_geometry::{Intrinsics, Pose};

use crate::trajectory::read_tum_trajectory;
use crate::{DatasetError, InstanceClass, RgbdFrame, RgbdSource};
use nalgebra::Vector3;
use noise::{quantize_depth, DepthNoise};
use path::{fit_start_pose, recentre, resample, LoopPath};
use scene::{indoor_room, Scene};

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
        }
    }
}

/// Generates frames of the synthetic room along a precomputed camera path.
pub struct SyntheticSource {
    options: SyntheticOptions,
    scene: Scene,
    poses: Vec<Pose>,
}

impl SyntheticSource {
    pub fn new(options: SyntheticOptions) -> Result<Self, DatasetError> {
        Self::with_scene(options, indoor_room())
    }

    /// Same generator over a caller-provided scene (tests, custom rooms).
    pub fn with_scene(options: SyntheticOptions, scene: Scene) -> Result<Self, DatasetError> {
        let positive = |x: f64| x.is_finite() && x > 0.0;
        let k = &options.intrinsics;
        if !positive(options.frame_rate)
            || !positive(options.depth_scale as f64)
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
        let poses = match &options.trajectory {
            Some(file) => {
                let stamped = resample(&read_tum_trajectory(file)?, options.frame_rate);
                if stamped.is_empty() {
                    return Err(DatasetError::invalid(file, "trajectory has no poses"));
                }
                let raw: Vec<Pose> = stamped.iter().map(|(_, p)| *p).collect();
                // Keep the camera 0.3 m inside the walls wherever the path allows.
                let margin = Vector3::repeat(0.3);
                let (lo, hi) = (scene.room.min + margin, scene.room.max - margin);
                let mut poses = recentre(&raw, &fit_start_pose(&raw, &lo, &hi));
                if let Some(n) = options.frames {
                    poses.truncate(n);
                }
                poses
            }
            None => LoopPath::default().poses(
                options.frames.unwrap_or(DEFAULT_LOOP_FRAMES),
                options.frame_rate,
                options.seed,
            ),
        };
        Ok(Self {
            options,
            scene,
            poses,
        })
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Ground-truth camera-to-world poses of all frames.
    pub fn poses(&self) -> &[Pose] {
        &self.poses
    }

    pub fn options(&self) -> &SyntheticOptions {
        &self.options
    }
}

impl RgbdSource for SyntheticSource {
    fn name(&self) -> String {
        match &self.options.trajectory {
            Some(t) => format!("synthetic room along {}", t.display()),
            None => "synthetic room".to_string(),
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
            timestamp: index as f64 / self.options.frame_rate,
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
