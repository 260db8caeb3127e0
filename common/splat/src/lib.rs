//! 3D Gaussian map and the GS Voting rasterizer (METHOD.md §1–3).
//!
//! Forward pass split as gsplat does: [`project`] (EWA) → [`bin_and_sort`] (16×16 tiles,
//! per-tile depth order) → [`rasterize`] (colour, depth, silhouette and, on request, voted
//! labels, per-pixel top-K and per-label visible counts, in one pass). [`render`] runs all three.

pub mod args;
pub mod bench;
mod bin;
mod blend;
mod camera;
mod map;
mod output;
mod ply;
mod png_out;
mod project;
mod rasterize;
#[cfg(test)]
mod reference;
mod render;
pub mod scene;
#[cfg(test)]
mod tests;
mod tiles;
mod topk;
mod voting;

pub use bin::{bin_and_sort, TileBins};
pub use blend::{alpha_of, exp_approx, gaussian_power, MAX_ALPHA, MIN_ALPHA, MIN_TRANSMITTANCE};
pub use camera::Camera;
pub use map::{
    color_to_sh_dc, covariance3d, logit, normalize_quat, quat_to_matrix, sh_dc_to_color, sigmoid,
    Gaussian, GaussianMap, SH_C0,
};
pub use output::{RenderOutput, RenderRequest, DEFAULT_TOP_K};
pub use ply::{read_ply, read_ply_file, write_ply, write_ply_file, PlyError};
pub use png_out::{label_color, write_render_pngs};
pub use project::{
    project, project_gaussian, project_into, radius_tile_rect, AlphaEllipse, Projected,
    ProjectedGaussian,
};
pub use rasterize::{rasterize, rasterize_into};
pub use render::{render, render_into, Rendered};
pub use tiles::{TileGrid, TileRect, TILE_PIXELS, TILE_SIZE};
pub use topk::{TopK, TopKBand};
