//! One call for the whole forward pass: project → bin_and_sort → rasterize.

use crate::bin::{bin_and_sort, TileBins};
use crate::camera::Camera;
use crate::map::GaussianMap;
use crate::output::{RenderOutput, RenderRequest};
use crate::project::{project_into, Projected};
use crate::rasterize::{rasterize_into, replay_pixel};
use crate::tiles::{TileGrid, TILE_SIZE};
use crate::top_k::heaviest_first;

/// A forward pass with its intermediate data kept for a later backward pass.
#[derive(Debug, Clone, Default)]
pub struct Rendered {
    pub projected: Projected,
    pub bins: TileBins,
    pub output: RenderOutput,
}

/// Renders `map` from `camera`, producing what `request` asks for.
pub fn render(map: &GaussianMap, camera: &Camera, request: &RenderRequest) -> Rendered {
    let mut r = Rendered::default();
    render_into(map, camera, request, &mut r);
    r
}

/// [`render`] reusing the image buffers of a previous render (the cheap way to render
/// every frame: no fresh memory to fault in).
pub fn render_into(map: &GaussianMap, camera: &Camera, request: &RenderRequest, r: &mut Rendered) {
    let grid = TileGrid::new(camera.width(), camera.height());
    project_into(map, camera, &grid, &mut r.projected);
    r.bins = bin_and_sort(&r.projected, &grid);
    rasterize_into(
        &r.projected,
        &r.bins,
        &grid,
        &map.labels,
        request,
        &mut r.output,
    );
}

impl Rendered {
    /// Contributions (Gaussian id, α·T) of pixel (x, y), front to back, recomputed from the
    /// kept projection and tile lists (bit-identical to the pass that made `output`).
    pub fn pixel_contributions(&self, x: u32, y: u32) -> Vec<(u32, f32)> {
        let (w, h) = (self.output.width, self.output.height);
        assert!(x < w && y < h, "pixel ({x}, {y}) outside {w}x{h}");
        let grid = TileGrid::new(w, h);
        let tile = ((y / TILE_SIZE) * grid.tiles_x + x / TILE_SIZE) as usize;
        let list = self.bins.tile(tile);
        let mut out = Vec::new();
        replay_pixel(&self.projected, list, x, y, &mut out);
        for c in &mut out {
            c.0 = list[c.0 as usize];
        }
        out
    }

    /// Top-K of one pixel on demand, heaviest first — the same lists the in-pass top-K gives,
    /// for callers that need them only at a few pixels (e.g. where a label changes, §4).
    pub fn top_k_at(&self, x: u32, y: u32, k: usize) -> Vec<(u32, f32)> {
        heaviest_first(&self.pixel_contributions(x, y), k)
    }
}
