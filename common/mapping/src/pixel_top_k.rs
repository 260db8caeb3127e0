//! The G_topK record of one keyframe render, kept by the mapper until the consensus for that
//! keyframe comes back (METHOD §4).

use opengs_splat::{TopK as RenderedTopK, TopKBand, TILE_SIZE};

/// A render's top-K lists, owned as the renderer wrote them (per pixel a start and a count in
/// its 16-row band's arrays): taking them costs nothing, where copying the 4.7 M entries of a
/// 640×480 render into another layout cost 24 ms, most of the render's own time.
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
        assert_eq!(lists.len(), width as usize * height as usize);
        let mut top_k = RenderedTopK {
            k: lists.iter().map(Vec::len).max().unwrap_or(0),
            width,
            height,
            start: Vec::with_capacity(lists.len()),
            count: Vec::with_capacity(lists.len()),
            bands: Vec::new(),
        };
        for (p, list) in lists.iter().enumerate() {
            let band = p / width as usize / TILE_SIZE as usize;
            if band == top_k.bands.len() {
                top_k.bands.push(TopKBand::default());
            }
            let store = &mut top_k.bands[band];
            top_k.start.push(store.ids.len() as u32);
            top_k.count.push(list.len() as u16);
            store.ids.extend(list.iter().map(|e| e.0));
            store.weights.extend(list.iter().map(|e| e.1));
        }
        Self { top_k }
    }

    /// Gives the render's top-K back (its buffers can serve another render).
    pub fn into_render(self) -> RenderedTopK {
        self.top_k
    }

    /// Pixels per 16-row band: pixel p's lists are in band p / this.
    fn pixels_per_band(&self) -> usize {
        TILE_SIZE as usize * self.top_k.width as usize
    }

    /// Pixel `pixel`'s (ids, weights) (row-major index; empty when out of range).
    fn lists_at(&self, pixel: usize) -> (&[u32], &[f32]) {
        let t = &self.top_k;
        let (Some(&s), Some(&n)) = (t.start.get(pixel), t.count.get(pixel)) else {
            return (&[], &[]);
        };
        let band = &t.bands[pixel / self.pixels_per_band()];
        let (s, n) = (s as usize, n as usize);
        (&band.ids[s..s + n], &band.weights[s..s + n])
    }

    /// Weight α·T of Gaussian `id` at `pixel`, if it is in that pixel's top-K.
    pub fn weight_of(&self, pixel: usize, id: u32) -> Option<f32> {
        let (ids, ws) = self.lists_at(pixel);
        let at = ids.iter().position(|&g| g == id)?;
        Some(ws[at])
    }

    /// Total number of recorded ids.
    pub fn entries(&self) -> usize {
        self.top_k.count.iter().map(|&c| c as usize).sum()
    }

    /// Rewrites ids after the map was compacted (`old_to_new` from `GaussianMap::remove_where`);
    /// removed Gaussians drop out of every list (each list shrinks in place).
    pub fn remap(&mut self, old_to_new: &[Option<u32>]) {
        let pixels_per_band = self.pixels_per_band();
        let t = &mut self.top_k;
        for (p, (&s, count)) in t.start.iter().zip(t.count.iter_mut()).enumerate() {
            let band = &mut t.bands[p / pixels_per_band];
            let (s, n) = (s as usize, *count as usize);
            let mut write = s;
            for read in s..s + n {
                if let Some(id) = old_to_new.get(band.ids[read] as usize).copied().flatten() {
                    band.ids[write] = id;
                    band.weights[write] = band.weights[read];
                    write += 1;
                }
            }
            *count = (write - s) as u16;
        }
    }
}

impl opengs_semantics::TopK for PixelTopK {
    fn pixel_count(&self) -> usize {
        self.top_k.count.len()
    }

    fn gaussians_at(&self, pixel: usize) -> &[u32] {
        self.lists_at(pixel).0
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
                vec![(0, 0.5), (2, 0.25), (3, 0.1)],
                vec![(1, 0.5), (3, 0.2)],
            ],
        );
        // Gaussians 0 and 3 removed: 1 → 0, 2 → 1.
        t.remap(&[None, Some(0), Some(1), None]);
        assert_eq!(t.gaussians_at(0), &[1]);
        assert_eq!(t.gaussians_at(1), &[0]);
        assert_eq!(t.entries(), 2);
        assert_eq!(t.gaussians_at(2), &[] as &[u32]);
        assert_eq!(t.weight_of(0, 1), Some(0.25));
        assert_eq!(t.weight_of(1, 0), Some(0.5));
        assert_eq!(t.weight_of(1, 1), None);
    }

    #[test]
    fn lists_of_every_band_are_found_and_remapped() {
        // 3×40 pixels: three 16-row bands, the last one partial. Pixel p lists p % 7 ids.
        let lists: Vec<Vec<(u32, f32)>> = (0..120u32)
            .map(|p| (0..p % 7).map(|i| (p + i, i as f32 * 0.1)).collect())
            .collect();
        let mut t = PixelTopK::from_lists(3, 40, &lists);
        assert_eq!(t.pixel_count(), 120);
        assert_eq!(t.entries(), lists.iter().map(Vec::len).sum::<usize>());
        for (p, list) in lists.iter().enumerate() {
            let ids: Vec<u32> = list.iter().map(|e| e.0).collect();
            assert_eq!(t.gaussians_at(p), &ids[..], "pixel {p}");
        }
        assert_eq!(t.weight_of(104, 106), Some(0.2));
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
            assert_eq!(t.gaussians_at(p), &ids[..], "pixel {p}");
        }
        assert_eq!(t.weight_of(104, 53), Some(0.2));
    }
}
