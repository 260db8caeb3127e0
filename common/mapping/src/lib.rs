//! The Gaussian map as the mapper stage keeps it (docs/METHOD.md §8): Gaussians
//! initialised from keyframe points where the map is empty, optimised
//! continuously against stored keyframes (newest first, then random), pruned,
//! and the trackable subset handed back to the tracker; and the mapper's side of the
//! semantic loop ([`SemanticLoop`], docs/METHOD.md §3–§5): a GS Voting render with its G_topK for
//! each segmented keyframe, and the consensus result (relabels, labels for new Gaussians,
//! counter pruning) applied through it. [`Mapper`] holds both; the dependency runs one way
//! (`mapper` → `semantic`).
//!
//! Training beyond the online loop: [`refine`] (more full-resolution steps with 3DGS
//! [splitting](split_largest_gradients) and pruning on a run's keyframes, `opengs refine`)
//! and the mapper's final optimisation at the end of the data ([`optimise_final`] on the
//! [`KeptKeyframes`], then [`fill_holes`]).

mod config;
mod densify;
mod final_optimisation;
mod fragment;
mod keyframe;
mod mapper;
mod pose_refinement;
mod refine;
mod scene_extent;
mod semantic;
mod splitting;
mod target_frame;

pub use config::MapperConfig;
pub use densify::{gaussians_for_holes, gaussians_from_points, DensifyInput, HoleFilling};
pub use final_optimisation::{fill_holes, final_step_count, optimise_final, KeptKeyframes};
pub use fragment::{
    lies_on_host, median_offset_from_host, FRAGMENT_MAX_OFFSET_M, FRAGMENT_NEIGHBOURS,
};
pub use keyframe::StoredKeyframe;
pub use mapper::{Mapper, TrackableGaussians};
pub use pose_refinement::{
    refine_pose, PoseRefinement, PoseRefinementConfig, PoseRefinementWorkspace,
};
pub use refine::{refine, PoseRoundStats, RefineConfig, RefineError, RefineStats, RefineStepMs};
pub use scene_extent::scene_extent;
pub use semantic::{
    ConsensusApplied, ConsensusApplyError, ConsensusUpdate, KeyframeRender, LabelVisibility,
    PendingRenders, SemanticLoop, MAX_PENDING_RENDERS,
};
pub use splitting::{split_largest_gradients, GradientStats};
pub use target_frame::target_frame;
