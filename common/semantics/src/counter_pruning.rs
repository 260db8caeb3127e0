//! Segmentation counter pruning selection (docs/METHOD.md §5.3).

use crate::error::Result;
use crate::output::CounterPruneRegion;
use opengs_splat::TopK;

use crate::relabel::validate_regions;

/// Counter Gaussians to prune: ids in the regions' top-K lists whose label is the region's ℓr
/// and whose largest scale (metres, not log) is above `theta`. Sorted, without duplicates.
pub fn select_counter_gaussians(
    top_k: &TopK,
    labels: &[u32],
    max_scale: impl Fn(usize) -> f32,
    theta: f32,
    regions: &[CounterPruneRegion],
) -> Result<Vec<u32>> {
    validate_regions(
        top_k,
        labels.len(),
        regions.iter().map(|r| r.pixels.as_slice()),
    )?;
    let mut selected = Vec::new();
    for region in regions {
        for &p in &region.pixels {
            for id in top_k.gaussians_at(p as usize) {
                // Validated above: every id indexes `labels`.
                if labels[id as usize] == region.label && max_scale(id as usize) > theta {
                    selected.push(id);
                }
            }
        }
    }
    selected.sort_unstable();
    selected.dedup();
    Ok(selected)
}
