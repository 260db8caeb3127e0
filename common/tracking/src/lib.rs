//! Frame-to-model tracking after GS-ICP SLAM (docs/METHOD.md §7), made to hold on
//! motion it was not tuned on: coarse-to-fine G-ICP of each frame's depth
//! samples from a constant-velocity prediction, every result verified, lost
//! frames reported as lost (no keyframe, no Gaussians), relocalisation from
//! several guesses and global registration until a result verifies again, the
//! keyframe rule, and a model built off the tracking path.

mod ambiguity;
mod attempt;
mod config;
mod depth_weight;
mod frame_tracker;
mod from_prior;
pub mod idle_time;
mod model;
mod motion;
mod relocalise;
mod relocalise_worker;
mod verify;
mod visibility;

pub use ambiguity::{restarts, surface_fitness, SettleConfig};
pub use config::TrackerConfig;
pub use depth_weight::depth_scale;
pub use frame_tracker::{
    DepthFrame, FrameTracker, KeyframeKind, StartedAgain, TrackOutcome, TrackStatus,
    WorldKeyframeCloud,
};
pub use model::{MapGaussians, ModelUpdate, TrackingModel};
pub use motion::ConstantVelocity;
pub use relocalise::{RelocaliseConfig, Relocaliser};
pub use verify::{verify, verify_visibility, MotionPrior, Rejection, VerifyConfig};
pub use visibility::{check_visibility, Visibility, VisibilityMargin};
