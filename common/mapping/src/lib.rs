//! The Gaussian map as the mapper stage keeps it (METHOD §8): Gaussians
//! initialised from keyframe points where the map is empty, optimised
//! continuously against stored keyframes (newest first, then random), pruned,
//! and the trackable subset handed back to the tracker.

mod config;
mod densify;
mod keyframe;
mod mapper;
mod pixel_top_k;
mod semantic;

pub use config::MapperConfig;
pub use densify::{gaussians_for_holes, gaussians_from_points, DensifyInput, HoleFilling};
pub use keyframe::StoredKeyframe;
pub use mapper::{Mapper, TrackableGaussians};
pub use pixel_top_k::PixelTopK;
pub use semantic::{
    ConsensusApplied, ConsensusApplyError, ConsensusUpdate, KeyframeRender, LabelVisibility,
    PendingRenders, MAX_PENDING_RENDERS,
};
