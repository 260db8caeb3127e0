use opengs_geometry::{Intrinsics, Pose};
use opengs_splat::{downscale_camera2, Camera, TargetFrame};

use crate::MapperConfig;

/// A keyframe the mapper optimises against: its camera and target images.
#[derive(Debug, Clone)]
pub struct StoredKeyframe {
    pub seq: u64,
    pub pose: Pose,
    pub camera: Camera,
    pub target: TargetFrame,
}

impl StoredKeyframe {
    /// From a keyframe's RGB8 and raw depth; at half resolution when the config asks.
    pub fn new(
        seq: u64,
        pose: Pose,
        k: Intrinsics,
        rgb: &[u8],
        depth: &[u16],
        depth_scale: f32,
        config: &MapperConfig,
    ) -> Self {
        let rgb3: Vec<[u8; 3]> = rgb.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let depth_m: Vec<f32> = depth.iter().map(|&d| d as f32 / depth_scale).collect();
        let target = TargetFrame::from_rgb8(k.width, k.height, &rgb3, &depth_m);
        let camera = Camera::from_pose(k, &pose, config.near);
        if config.half_resolution {
            Self {
                seq,
                pose,
                camera: downscale_camera2(&camera),
                target: target.downscale2(),
            }
        } else {
            Self {
                seq,
                pose,
                camera,
                target,
            }
        }
    }
}
