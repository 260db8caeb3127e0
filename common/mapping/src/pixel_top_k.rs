//! The G_topK record of one keyframe render, kept by the mapper until the consensus for that
//! keyframe comes back (METHOD §4).

use opengs_splat::TopK as RenderedTopK;

/// A render's top-K, owned as the renderer wrote it (per tile row, its visits with lane masks
/// and weights): taking it costs nothing, where copying the 4.7 M entries of a 640×480
/// render into another layout cost 24 ms, most of the render's own time.
#[derive(Debug, Clone, Default)]
pub struct PixelTopK {
    top_k: RenderedTopK,
}

impl PixelTopK {
    /// Takes a render's top-K.
    pub fn from_render(top_k: RenderedTopK) -> Self {
        Self { top_k }
    }

    /// Builds a record from explicit per-pixel (id, weight) lists (row-major), e.g. in tests.
    pub fn from_lists(width: u32, height: u32, lists: &[Vec<(u32, f32)>]) -> Self {
        Self {
            top_k: RenderedTopK::from_lists(width, height, lists),
        }
    }

    /// Gives the render's top-K back (its buffers can serve another render).
    pub fn into_render(self) -> RenderedTopK {
        self.top_k
    }

    /// Pixel `pixel`'s (id, weight) entries, front to back (none when out of range).
    fn entries_at(&self, pixel: usize) -> impl Iterator<Item = (u32, f32)> + '_ {
        let t = &self.top_k;
        // A pixel in range means a width of at least 1.
        let w = t.width as usize;
        (pixel < t.count.len())
            .then(|| t.pixel((pixel % w) as u32, (pixel / w) as u32))
            .into_iter()
            .flatten()
    }

    /// Weight α·T of Gaussian `id` at `pixel`, if it is in that pixel's top-K.
    pub fn weight_of(&self, pixel: usize, id: u32) -> Option<f32> {
        self.entries_at(pixel).find(|e| e.0 == id).map(|e| e.1)
    }

    /// Total number of recorded ids.
    pub fn entries(&self) -> usize {
        self.top_k.entries()
    }

    /// Rewrites ids after the map was compacted (`old_to_new` from `GaussianMap::remove_where`);
    /// removed Gaussians drop out of every list.
    pub fn remap(&mut self, old_to_new: &[Option<u32>]) {
        self.top_k.remap(old_to_new);
    }
}

impl opengs_semantics::TopK for PixelTopK {
    fn pixel_count(&self) -> usize {
        self.top_k.count.len()
    }

    fn gaussians_at(&self, pixel: usize) -> impl Iterator<Item = u32> + '_ {
        self.entries_at(pixel).map(|e| e.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_semantics::TopK;

    #[test]
    fn remap_drops_removed_and_renumbers() {
        let mut t = PixelTopK::from_lists(
            2,
            1,
            &[
                vec![(0, 0.5), (2, 0.25), (3, 0.125)],
                vec![(1, 0.5), (3, 0.375)],
            ],
        );
        // Gaussians 0 and 3 removed: 1 → 0, 2 → 1.
        t.remap(&[None, Some(0), Some(1), None]);
        assert_eq!(t.gaussians_at(0).collect::<Vec<_>>(), [1]);
        assert_eq!(t.gaussians_at(1).collect::<Vec<_>>(), [0]);
        assert_eq!(t.entries(), 2);
        assert_eq!(t.gaussians_at(2).count(), 0);
        assert_eq!(t.weight_of(0, 1), Some(0.25));
        assert_eq!(t.weight_of(1, 0), Some(0.5));
        assert_eq!(t.weight_of(1, 1), None);
    }

    #[test]
    fn lists_of_every_band_are_found_and_remapped() {
        // 3×40 pixels: three 16-row bands, the last one partial. Pixel p lists p % 7 ids,
        // weights in eighths (f16 holds them exactly).
        let lists: Vec<Vec<(u32, f32)>> = (0..120u32)
            .map(|p| (0..p % 7).map(|i| (p + i, (i + 1) as f32 / 8.0)).collect())
            .collect();
        let mut t = PixelTopK::from_lists(3, 40, &lists);
        assert_eq!(t.pixel_count(), 120);
        assert_eq!(t.entries(), lists.iter().map(Vec::len).sum::<usize>());
        for (p, list) in lists.iter().enumerate() {
            let ids: Vec<u32> = list.iter().map(|e| e.0).collect();
            assert_eq!(t.gaussians_at(p).collect::<Vec<_>>(), ids, "pixel {p}");
        }
        assert_eq!(t.weight_of(104, 106), Some(0.375));
        // Odd ids removed, even ones halved.
        let old_to_new: Vec<Option<u32>> =
            (0..130u32).map(|i| (i % 2 == 0).then_some(i / 2)).collect();
        t.remap(&old_to_new);
        for (p, list) in lists.iter().enumerate() {
            let ids: Vec<u32> = list
                .iter()
                .filter(|e| e.0 % 2 == 0)
                .map(|e| e.0 / 2)
                .collect();
            assert_eq!(t.gaussians_at(p).collect::<Vec<_>>(), ids, "pixel {p}");
        }
        assert_eq!(t.weight_of(104, 53), Some(0.375));
    }
}
