//! The G_topK record of one keyframe render, kept by the mapper until the consensus for that
//! keyframe comes back (METHOD §4).

use opengs_splat::TopK as RenderedTopK;

/// Per-pixel Gaussian ids and weights in compressed-row form: pixel p's entries are
/// `offsets[p] .. offsets[p + 1]`. Compact (8 bytes per entry), and easy to remap when the map
/// is pruned while the record waits for its consensus.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PixelTopK {
    pub width: u32,
    pub height: u32,
    offsets: Vec<u32>,
    ids: Vec<u32>,
    weights: Vec<f32>,
}

impl PixelTopK {
    /// Copies a render's top-K.
    pub fn from_render(top_k: &RenderedTopK) -> Self {
        let pixels = top_k.width as usize * top_k.height as usize;
        let mut offsets = Vec::with_capacity(pixels + 1);
        let mut ids = Vec::with_capacity(top_k.entries());
        let mut weights = Vec::with_capacity(top_k.entries());
        offsets.push(0);
        for y in 0..top_k.height {
            for x in 0..top_k.width {
                let (i, w) = top_k.pixel(x, y);
                ids.extend_from_slice(i);
                weights.extend_from_slice(w);
                offsets.push(ids.len() as u32);
            }
        }
        Self {
            width: top_k.width,
            height: top_k.height,
            offsets,
            ids,
            weights,
        }
    }

    /// Builds a record from explicit per-pixel (id, weight) lists (row-major), e.g. in tests.
    pub fn from_lists(width: u32, height: u32, lists: &[Vec<(u32, f32)>]) -> Self {
        assert_eq!(lists.len(), width as usize * height as usize);
        let mut offsets = vec![0];
        let (mut ids, mut weights) = (Vec::new(), Vec::new());
        for list in lists {
            ids.extend(list.iter().map(|e| e.0));
            weights.extend(list.iter().map(|e| e.1));
            offsets.push(ids.len() as u32);
        }
        Self {
            width,
            height,
            offsets,
            ids,
            weights,
        }
    }

    /// Weight α·T of Gaussian `id` at `pixel`, if it is in that pixel's top-K.
    pub fn weight_of(&self, pixel: usize, id: u32) -> Option<f32> {
        let (s, e) = (*self.offsets.get(pixel)?, *self.offsets.get(pixel + 1)?);
        let (s, e) = (s as usize, e as usize);
        let at = self.ids[s..e].iter().position(|&g| g == id)?;
        Some(self.weights[s + at])
    }

    /// Total number of recorded ids.
    pub fn entries(&self) -> usize {
        self.ids.len()
    }

    /// Rewrites ids after the map was compacted (`old_to_new` from `GaussianMap::remove_where`);
    /// removed Gaussians drop out of every list.
    pub fn remap(&mut self, old_to_new: &[Option<u32>]) {
        let mut write = 0usize;
        let mut start = 0usize;
        for p in 0..self.offsets.len() - 1 {
            let end = self.offsets[p + 1] as usize;
            for read in start..end {
                let new = old_to_new.get(self.ids[read] as usize).copied().flatten();
                if let Some(id) = new {
                    self.ids[write] = id;
                    self.weights[write] = self.weights[read];
                    write += 1;
                }
            }
            start = end;
            self.offsets[p + 1] = write as u32;
        }
        self.ids.truncate(write);
        self.weights.truncate(write);
    }
}

impl opengs_semantics::TopK for PixelTopK {
    fn pixel_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    fn gaussians_at(&self, pixel: usize) -> &[u32] {
        match (self.offsets.get(pixel), self.offsets.get(pixel + 1)) {
            (Some(&s), Some(&e)) => &self.ids[s as usize..e as usize],
            _ => &[],
        }
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
}
