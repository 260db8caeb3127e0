//! Edge-aware upsampling of coarse segments back to full resolution: pixels
//! in blocks on a segment boundary take the segment of the most similar
//! neighbouring block, so boundaries are not blocky.

use super::downscale::CoarseFrame;
use super::graph::EdgeWeights;
use super::noise::DepthNoiseModel;

/// Full-resolution frame the coarse segments are painted back into.
pub struct FullFrame<'a> {
    pub width: usize,
    pub height: usize,
    pub rgb: &'a [u8],
    pub depth: &'a [u16],
    pub depth_scale: f32,
}

impl<'a> FullFrame<'a> {
    /// The buffers of a validated segmenter input.
    pub fn of_input(input: &crate::SegmenterInput<'a>) -> Self {
        Self {
            width: input.width as usize,
            height: input.height as usize,
            rgb: input.rgb,
            depth: input.depth,
            depth_scale: input.depth_scale,
        }
    }
}

/// Segment index per full-resolution pixel.
pub fn upsample_segments(
    full: &FullFrame,
    coarse: &CoarseFrame,
    segment_of: &[u32],
    factor: usize,
    weights: &EdgeWeights,
    noise: &DepthNoiseModel,
) -> Vec<u32> {
    // Full-resolution pixels carry the raw (unsmoothed, unaveraged) noise.
    let gap_per_z2 = weights.noise_sigmas * noise.inverse_depth_sigma * factor as f32;
    let (cw, ch) = (coarse.width, coarse.height);
    let on_boundary: Vec<bool> = (0..cw * ch)
        .map(|i| {
            let (x, y) = (i % cw, i / cw);
            neighbourhood(x, y, cw, ch).any(|j| segment_of[j] != segment_of[i])
        })
        .collect();
    let inv_units = 1.0 / full.depth_scale;
    let mut out = Vec::with_capacity(full.width * full.height);
    for y in 0..full.height {
        let cy = y / factor;
        for x in 0..full.width {
            let cx = x / factor;
            let own = cy * cw + cx;
            if !on_boundary[own] {
                out.push(segment_of[own]);
                continue;
            }
            let p = y * full.width + x;
            let colour = [0, 1, 2].map(|c| full.rgb[p * 3 + c] as f32 / 255.0);
            let depth = full.depth[p] as f32 * inv_units;
            let best = neighbourhood(cx, cy, cw, ch)
                .map(|j| {
                    (
                        dissimilarity(colour, depth, coarse, j, weights, gap_per_z2),
                        j,
                    )
                })
                .fold((f32::INFINITY, own), |a, b| if b.0 < a.0 { b } else { a });
            out.push(segment_of[best.1]);
        }
    }
    out
}

/// Same colour + depth terms as the graph edges, between a pixel and a block.
fn dissimilarity(
    colour: [f32; 3],
    depth: f32,
    coarse: &CoarseFrame,
    j: usize,
    w: &EdgeWeights,
    gap_per_z2: f32,
) -> f32 {
    let c = coarse.rgb[j];
    let dc = [colour[0] - c[0], colour[1] - c[1], colour[2] - c[2]];
    let mut d = w.colour * (dc[0] * dc[0] + dc[1] * dc[1] + dc[2] * dc[2]).sqrt();
    let z = coarse.depth_m[j];
    if depth > 0.0 && z > 0.0 {
        let near = depth.min(z);
        let excess = ((depth - z).abs() - gap_per_z2 * near * near).max(0.0);
        d += w.depth * (excess / (near * w.depth_gap_scale)).min(w.depth_cap);
    }
    d
}

/// The block itself first (wins ties), then its 8 neighbours inside the grid.
fn neighbourhood(x: usize, y: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    const OFFSETS: [(isize, isize); 9] = [
        (0, 0),
        (-1, -1),
        (0, -1),
        (1, -1),
        (-1, 0),
        (1, 0),
        (-1, 1),
        (0, 1),
        (1, 1),
    ];
    OFFSETS.iter().filter_map(move |&(dx, dy)| {
        let (nx, ny) = (x as isize + dx, y as isize + dy);
        (nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h)
            .then(|| ny as usize * w + nx as usize)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boundary_pixels_follow_colour() {
        // 4x2 frame, columns 0..=2 black, column 3 white; coarse 2x1 blocks
        // [black, black | black, white] labelled 0 | 1.
        let mut rgb = vec![0u8; 4 * 2 * 3];
        for y in 0..2 {
            for c in 0..3 {
                rgb[(y * 4 + 3) * 3 + c] = 255;
            }
        }
        let depth = vec![0u16; 8];
        let coarse = CoarseFrame {
            width: 2,
            height: 1,
            rgb: vec![[0.0; 3], [0.5; 3]],
            depth_m: vec![0.0; 2],
        };
        let full = FullFrame {
            width: 4,
            height: 2,
            rgb: &rgb,
            depth: &depth,
            depth_scale: 1000.0,
        };
        let w = EdgeWeights {
            colour: 1.0,
            depth: 1.0,
            depth_gap_scale: 0.01,
            depth_cap: 4.0,
            depth_to_missing: 0.0,
            normal: 1.0,
            noise_sigmas: 3.0,
        };
        let out = upsample_segments(&full, &coarse, &[0, 1], 2, &w, &DepthNoiseModel::default());
        assert_eq!(out, vec![0, 0, 0, 1, 0, 0, 0, 1]);
    }
}
