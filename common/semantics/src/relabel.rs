//! The relabel step of docs/METHOD.md §4, through a render's G_topK ([`TopK`]).

use opengs_splat::TopK;

use crate::error::{Result, SemanticsError};
use crate::output::{RelabelInstruction, RelabelScope};

/// Checks every pixel of `regions` and every Gaussian id recorded there (against a map of
/// `gaussians`), so a caller can validate before it changes anything.
pub fn validate_regions<'p>(
    top_k: &TopK,
    gaussians: usize,
    regions: impl Iterator<Item = &'p [u32]>,
) -> Result<()> {
    for region in regions {
        for (y, tile_x, lanes) in tile_rows(top_k, region)? {
            if let Some(id) = top_k
                .ids_kept_in_tile_row(y, tile_x, lanes)
                .find(|&id| id as usize >= gaussians)
            {
                return Err(SemanticsError::GaussianOutOfRange { id, gaussians });
            }
        }
    }
    Ok(())
}

/// [`validate_regions`] read pixel by pixel: the twin [`crate::select_counter_gaussians_per_pixel`]
/// checks with.
pub(crate) fn validate_regions_per_pixel<'p>(
    top_k: &TopK,
    gaussians: usize,
    regions: impl Iterator<Item = &'p [u32]>,
) -> Result<()> {
    let pixels = top_k.pixel_count();
    for region in regions {
        for &p in region {
            if p as usize >= pixels {
                return Err(SemanticsError::PixelOutOfRange { pixel: p, pixels });
            }
            if let Some(id) = top_k
                .gaussians_at(p as usize)
                .find(|&id| id as usize >= gaussians)
            {
                return Err(SemanticsError::GaussianOutOfRange { id, gaussians });
            }
        }
    }
    Ok(())
}

/// A region's pixels gathered by tile row, `(image row, tile, lane bits)`, for
/// [`TopK::ids_kept_in_tile_row`]: one scan of a tile row's visits serves all its pixels
/// (docs/METHOD.md §5.3). Errors on a pixel outside the render.
pub(crate) fn tile_rows(top_k: &TopK, pixels: &[u32]) -> Result<Vec<(u32, u32, u32)>> {
    let count = top_k.pixel_count();
    let (width, tile) = (top_k.width.max(1), opengs_splat::TILE_SIZE);
    let mut rows: Vec<(u32, u32, u32)> = Vec::new();
    for &p in pixels {
        if p as usize >= count {
            return Err(SemanticsError::PixelOutOfRange {
                pixel: p,
                pixels: count,
            });
        }
        let (x, y) = (p % width, p / width);
        let (tile_x, lane) = (x / tile, 1u32 << (x % tile));
        match rows.last_mut() {
            Some((ry, rt, lanes)) if (*ry, *rt) == (y, tile_x) => *lanes |= lane,
            _ => rows.push((y, tile_x, lane)),
        }
    }
    Ok(rows)
}

/// Applies relabel instructions in order: in each listed pixel's top-K (or, for
/// [`RelabelScope::Label`] and [`RelabelScope::Merged`], anywhere in the map) a Gaussian
/// labelled `from` gets `to`. [`RelabelScope::Rejoin`] is skipped: it needs the map's surfaces
/// after labelling, which the mapper has.
/// Validates everything first, so on error no label changed.
/// Returns how many label writes happened.
pub fn apply_relabels(
    top_k: &TopK,
    labels: &mut [u32],
    relabels: &[RelabelInstruction],
) -> Result<usize> {
    apply_relabels_centred(top_k, labels, relabels, |_| None)
}

/// [`apply_relabels`], where a pixel-scope instruction moves only the Gaussians whose centre
/// falls in its own pixels (`centre_pixel`: None where unknown, which moves): a large Gaussian
/// that only overlaps a small segment belongs to what lies around it.
pub fn apply_relabels_centred(
    top_k: &TopK,
    labels: &mut [u32],
    relabels: &[RelabelInstruction],
    centre_pixel: impl Fn(u32) -> Option<usize>,
) -> Result<usize> {
    validate_regions(
        top_k,
        labels.len(),
        relabels.iter().map(|r| r.pixels.as_slice()),
    )?;
    let mut changed = 0;
    let mut in_region = vec![false; top_k.pixel_count()];
    for instruction in relabels {
        if instruction.from == instruction.to || instruction.scope == RelabelScope::Rejoin {
            continue;
        }
        if matches!(
            instruction.scope,
            RelabelScope::Label | RelabelScope::Merged
        ) {
            for label in labels.iter_mut().filter(|l| **l == instruction.from) {
                *label = instruction.to;
                changed += 1;
            }
            continue;
        }
        for &p in &instruction.pixels {
            in_region[p as usize] = true; // in range: validated above
        }
        for (y, tile_x, lanes) in tile_rows(top_k, &instruction.pixels)? {
            for id in top_k.ids_kept_in_tile_row(y, tile_x, lanes) {
                let label = &mut labels[id as usize]; // in range: validated above
                if *label != instruction.from {
                    continue;
                }
                if centre_pixel(id).is_none_or(|c| in_region.get(c) == Some(&true)) {
                    *label = instruction.to;
                    changed += 1;
                }
            }
        }
        for &p in &instruction.pixels {
            in_region[p as usize] = false;
        }
    }
    Ok(changed)
}
