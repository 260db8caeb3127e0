//! Step 4b: large planar segments that lie in one plane but do not touch in the image are
//! one surface seen around an occluder (the floor on both sides of a table's legs and
//! under its top; a wall behind a chair). They are joined, so the surface keeps one label
//! in every view instead of one per visible piece, which the consensus cannot merge once
//! each piece has its own confident label.
//!
//! ```text
//!   segment s:  n̄ = Σ wᵢ nᵢ / |Σ wᵢ nᵢ|   c̄ = Σ wᵢ cᵢ / Σ wᵢ   (patches i, w = pixels)
//!   planar(s)   ⇔  Σ wᵢ (nᵢ·n̄) / Σ wᵢ ≥ cos(max_angle)
//!                  ∧ √(Σ wᵢ (n̄·(cᵢ − c̄))² / Σ wᵢ) ≤ tol(s)
//!   join(a, b)  ⇔  both large and planar, no boundary between them,
//!                  ∠(n̄a, n̄b) ≤ max_angle, |n̄a·(c̄b − c̄a)| ≤ tol(a), |n̄b·(c̄a − c̄b)| ≤ tol(b)
//!   tol(s)      =  offset_scale · depth of c̄
//! ```
//!
//! Segments that share a boundary were cut there on purpose (a poster on its wall, a
//! flat book on its desk): only pieces with no boundary between them are joined.

use std::collections::HashSet;

use super::convexity::PatchEdge;
use super::patches::PatchStats;
use crate::classic::labels::compact_components;
use crate::classic::union_find::UnionFind;

/// Thresholds of the coplanar join.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoplanarRules {
    /// Smallest segment considered, as a share of the patches' pixels.
    pub min_share: f32,
    /// Largest angle (radians) between normals of one plane.
    pub max_angle: f32,
    /// Plane offset per metre of depth still in one plane.
    pub offset_scale: f32,
}

/// A segment's plane and how well its patches fit it.
#[derive(Debug, Clone, Copy)]
struct Plane {
    normal: [f32; 3],
    centroid: [f32; 3],
    pixels: u32,
    planar: bool,
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

impl CoplanarRules {
    fn tolerance(&self, p: &Plane) -> f32 {
        self.offset_scale * p.centroid[2].abs().max(0.1)
    }

    fn planes(&self, stats: &[PatchStats], segment_of_patch: &[u32], count: usize) -> Vec<Plane> {
        let mut sums = vec![([0.0f64; 3], [0.0f64; 3], 0u64); count];
        for (st, &s) in stats.iter().zip(segment_of_patch) {
            let (n, c, w) = &mut sums[s as usize];
            let pw = f64::from(st.pixels);
            for k in 0..3 {
                n[k] += pw * f64::from(st.normal[k]);
                c[k] += pw * f64::from(st.centroid[k]);
            }
            *w += u64::from(st.pixels);
        }
        let mut planes: Vec<Plane> = sums
            .iter()
            .map(|(n, c, w)| {
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                let w = (*w).max(1) as f64;
                Plane {
                    normal: if len > 0.0 {
                        [
                            (n[0] / len) as f32,
                            (n[1] / len) as f32,
                            (n[2] / len) as f32,
                        ]
                    } else {
                        [0.0; 3]
                    },
                    centroid: [(c[0] / w) as f32, (c[1] / w) as f32, (c[2] / w) as f32],
                    pixels: w as u32,
                    planar: len > 0.0,
                }
            })
            .collect();
        // Fit: mean cosine of the patch normals and RMS offset of the patch centroids.
        let mut fit = vec![(0.0f64, 0.0f64, 0.0f64); count];
        for (st, &s) in stats.iter().zip(segment_of_patch) {
            let p = &planes[s as usize];
            let pw = f64::from(st.pixels);
            let offset = dot(p.normal, sub(st.centroid, p.centroid));
            let f = &mut fit[s as usize];
            f.0 += pw * f64::from(dot(st.normal, p.normal));
            f.1 += pw * f64::from(offset * offset);
            f.2 += pw;
        }
        let min_cos = f64::from(self.max_angle.cos());
        for (p, &(cos, sq, w)) in planes.iter_mut().zip(&fit) {
            let w = w.max(1.0);
            let tol = f64::from(self.tolerance(p));
            p.planar &= cos / w >= min_cos && (sq / w).sqrt() <= tol;
        }
        planes
    }

    /// Joins coplanar segments that share no boundary; returns the new segment of every
    /// patch and the new count (segment ids stay dense, in first-seen order).
    pub fn join(
        &self,
        stats: &[PatchStats],
        edges: &[PatchEdge],
        segment_of_patch: &[u32],
        count: usize,
    ) -> (Vec<u32>, usize) {
        if self.min_share <= 0.0 {
            return (segment_of_patch.to_vec(), count);
        }
        let planes = self.planes(stats, segment_of_patch, count);
        let total: u64 = planes.iter().map(|p| u64::from(p.pixels)).sum();
        let min_pixels = (self.min_share as f64 * total as f64) as u32;
        let large: Vec<usize> = (0..count)
            .filter(|&s| planes[s].planar && planes[s].pixels >= min_pixels.max(1))
            .collect();
        if large.len() < 2 {
            return (segment_of_patch.to_vec(), count);
        }
        let touching: HashSet<(u32, u32)> = edges
            .iter()
            .map(|e| {
                let (a, b) = (
                    segment_of_patch[e.a as usize],
                    segment_of_patch[e.b as usize],
                );
                (a.min(b), a.max(b))
            })
            .collect();
        let min_cos = self.max_angle.cos();
        let mut sets = UnionFind::default();
        sets.reset(count, 0.0);
        for (i, &a) in large.iter().enumerate() {
            for &b in &large[i + 1..] {
                let (pa, pb) = (&planes[a], &planes[b]);
                let key = (a.min(b) as u32, a.max(b) as u32);
                if touching.contains(&key) || dot(pa.normal, pb.normal) < min_cos {
                    continue;
                }
                let gap = sub(pb.centroid, pa.centroid);
                if dot(pa.normal, gap).abs() <= self.tolerance(pa)
                    && dot(pb.normal, gap).abs() <= self.tolerance(pb)
                {
                    sets.union(a as u32, b as u32);
                }
            }
        }
        let (new_of_segment, joined) = compact_components(&mut sets, count);
        (
            segment_of_patch
                .iter()
                .map(|&s| new_of_segment[s as usize])
                .collect(),
            joined,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn patch(pixels: u32, centroid: [f32; 3], normal: [f32; 3]) -> PatchStats {
        PatchStats {
            pixels,
            centroid,
            normal,
            colour: [0.5; 3],
        }
    }

    const RULES: CoplanarRules = CoplanarRules {
        min_share: 0.05,
        max_angle: 0.1,
        offset_scale: 0.012,
    };

    #[test]
    fn pieces_of_one_floor_join_and_a_parallel_table_top_does_not() {
        let up = [0.0, -0.8, -0.6];
        // Floor left (segment 0), floor right (1): one plane through (0, 1.2, 2.0) and
        // (1.0, 1.2 + 0.6·…, …) — built as points on n·x = d.
        let d = dot(up, [0.0, 1.2, 2.0]);
        let on_floor = |x: f32, z: f32| {
            // Solve n·(x, y, z) = d for y.
            let y = (d - up[0] * x - up[2] * z) / up[1];
            [x, y, z]
        };
        let stats = vec![
            patch(400, on_floor(-1.0, 2.0), up),
            patch(400, on_floor(-1.0, 2.4), up),
            patch(400, on_floor(1.0, 2.1), up),
            patch(400, on_floor(1.1, 2.5), up),
            // A table top 0.7 m above the floor, parallel, between the pieces.
            patch(500, [0.0, 0.5, 1.8], up),
            patch(500, [0.2, 0.45, 1.9], up),
        ];
        let segment_of_patch = [0, 0, 1, 1, 2, 2];
        // The table touches both floor pieces (its front edge cuts them); the floor
        // pieces do not touch each other.
        let edges = [
            PatchEdge {
                a: 1,
                b: 4,
                pairs: 8,
                steps: 8,
            },
            PatchEdge {
                a: 2,
                b: 5,
                pairs: 8,
                steps: 8,
            },
        ];
        let (seg, count) = RULES.join(&stats, &edges, &segment_of_patch, 3);
        assert_eq!(count, 2);
        assert_eq!(seg[0], seg[2], "the floor is one segment");
        assert_ne!(seg[0], seg[4], "the table top is not the floor");
    }

    #[test]
    fn touching_coplanar_segments_stay_apart() {
        // A poster on its wall: coplanar, but cut along their shared boundary on purpose.
        let n = [0.0, 0.0, -1.0];
        let stats = vec![
            patch(800, [0.0, 0.0, 3.0], n),
            patch(300, [0.5, 0.2, 2.99], n),
        ];
        let edges = [PatchEdge {
            a: 0,
            b: 1,
            pairs: 20,
            steps: 0,
        }];
        let (seg, count) = RULES.join(&stats, &edges, &[0, 1], 2);
        assert_eq!(count, 2);
        assert_ne!(seg[0], seg[1]);
    }

    #[test]
    fn curved_or_small_segments_are_never_joined() {
        let n = [0.0, 0.0, -1.0];
        let tilted = [0.0, 0.6, -0.8];
        let stats = vec![
            patch(800, [0.0, 0.0, 3.0], n),
            // A ball: its patches' normals disagree, so it has no plane.
            patch(400, [1.0, 0.0, 3.0], n),
            patch(400, [1.2, 0.1, 3.0], tilted),
            // A small coplanar piece (under min_share).
            patch(20, [2.0, 0.0, 3.0], n),
        ];
        let (seg, count) = RULES.join(&stats, &[], &[0, 1, 1, 2], 3);
        assert_eq!(count, 3, "{seg:?}");
    }
}
