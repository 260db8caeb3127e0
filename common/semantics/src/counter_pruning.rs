//! Segmentation counter pruning selection (docs/METHOD.md §5.3).

use crate::error::{Result, SemanticsError};
use crate::output::CounterPruneRegion;
use opengs_splat::TopK;

use crate::relabel::tile_rows;

/// Counter Gaussians to prune: ids in the regions' top-K lists whose label is the region's ℓr
/// and whose largest scale (metres, not log) is above `theta`. Sorted, without duplicates.
/// Checks every pixel and id before it returns any (an error selects nothing).
///
/// A region's pixels share most of their Gaussians: its pixels are read a tile row at a
/// time (one scan of the row's visits, no weights), each id is judged once per region (its
/// label, then its scale), and the answer needs no sort of every entry (docs/METHOD.md
/// §5.3: per pixel, this took a tenth of the pipeline mapper's CPU).
pub fn select_counter_gaussians(
    top_k: &TopK,
    labels: &[u32],
    max_scale: impl Fn(usize) -> f32,
    theta: f32,
    regions: &[CounterPruneRegion],
) -> Result<Vec<u32>> {
    let gaussians = labels.len();
    // Per Gaussian: the last region (1-based) that judged it, and whether it is selected.
    let mut judged_in = vec![0u32; gaussians];
    let mut selected = vec![false; gaussians];
    for (region_number, region) in (1u32..).zip(regions) {
        for (y, tile_x, lanes) in tile_rows(top_k, &region.pixels)? {
            for id in top_k.ids_kept_in_tile_row(y, tile_x, lanes) {
                let i = id as usize;
                if i >= gaussians {
                    return Err(SemanticsError::GaussianOutOfRange { id, gaussians });
                }
                if judged_in[i] == region_number {
                    continue;
                }
                judged_in[i] = region_number;
                if labels[i] == region.label && max_scale(i) > theta {
                    selected[i] = true;
                }
            }
        }
    }
    Ok((0u32..)
        .zip(&selected)
        .filter_map(|(id, &s)| s.then_some(id))
        .collect())
}

/// [`select_counter_gaussians`] read pixel by pixel, every entry judged: slow and plainly
/// the definition, for tests and `opengs bench consensus` to compare against.
pub fn select_counter_gaussians_per_pixel(
    top_k: &TopK,
    labels: &[u32],
    max_scale: impl Fn(usize) -> f32,
    theta: f32,
    regions: &[CounterPruneRegion],
) -> Result<Vec<u32>> {
    crate::relabel::validate_regions_per_pixel(
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn tile_rows_select_what_the_per_pixel_reading_selects() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (w, h, n) = (45u32, 37u32, 400u32);
        let lists: Vec<Vec<(u32, f32)>> = (0..w * h)
            .map(|_| {
                let k = rng.gen_range(0..6);
                (0..k).map(|_| (rng.gen_range(0..n), 0.2)).collect()
            })
            .collect();
        let top_k = TopK::from_lists(w, h, &lists);
        let labels: Vec<u32> = (0..n).map(|_| rng.gen_range(0..4)).collect();
        let scales: Vec<f32> = (0..n).map(|_| rng.gen_range(0.0..0.2)).collect();
        let regions: Vec<CounterPruneRegion> = (0..5)
            .map(|r| CounterPruneRegion {
                label: r % 4,
                pixels: (0..w * h).filter(|_| rng.gen_bool(0.3)).collect(),
            })
            .collect();
        let fast = select_counter_gaussians(&top_k, &labels, |i| scales[i], 0.1, &regions);
        let slow =
            select_counter_gaussians_per_pixel(&top_k, &labels, |i| scales[i], 0.1, &regions);
        let fast = fast.expect("valid regions");
        assert_eq!(Ok(fast.clone()), slow);
        assert!(fast.len() > 20, "only {} selected", fast.len());
        // A pixel or an id out of range is refused by both.
        let outside = [CounterPruneRegion {
            label: 0,
            pixels: vec![w * h],
        }];
        assert!(select_counter_gaussians(&top_k, &labels, |i| scales[i], 0.1, &outside).is_err());
        let few_labels = &labels[..n as usize / 2];
        assert!(
            select_counter_gaussians(&top_k, few_labels, |i| scales[i], 0.1, &regions).is_err()
        );
    }
}
