//! Render camera: intrinsics, world-to-camera transform and near plane, in f32.

use opengs_geometry::{Intrinsics, Pose};

/// Near plane (m) of mapping, evaluation and `opengs render` cameras (docs/METHOD.md §2).
pub const DEFAULT_NEAR: f32 = 0.05;

/// Everything the projection needs about a view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub intrinsics: Intrinsics,
    /// World-to-camera rotation, row-major.
    pub rotation: [[f32; 3]; 3],
    /// World-to-camera translation.
    pub translation: [f32; 3],
    /// Gaussians with camera depth ≤ near are culled.
    pub near: f32,
}

impl Camera {
    /// Builds a camera from a camera-to-world pose (TUM / Replica convention).
    pub fn from_pose(intrinsics: Intrinsics, camera_to_world: &Pose, near: f32) -> Self {
        Self::from_world_to_camera(intrinsics, &camera_to_world.inverse(), near)
    }

    /// Builds a camera from a world-to-camera transform.
    pub fn from_world_to_camera(intrinsics: Intrinsics, world_to_camera: &Pose, near: f32) -> Self {
        let r = world_to_camera.rotation.to_rotation_matrix();
        let t = world_to_camera.translation.vector;
        Self {
            intrinsics,
            rotation: std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)] as f32)),
            translation: [t.x as f32, t.y as f32, t.z as f32],
            near,
        }
    }

    pub fn width(&self) -> u32 {
        self.intrinsics.width
    }

    pub fn height(&self) -> u32 {
        self.intrinsics.height
    }

    /// Camera-frame coordinates of a world point.
    #[inline]
    pub fn to_camera(&self, p: [f32; 3]) -> [f32; 3] {
        let r = &self.rotation;
        std::array::from_fn(|i| {
            r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + self.translation[i]
        })
    }
}
