//! Per-pixel G_topK records and the relabel step of METHOD.md §4.

use crate::error::{Result, SemanticsError};
use crate::output::RelabelInstruction;

/// Read access to a per-pixel list of Gaussian ids (the K largest-weight contributors).
pub trait TopK {
    /// Number of pixels covered.
    fn pixel_count(&self) -> usize;
    /// Gaussian ids recorded at `pixel` (none when out of range).
    fn gaussians_at(&self, pixel: usize) -> impl Iterator<Item = u32> + '_;
}

/// Flat top-K record: `k` slots per pixel in `ids`, of which the first `counts[p]` are used.
/// The count type is generic (`u8` for K ≤ 255, `u16` for larger K).
#[derive(Debug, Clone, Copy)]
pub struct TopKView<'a, C = u8> {
    pub k: usize,
    pub counts: &'a [C],
    pub ids: &'a [u32],
}

impl<'a, C: Copy + Into<usize>> TopKView<'a, C> {
    /// Checks `ids.len() == counts.len() × k` and every count ≤ k.
    pub fn new(k: usize, counts: &'a [C], ids: &'a [u32]) -> Result<Self> {
        let expected = counts.len().checked_mul(k);
        if expected != Some(ids.len()) {
            return Err(SemanticsError::InvalidTopK(format!(
                "{} ids for {} pixels × k={}",
                ids.len(),
                counts.len(),
                k
            )));
        }
        if let Some(p) = counts.iter().position(|&c| c.into() > k) {
            let claimed: usize = counts[p].into();
            return Err(SemanticsError::InvalidTopK(format!(
                "pixel {p} claims {claimed} entries, k={k}"
            )));
        }
        Ok(Self { k, counts, ids })
    }
}

impl<C: Copy + Into<usize>> TopK for TopKView<'_, C> {
    fn pixel_count(&self) -> usize {
        self.counts.len()
    }

    fn gaussians_at(&self, pixel: usize) -> impl Iterator<Item = u32> + '_ {
        let ids = match self.counts.get(pixel) {
            Some(&count) => {
                let start = pixel * self.k;
                self.ids.get(start..start + count.into()).unwrap_or(&[])
            }
            None => &[],
        };
        ids.iter().copied()
    }
}

/// Checks every pixel of `regions` and every Gaussian id recorded there (against a map of
/// `gaussians`), so a caller can validate before it changes anything.
pub fn validate_regions<'p>(
    top_k: &impl TopK,
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

/// Applies relabel instructions in order: in each listed pixel's top-K, a Gaussian labelled
/// `from` gets `to`. Validates everything first, so on error no label changed.
/// Returns how many label writes happened.
pub fn apply_relabels(
    top_k: &impl TopK,
    labels: &mut [u32],
    relabels: &[RelabelInstruction],
) -> Result<usize> {
    validate_regions(
        top_k,
        labels.len(),
        relabels.iter().map(|r| r.pixels.as_slice()),
    )?;
    let mut changed = 0;
    for instruction in relabels {
        for &p in &instruction.pixels {
            for id in top_k.gaussians_at(p as usize) {
                let label = &mut labels[id as usize]; // in range: validated above
                if *label == instruction.from && instruction.from != instruction.to {
                    *label = instruction.to;
                    changed += 1;
                }
            }
        }
    }
    Ok(changed)
}
