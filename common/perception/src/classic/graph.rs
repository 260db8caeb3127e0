//! Pixel-adjacency graph with colour + depth-gap + normal-angle edge weights,
//! quantised and counting-sorted.

use super::downscale::CoarseFrame;
use super::normals::{dot, is_known, sub, SurfaceGeometry};

/// Edge weights are clamped to [0, MAX_WEIGHT] and quantised to this many bins.
pub const WEIGHT_BINS: usize = 4096;
pub const MAX_WEIGHT: f32 = 8.0;
pub const BIN_WIDTH: f32 = MAX_WEIGHT / (WEIGHT_BINS - 1) as f32;

/// Undirected edge between coarse pixels `a` < `b`, weight as a bin index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Edge {
    pub a: u32,
    pub b: u32,
    pub bin: u16,
}

impl Edge {
    pub fn weight(&self) -> f32 {
        self.bin as f32 * BIN_WIDTH
    }
}

/// How colour, depth and normals combine into one dissimilarity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeWeights {
    /// Multiplies the RGB distance (channels in 0..1, so at most √3).
    pub colour: f32,
    /// Weight added per `depth_gap_scale` of relative depth gap.
    pub depth: f32,
    /// Relative point-to-tangent-plane gap (gap / depth) worth `depth`.
    pub depth_gap_scale: f32,
    /// Cap on the depth term in units of `depth`.
    pub depth_cap: f32,
    /// Added between a pixel with depth and one without: the sensor loses
    /// depth beyond its range and in the shadow of a depth edge.
    pub depth_to_missing: f32,
    /// Multiplies 1 − cos(angle between normals).
    pub normal: f32,
    /// Depth gaps and normal angles within this many noise deviations of the
    /// frame's estimated depth noise are ignored.
    pub noise_sigmas: f32,
}

/// Noise-derived dead zones of one frame (zero on exact depth).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NoiseTolerance {
    /// Ignored point-to-plane gap per z² (metres⁻¹).
    pub gap_per_z2: f32,
    /// Ignored normal angle per metre of depth (radians per metre).
    pub angle_per_z: f32,
}

impl NoiseTolerance {
    /// From the std of (smoothed) inverse depth and the coarse focal length:
    /// a central difference spans 2 pixels = 2z/f metres, so its angle noise
    /// is √2·σ_z / (2z/f) = σ(1/z)·z·f/√2.
    pub fn new(inverse_depth_sigma: f32, focal_px: f32, sigmas: f32) -> Self {
        Self {
            gap_per_z2: sigmas * inverse_depth_sigma,
            angle_per_z: sigmas * inverse_depth_sigma * focal_px / std::f32::consts::SQRT_2,
        }
    }
}

impl EdgeWeights {
    fn weight(
        &self,
        frame: &CoarseFrame,
        geo: &SurfaceGeometry,
        tolerance: &NoiseTolerance,
        a: usize,
        b: usize,
    ) -> f32 {
        let (ca, cb) = (frame.rgb[a], frame.rgb[b]);
        let dc = sub(ca, cb);
        let mut w = self.colour * dot(dc, dc).sqrt();
        let (za, zb) = (geo.points[a][2], geo.points[b][2]);
        if za > 0.0 && zb > 0.0 {
            // Gap to the neighbour's tangent plane, not the raw depth step:
            // a slanted floor has large steps but lies in its own plane.
            let (na, nb) = (geo.normals[a], geo.normals[b]);
            let d = sub(geo.points[b], geo.points[a]);
            let gap = match (is_known(na), is_known(nb)) {
                (true, true) => dot(na, d).abs().max(dot(nb, d).abs()),
                (true, false) => dot(na, d).abs(),
                (false, true) => dot(nb, d).abs(),
                (false, false) => (za - zb).abs(),
            };
            let z = za.min(zb);
            let excess = (gap - tolerance.gap_per_z2 * z * z).max(0.0);
            w += self.depth * (excess / (z * self.depth_gap_scale)).min(self.depth_cap);
            if is_known(na) && is_known(nb) {
                // 1 − cos(θ) ≈ θ²/2 for the tolerated angle.
                let angle = (tolerance.angle_per_z * z).min(1.0);
                w += self.normal * (1.0 - dot(na, nb) - 0.5 * angle * angle).max(0.0);
            }
        } else if (za > 0.0) != (zb > 0.0) {
            w += self.depth_to_missing;
        }
        w
    }
}

fn quantise(w: f32) -> u16 {
    ((w.clamp(0.0, MAX_WEIGHT) / BIN_WIDTH) + 0.5) as u16
}

/// Builds the 4- or 8-connected graph into `edges`, sorted by weight.
/// `scratch` is reused between frames.
pub fn build_sorted_edges(
    frame: &CoarseFrame,
    geo: &SurfaceGeometry,
    weights: &EdgeWeights,
    tolerance: &NoiseTolerance,
    eight_connected: bool,
    edges: &mut Vec<Edge>,
    scratch: &mut Vec<Edge>,
) {
    let (w, h) = (frame.width, frame.height);
    scratch.clear();
    scratch.reserve(w * h * if eight_connected { 4 } else { 2 });
    let mut push = |a: usize, b: usize| {
        scratch.push(Edge {
            a: a as u32,
            b: b as u32,
            bin: quantise(weights.weight(frame, geo, tolerance, a, b)),
        })
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x + 1 < w {
                push(i, i + 1);
            }
            if y + 1 < h {
                push(i, i + w);
                if eight_connected {
                    if x + 1 < w {
                        push(i, i + w + 1);
                    }
                    if x > 0 {
                        push(i, i + w - 1);
                    }
                }
            }
        }
    }
    counting_sort(scratch, edges);
}

/// Stable counting sort by bin: O(E + bins) instead of O(E log E) on the
/// hot path, and FH only needs the order of the quantised weights.
fn counting_sort(input: &[Edge], output: &mut Vec<Edge>) {
    let mut start = vec![0usize; WEIGHT_BINS + 1];
    for e in input {
        start[e.bin as usize + 1] += 1;
    }
    for b in 0..WEIGHT_BINS {
        start[b + 1] += start[b];
    }
    output.clear();
    output.resize(input.len(), Edge { a: 0, b: 0, bin: 0 });
    for e in input {
        let slot = &mut start[e.bin as usize];
        output[*slot] = *e;
        *slot += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counting_sort_orders_and_is_stable() {
        let input: Vec<Edge> = [5u16, 1, 5, 0, 4095, 1]
            .iter()
            .enumerate()
            .map(|(i, &bin)| Edge {
                a: i as u32,
                b: 0,
                bin,
            })
            .collect();
        let mut out = Vec::new();
        counting_sort(&input, &mut out);
        let order: Vec<u32> = out.iter().map(|e| e.a).collect();
        assert_eq!(order, vec![3, 1, 5, 0, 2, 4]);
    }

    #[test]
    fn quantise_clamps() {
        assert_eq!(quantise(-1.0), 0);
        assert_eq!(quantise(1e9) as usize, WEIGHT_BINS - 1);
        assert!(
            (Edge {
                a: 0,
                b: 1,
                bin: quantise(1.0)
            }
            .weight()
                - 1.0)
                .abs()
                <= BIN_WIDTH
        );
    }
}
