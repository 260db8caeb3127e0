//! From boundary verdicts to segments: union of patches across joined
//! boundaries, small pieces into their weakest-bounded neighbour, holes
//! without depth into the surface around them, confidence from the
//! boundary evidence.

use super::convexity::{PatchEdge, Verdict};
use super::patches::NO_PATCH;
use crate::classic::labels::compact_components;
use crate::classic::union_find::UnionFind;

/// Segment index of a coarse pixel that belongs to no segment (label 0).
pub const NO_SEGMENT: u32 = u32::MAX;

/// Confidence of a segment with no boundary (it fills the whole frame).
const NO_BOUNDARY_CONFIDENCE: f32 = 0.5;

/// Joins patches across non-cut boundaries, then absorbs segments under
/// `min_pixels` across their weakest boundary; returns the compact segment
/// index per patch and the segment count.
pub fn merge_patches(
    edges: &[PatchEdge],
    verdicts: &[Verdict],
    patch_pixels: &[u32],
    min_pixels: u32,
    sets: &mut UnionFind,
) -> (Vec<u32>, usize) {
    sets.reset(patch_pixels.len(), 0.0);
    let mut pixels = patch_pixels.to_vec();
    let join = |sets: &mut UnionFind, pixels: &mut Vec<u32>, a: u32, b: u32| {
        let (ra, rb) = (sets.find(a), sets.find(b));
        if ra != rb {
            let total = pixels[ra as usize] + pixels[rb as usize];
            let root = sets.union(ra, rb);
            pixels[root as usize] = total;
        }
    };
    for (e, v) in edges.iter().zip(verdicts) {
        if !v.cut {
            join(sets, &mut pixels, e.a, e.b);
        }
    }
    // Weakest evidence first, so a fragment joins the surface it is least
    // separated from (a crease sliver, a noisy corner).
    let mut order: Vec<usize> = (0..edges.len()).filter(|&i| verdicts[i].cut).collect();
    order.sort_unstable_by(|&i, &j| verdicts[i].evidence.total_cmp(&verdicts[j].evidence));
    for i in order {
        let (ra, rb) = (sets.find(edges[i].a), sets.find(edges[i].b));
        if ra != rb && (pixels[ra as usize] < min_pixels || pixels[rb as usize] < min_pixels) {
            join(sets, &mut pixels, ra, rb);
        }
    }
    let mut index_of_root = vec![NO_SEGMENT; patch_pixels.len()];
    let mut count = 0u32;
    let segment_of_patch = (0..patch_pixels.len() as u32)
        .map(|p| {
            let root = sets.find(p) as usize;
            if index_of_root[root] == NO_SEGMENT {
                index_of_root[root] = count;
                count += 1;
            }
            index_of_root[root]
        })
        .collect();
    (segment_of_patch, count as usize)
}

/// The segment of every patch after segments were joined in `sets` (one set per segment):
/// ids stay dense, in first-seen order; returns them and the new count.
pub fn regroup(sets: &mut UnionFind, segment_of_patch: &[u32], count: usize) -> (Vec<u32>, usize) {
    let (new_of_segment, joined) = compact_components(sets, count);
    (
        segment_of_patch
            .iter()
            .map(|&s| new_of_segment[s as usize])
            .collect(),
        joined,
    )
}

/// Boundary-length-weighted mean evidence of each segment's cut boundaries.
pub fn segment_confidence(
    edges: &[PatchEdge],
    verdicts: &[Verdict],
    segment_of_patch: &[u32],
    count: usize,
) -> Vec<f32> {
    let mut acc = vec![(0.0f64, 0u64); count];
    for (e, v) in edges.iter().zip(verdicts) {
        let (sa, sb) = (
            segment_of_patch[e.a as usize],
            segment_of_patch[e.b as usize],
        );
        if sa == sb {
            continue;
        }
        for s in [sa, sb] {
            acc[s as usize].0 += v.evidence as f64 * e.pairs as f64;
            acc[s as usize].1 += e.pairs as u64;
        }
    }
    acc.iter()
        .map(|&(sum, n)| {
            if n == 0 {
                NO_BOUNDARY_CONFIDENCE
            } else {
                (sum / n as f64).clamp(0.0, 1.0) as f32
            }
        })
        .collect()
}

/// Per segment, the depth (m) that `quantile` of its pixels with depth lie nearer than
/// (0 for a segment without depth): how near the camera saw the object.
pub fn near_depth(segments: &[u32], depth_m: &[f32], count: usize, quantile: f32) -> Vec<f32> {
    let mut depths: Vec<Vec<f32>> = vec![Vec::new(); count];
    for (&s, &z) in segments.iter().zip(depth_m) {
        if (s as usize) < count && z > 0.0 && z.is_finite() {
            depths[s as usize].push(z);
        }
    }
    depths
        .iter_mut()
        .map(|d| {
            if d.is_empty() {
                return 0.0;
            }
            let k = ((d.len() - 1) as f32 * quantile.clamp(0.0, 1.0)) as usize;
            *d.select_nth_unstable_by(k, f32::total_cmp).1
        })
        .collect()
}

/// Segment per coarse pixel; each 4-connected hole (no depth) bordered by
/// one segment only takes it, other holes stay `NO_SEGMENT`.
pub fn paint_and_fill_holes(patch_of: &[u32], segment_of_patch: &[u32], width: usize) -> Vec<u32> {
    let mut out: Vec<u32> = patch_of
        .iter()
        .map(|&p| {
            if p == NO_PATCH {
                NO_SEGMENT
            } else {
                segment_of_patch[p as usize]
            }
        })
        .collect();
    let n = out.len();
    let mut visited = vec![false; n];
    let (mut hole, mut stack) = (Vec::new(), Vec::new());
    for seed in 0..n {
        if visited[seed] || out[seed] != NO_SEGMENT {
            continue;
        }
        // One hole, and the single segment around it (None if several).
        let mut border: Option<Option<u32>> = None;
        hole.clear();
        visited[seed] = true;
        stack.push(seed);
        while let Some(i) = stack.pop() {
            hole.push(i);
            let x = i % width;
            let neighbours = [
                (x > 0).then(|| i - 1),
                (x + 1 < width).then(|| i + 1),
                i.checked_sub(width),
                (i + width < n).then(|| i + width),
            ];
            for j in neighbours.into_iter().flatten() {
                let s = out[j];
                if s == NO_SEGMENT {
                    if !visited[j] {
                        visited[j] = true;
                        stack.push(j);
                    }
                } else {
                    border = match border {
                        None => Some(Some(s)),
                        Some(Some(t)) if t == s => Some(Some(t)),
                        _ => Some(None),
                    };
                }
            }
        }
        if let Some(Some(s)) = border {
            for &i in &hole {
                out[i] = s;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn verdict(cut: bool, evidence: f32) -> Verdict {
        Verdict { cut, evidence }
    }

    fn edge(a: u32, b: u32) -> PatchEdge {
        PatchEdge {
            a,
            b,
            pairs: 4,
            steps: 0,
        }
    }

    #[test]
    fn joins_uncut_and_absorbs_small_fragments() {
        // 0-1 joined; 1|2 cut strongly; 2|3 cut weakly and 3 is tiny.
        let edges = [edge(0, 1), edge(1, 2), edge(2, 3), edge(1, 3)];
        let verdicts = [
            verdict(false, 0.0),
            verdict(true, 1.0),
            verdict(true, 0.3),
            verdict(true, 0.9),
        ];
        let mut sets = UnionFind::default();
        let (seg, count) = merge_patches(&edges, &verdicts, &[50, 50, 80, 5], 20, &mut sets);
        assert_eq!(count, 2);
        assert_eq!(seg[0], seg[1]);
        assert_eq!(seg[2], seg[3], "tiny patch joins its weakest neighbour");
        assert_ne!(seg[0], seg[2]);
        let conf = segment_confidence(&edges, &verdicts, &seg, count);
        assert!(conf.iter().all(|&c| c > 0.9), "{conf:?}");
    }

    #[test]
    fn near_depth_is_the_quantile_of_each_segments_depths() {
        // Segment 0: 1..=10 m; segment 1: 2 m and one pixel without depth; segment 2: no pixel.
        let mut segments = vec![0u32; 10];
        let mut depth: Vec<f32> = (1..=10).map(|z| z as f32).collect();
        segments.extend([1, 1, NO_SEGMENT]);
        depth.extend([2.0, 0.0, 7.0]);
        let near = near_depth(&segments, &depth, 3, 0.1);
        assert_eq!(near, vec![1.0, 2.0, 0.0]);
        assert_eq!(near_depth(&segments, &depth, 3, 0.5)[0], 5.0);
    }

    #[test]
    fn holes_take_the_single_surrounding_segment() {
        // 5x3: segment 0 left, 1 right; a hole inside 0 and one between.
        let p = NO_PATCH;
        let patch_of = [0, 0, p, 1, 1, 0, p, 0, 1, 1, 0, 0, 0, 1, 1];
        let filled = paint_and_fill_holes(&patch_of, &[0, 1], 5);
        assert_eq!(filled[6], 0, "enclosed hole");
        assert_eq!(filled[2], NO_SEGMENT, "hole between two segments");
        let all_missing = paint_and_fill_holes(&[p; 6], &[], 3);
        assert!(all_missing.iter().all(|&s| s == NO_SEGMENT));
    }
}
