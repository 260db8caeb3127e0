//! What a quality evaluation found.

use std::path::PathBuf;

use serde::Serialize;

/// Scores of one evaluated frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FrameQuality {
    /// Dataset frame index.
    pub index: usize,
    pub timestamp: f64,
    pub psnr_db: f64,
    pub ssim: f64,
    /// Fraction of pixels with valid input depth (the evaluated ones).
    pub valid_fraction: f64,
    /// Of those, the fraction the map leaves open: accumulated α (silhouette) below
    /// [`HOLE_SILHOUETTE`].
    pub holes: f64,
}

/// A valid-depth pixel whose render accumulates less α than this is a hole in the map.
pub const HOLE_SILHOUETTE: f32 = 0.5;

/// Render quality over a set of frames (docs/METHOD.md §9: masked where input depth is missing).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct QualityReport {
    pub frames_evaluated: usize,
    /// Mean over frames of the per-frame PSNR (dB), as 3DGS-SLAM papers report it.
    pub psnr_db: f64,
    /// Mean over frames of the per-frame SSIM.
    pub ssim: f64,
    /// Holes over all evaluated pixels: percent of valid-depth pixels with α < 0.5.
    pub holes_pct: f64,
    /// Frames skipped because no pixel had depth.
    pub frames_without_depth: usize,
    pub per_frame: Vec<FrameQuality>,
    /// Side-by-side PNGs written.
    pub pngs: Vec<PathBuf>,
}
