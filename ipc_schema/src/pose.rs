use iceoryx2::prelude::ZeroCopySend;

use crate::{MessageKind, SchemaError, Stamp};

/// Outcome of tracking one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum PoseStatus {
    /// Registered and verified.
    Tracked = 0,
    /// Lost: too few depth samples; the pose is the last verified one.
    TooFewPoints = 1,
    /// Lost: registration failed or was not trusted; the pose is the last verified one.
    Lost = 2,
    /// Lost: no depth at all; the pose is the last verified one.
    NoDepth = 3,
    /// The first frame: pose set by convention (identity or ground truth).
    Initial = 4,
    /// Verified again after lost frames.
    Relocalised = 5,
}

impl PoseStatus {
    /// Whether the pose is trustworthy (set for the first frame, or verified).
    pub fn has_pose(self) -> bool {
        matches!(self, Self::Tracked | Self::Initial | Self::Relocalised)
    }

    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::Tracked,
            1 => Self::TooFewPoints,
            2 => Self::Lost,
            3 => Self::NoDepth,
            4 => Self::Initial,
            5 => Self::Relocalised,
            _ => return None,
        })
    }
}

/// Tracker output for every frame. No payload.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[type_name("opengs::PoseHeader")]
#[repr(C)]
pub struct PoseHeader {
    pub stamp: Stamp,
    /// Estimated camera-to-world `tx ty tz qx qy qz qw`.
    pub pose: [f64; 7],
    /// Ground truth when `has_gt != 0` (copied from the frame, for the recorder).
    pub gt_pose: [f64; 7],
    pub has_gt: u32,
    pub status: u32,
    pub is_keyframe: u32,
    pub iterations: u32,
    pub inliers: u32,
    pub overlap: f32,
}

impl PoseHeader {
    pub fn decode(&self, payload: &[u8]) -> Result<PoseStatus, SchemaError> {
        self.stamp.validate(MessageKind::Pose, payload.len())?;
        if self.stamp.payload_len != 0 {
            return Err(SchemaError::Invalid("pose messages carry no payload"));
        }
        if self.pose.iter().any(|v| !v.is_finite()) {
            return Err(SchemaError::NonFinite("pose"));
        }
        if self.has_gt != 0 && self.gt_pose.iter().any(|v| !v.is_finite()) {
            return Err(SchemaError::NonFinite("gt_pose"));
        }
        if !(0.0..=1.0).contains(&self.overlap) {
            return Err(SchemaError::Invalid("overlap outside [0, 1]"));
        }
        PoseStatus::from_u32(self.status).ok_or(SchemaError::Invalid("unknown pose status"))
    }
}
