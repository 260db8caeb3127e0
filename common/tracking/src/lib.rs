//! Frame-to-model tracking after GS-ICP SLAM (METHOD §7): G-ICP of each
//! frame's depth samples against a target model, a constant-velocity guess
//! when registration fails, and the keyframe rule.

mod config;
mod frame_tracker;
mod motion;

pub use config::TrackerConfig;
pub use frame_tracker::{
    FrameTracker, KeyframeKind, TrackOutcome, TrackStatus, WorldKeyframeCloud,
};
pub use motion::ConstantVelocity;
