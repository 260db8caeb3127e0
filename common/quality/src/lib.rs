//! Render quality of a finished map: PSNR / SSIM of renders against the input frames with
//! pixels of missing depth masked (METHOD §9), side-by-side PNGs, and offline refinement.
//!
//! After a run: [`evaluate_run_quality`] (map.ply + trajectory.txt + the run's dataset →
//! metrics.json and PNGs), or its parts [`evaluate_dataset_quality`] and
//! [`write_quality_metrics`]. `opengs refine` adds [`refine`].

mod colormap;
mod dataset_frames;
mod densify;
mod error;
mod evaluate;
mod frame_images;
mod frame_match;
mod image_pair;
mod metrics_json;
mod psnr;
mod refine;
mod report;
mod run_quality;
mod scene_extent;
mod side_by_side;
mod ssim;
#[cfg(test)]
mod tests;

pub use colormap::{depth_color, error_color};
pub use dataset_frames::{evaluate_dataset_quality, load_posed_frames};
pub use densify::{split_largest_gradients, GradientStats};
pub use error::QualityError;
pub use evaluate::{
    evaluate_render_quality, png_positions, QualityEvaluator, DEFAULT_NEAR, MAX_PNGS,
};
pub use frame_images::{check_frame, depth_metres, target_frame, valid_depth_mask};
pub use frame_match::{FrameMatcher, MATCH_TOLERANCE_S};
pub use metrics_json::{merge_metrics_json, write_quality_metrics, write_report_json};
pub use psnr::psnr_masked;
pub use refine::{refine, RefineConfig, RefineStats};
pub use report::{FrameQuality, QualityReport};
pub use run_quality::{evaluate_run_quality, read_map};
pub use scene_extent::scene_extent;
pub use side_by_side::write_side_by_side_png;
pub use ssim::ssim_masked;
