//! Per-segment confidence: boundary contrast against internal variation.

use super::graph::Edge;

/// Contrast (mean edge weight) at which a perfectly homogeneous segment
/// reaches confidence 0.5: weak boundaries are not trusted.
const HALF_CONFIDENCE_CONTRAST: f32 = 0.1;
/// Confidence of a segment with no boundary (it fills the whole frame).
const NO_BOUNDARY_CONFIDENCE: f32 = 0.5;

/// `(mean boundary − mean internal) / (mean boundary + c)`, clamped to [0, 1],
/// per segment; `segment_of` maps each vertex to a segment in `0..count`.
pub fn segment_confidence(edges: &[Edge], segment_of: &[u32], count: usize) -> Vec<f32> {
    // [internal sum, internal n, boundary sum, boundary n] per segment.
    let mut acc = vec![[0.0f64; 4]; count];
    for e in edges {
        let (sa, sb) = (
            segment_of[e.a as usize] as usize,
            segment_of[e.b as usize] as usize,
        );
        let w = e.weight() as f64;
        if sa == sb {
            acc[sa][0] += w;
            acc[sa][1] += 1.0;
        } else {
            for s in [sa, sb] {
                acc[s][2] += w;
                acc[s][3] += 1.0;
            }
        }
    }
    acc.iter()
        .map(|&[is, n_in, bs, n_b]| {
            if n_b == 0.0 {
                return NO_BOUNDARY_CONFIDENCE;
            }
            let internal = if n_in > 0.0 { is / n_in } else { 0.0 } as f32;
            let boundary = (bs / n_b) as f32;
            ((boundary - internal) / (boundary + HALF_CONFIDENCE_CONTRAST)).clamp(0.0, 1.0)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classic::graph::BIN_WIDTH;

    fn edge(a: u32, b: u32, w: f32) -> Edge {
        Edge {
            a,
            b,
            bin: (w / BIN_WIDTH).round() as u16,
        }
    }

    #[test]
    fn strong_boundary_is_confident_weak_is_not() {
        let strong = [edge(0, 1, 0.0), edge(1, 2, 2.0), edge(2, 3, 0.0)];
        let c = segment_confidence(&strong, &[0, 0, 1, 1], 2);
        assert!(c.iter().all(|&c| c > 0.9), "{c:?}");
        let weak = [edge(0, 1, 0.05), edge(1, 2, 0.06), edge(2, 3, 0.05)];
        let c = segment_confidence(&weak, &[0, 0, 1, 1], 2);
        assert!(c.iter().all(|&c| c < 0.1), "{c:?}");
        let single = segment_confidence(&weak, &[0, 0, 0, 0], 1);
        assert_eq!(single, vec![NO_BOUNDARY_CONFIDENCE]);
    }
}
