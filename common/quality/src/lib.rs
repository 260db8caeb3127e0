//! Scores of a finished run (docs/METHOD.md §9), each read from its run directory and merged into
//! its `metrics.json`: the trajectory's ATE ([`evaluate_run_trajectory`]); render quality, PSNR /
//! SSIM of renders against the input frames with pixels of missing depth masked, holes, and
//! side-by-side PNGs ([`evaluate_run_quality`], or its parts [`evaluate_dataset_quality`] and
//! [`write_quality_metrics`]); labels, mIoU / accuracy of label maps rendered at held-out
//! poses and of the segmenter's own maps ([`evaluate_run_semantics`]). Training (refinement,
//! splitting) lives in `opengs-mapping`.

mod colormap;
mod dataset_frames;
mod error;
mod evaluate;
mod frame_images;
mod frame_match;
mod image_pair;
mod metrics_json;
mod psnr;
mod report;
mod run_quality;
mod run_semantics;
mod run_trajectory;
mod side_by_side;
mod ssim;
#[cfg(test)]
mod tests;

pub use colormap::{depth_color, error_color};
pub use dataset_frames::{evaluate_dataset_quality, load_posed_frames};
pub use error::QualityError;
pub use evaluate::{evaluate_render_quality, png_positions, QualityEvaluator, MAX_PNGS};
pub use frame_images::{check_frame, valid_depth_mask};
pub use frame_match::{FrameMatcher, MATCH_TOLERANCE_S};
pub use metrics_json::{merge_metrics_json, write_quality_metrics, write_report_json};
pub use psnr::psnr_masked;
pub use report::{FrameQuality, QualityReport};
pub use run_quality::{evaluate_run_quality, read_map};
pub use run_semantics::{evaluate_run_semantics, SemanticReport};
pub use run_trajectory::{evaluate_run_trajectory, RunMetrics};
pub use side_by_side::write_side_by_side_png;
pub use ssim::ssim_masked;
