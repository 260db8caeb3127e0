//! Tile binning with per-tile front-to-back order (3DGS duplicateWithKeys + sort).

use rayon::prelude::*;

use crate::project::Projected;
use crate::tiles::TileGrid;

/// Per-tile Gaussian lists, each sorted by view depth (ties by index), as CSR.
/// Plain data so a backward pass can walk the same lists.
#[derive(Debug, Clone, Default)]
pub struct TileBins {
    /// `ids[offsets[t]..offsets[t + 1]]` are tile t's Gaussians (row-major tile index).
    pub offsets: Vec<u32>,
    pub ids: Vec<u32>,
}

impl TileBins {
    /// Gaussians of tile `t`, front to back.
    pub fn tile(&self, t: usize) -> &[u32] {
        &self.ids[self.offsets[t] as usize..self.offsets[t + 1] as usize]
    }
}

/// Sorts visible Gaussians by depth once, then scatters them into tiles (a stable counting
/// sort by tile), which leaves every tile's list in depth order.
pub fn bin_and_sort(projected: &Projected, grid: &TileGrid) -> TileBins {
    let mut keys: Vec<u64> = projected
        .tile_rects
        .par_iter()
        .enumerate()
        .with_min_len(4096)
        .filter(|(_, r)| !r.is_empty())
        // Depths are > near ≥ 0, so their bit patterns sort like the values.
        .map(|(i, _)| ((projected.depths[i].to_bits() as u64) << 32) | i as u64)
        .collect();
    keys.par_sort_unstable();

    let tiles = grid.tile_count();
    let tx = grid.tiles_x as usize;
    let mut counts = vec![0u32; tiles + 1];
    for &k in &keys {
        let r = projected.tile_rects[k as u32 as usize];
        for y in r.y0..r.y1 {
            let row = y as usize * tx;
            for x in r.x0..r.x1 {
                counts[row + x as usize] += 1;
            }
        }
    }
    let mut offsets = vec![0u32; tiles + 1];
    for t in 0..tiles {
        offsets[t + 1] = offsets[t] + counts[t];
    }
    let mut cursor = offsets.clone();
    let mut ids = vec![0u32; offsets[tiles] as usize];
    for &k in &keys {
        let i = k as u32;
        let r = projected.tile_rects[i as usize];
        for y in r.y0..r.y1 {
            let row = y as usize * tx;
            for x in r.x0..r.x1 {
                let c = &mut cursor[row + x as usize];
                ids[*c as usize] = i;
                *c += 1;
            }
        }
    }
    TileBins { offsets, ids }
}
