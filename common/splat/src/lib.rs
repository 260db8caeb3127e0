//! 3D Gaussian map and the GS Voting rasterizer (docs/METHOD.md §1–3).
//!
//! Forward pass split as gsplat does: [`project`] (EWA) → [`bin_and_sort`] (16×16 tiles,
//! per-tile depth order) → [`rasterize`] (colour, depth, silhouette and, on request, voted
//! labels, per-pixel top-K and per-label visible counts, in one pass). [`render`] runs all three.
//!
//! Mapping (docs/METHOD.md §8, CPU): [`train_step`] = colour + depth render → [`Loss`] (L1 + SSIM +
//! depth L1) → [`Backward`] (rasterizer, then projection chain) → [`Adam`]; [`prune`].

mod adam;
pub mod args;
mod backward;
pub mod bench;
mod bin;
mod blend;
mod camera;
pub mod cpu;
mod fused_loss;
#[cfg(test)]
mod grad_tests;
mod grads;
mod keep_heaviest;
mod loss;
#[cfg(test)]
mod loss_tests;
mod map;
mod output;
mod ply;
mod png_out;
mod project;
mod project_backward;
mod prune;
mod raster_backward;
mod rasterize;
#[cfg(test)]
mod reference;
mod render;
mod row_log;
mod row_votes;
pub mod scene;
mod ssim;
mod target;
#[cfg(test)]
mod tests;
mod tiles;
mod top_k;
mod train;
mod train_bench;
mod voting;

pub use adam::{Adam, AdamConfig};
pub use backward::Backward;
pub use bin::{bin_and_sort, TileBins};
pub use blend::{alpha_of, exp_approx, gaussian_power, MAX_ALPHA, MIN_ALPHA, MIN_TRANSMITTANCE};
pub use camera::{Camera, DEFAULT_NEAR};
pub use grads::MapGrads;
pub use loss::{Loss, LossValue, LossWeights};
pub use map::{
    color_to_sh_dc, covariance3d, logit, normalize_quat, quat_to_matrix, sh_dc_to_color, sigmoid,
    Gaussian, GaussianMap, SH_C0,
};
pub use output::{RenderOutput, RenderRequest, DEFAULT_TOP_K};
pub use ply::{
    read_ply, read_ply_counted, read_ply_file, read_ply_file_counted, write_ply, write_ply_file,
    PlyError, PlyMap,
};
pub use png_out::{label_color, write_render_pngs};
pub use project::{
    project, project_gaussian, project_into, radius_tile_rect, AlphaEllipse, Projected,
    ProjectedGaussian,
};
pub use project_backward::{project_backward, GaussianGrad};
pub use prune::{prune, prune_mask, PruneConfig};
pub use raster_backward::{GradientChunk, RasterBackward, ScreenGrad};
pub use rasterize::{rasterize, rasterize_into};
pub use render::{render, render_into, Rendered};
pub use ssim::{blur as ssim_blur, ssim_plane, SsimScratch, SSIM_C1, SSIM_C2};
pub use target::{downscale_camera2, TargetFrame};
pub use tiles::{TileGrid, TileRect, TILE_PIXELS, TILE_SIZE};
pub use top_k::{stored_weight, PixelEntries, RowSpan, TopK, TopKBand};
pub use train::{train_step, StageMs, StepStats, TrainConfig, TrainWorkspace};
pub use train_bench::{bench_train_steps, TrainBenchRow};
