//! What a render is asked for and what it returns.

use std::collections::BTreeMap;

use crate::top_k::TopK;

/// Which outputs a render must produce. Colour, depth, silhouette always come; the rest
/// cost (almost) nothing when not asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RenderRequest {
    /// GS Voting label map (docs/METHOD.md §3).
    pub labels: bool,
    /// Top-K Gaussians per pixel by weight; `Some(k)` with k ≥ 1.
    pub top_k: Option<usize>,
    /// Per-label count of Gaussians that contributed to at least one pixel.
    pub visible_counts: bool,
}

impl RenderRequest {
    /// Colour, depth and silhouette only.
    pub fn color_depth() -> Self {
        Self::default()
    }

    /// Everything the consensus stage needs: labels, top-K (K = `k`), visible counts.
    pub fn semantic(k: usize) -> Self {
        Self {
            labels: true,
            top_k: Some(k),
            visible_counts: true,
        }
    }

    /// True when any per-contribution bookkeeping is needed.
    pub fn needs_contributions(&self) -> bool {
        self.labels || self.top_k.is_some_and(|k| k > 0) || self.visible_counts
    }
}

/// Default K of the paper's G_topK.
pub const DEFAULT_TOP_K: usize = 50;

/// Images of one render, row-major, `width × height`.
#[derive(Debug, Clone, Default)]
pub struct RenderOutput {
    pub width: u32,
    pub height: u32,
    /// C = Σ f α T (black background).
    pub color: Vec<[f32; 3]>,
    /// D = Σ d α T (not normalised by the silhouette).
    pub depth: Vec<f32>,
    /// S = Σ α T.
    pub silhouette: Vec<f32>,
    /// Transmittance left after the last composited Gaussian (for a backward pass).
    pub final_transmittance: Vec<f32>,
    /// Tile-list position + 1 of the last contributing Gaussian (3DGS n_contrib; 0 = none).
    pub n_contrib: Vec<u32>,
    /// Voted label per pixel (0 = none).
    pub labels: Option<Vec<u32>>,
    pub top_k: Option<TopK>,
    /// label → number of Gaussians that contributed to at least one pixel.
    pub visible_per_label: Option<BTreeMap<u32, u32>>,
}

impl RenderOutput {
    pub fn index(&self, x: u32, y: u32) -> usize {
        (y * self.width + x) as usize
    }
}
