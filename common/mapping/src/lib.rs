//! The Gaussian map as the mapper stage keeps it (METHOD §8): Gaussians
//! initialised from keyframe points where the map is empty, optimised
//! continuously against stored keyframes (newest first, then random), pruned,
//! and the trackable subset handed back to the tracker; and the mapper's side of the
//! semantic loop ([`SemanticLoop`], METHOD §3–§5): a GS Voting render with its G_topK for
//! each segmented keyframe, and the consensus result (relabels, labels for new Gaussians,
//! counter pruning) applied through it. [`Mapper`] holds both; the dependency runs one way
//! (`mapper` → `semantic`).

mod config;
mod densify;
mod keyframe;
mod mapper;
mod semantic;

pub use config::MapperConfig;
pub use densify::{gaussians_for_holes, gaussians_from_points, DensifyInput, HoleFilling};
pub use keyframe::StoredKeyframe;
pub use mapper::{Mapper, TrackableGaussians};
pub use semantic::{
    ConsensusApplied, ConsensusApplyError, ConsensusUpdate, KeyframeRender, LabelVisibility,
    PendingRenders, SemanticLoop, MAX_PENDING_RENDERS,
};
