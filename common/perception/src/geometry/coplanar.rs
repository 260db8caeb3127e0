//! Step 4b: large planar segments that lie in one plane but do not touch in the image are
//! one surface seen around an occluder (the floor on both sides of a table's legs and
//! under its top; a wall behind a chair). They are joined, so the surface keeps one label
//! in every view instead of one per visible piece, which the consensus cannot merge once
//! each piece has its own confident label.
//!
//! ```text
//!   segment s:  n̄ = Σ wᵢ nᵢ / |Σ wᵢ nᵢ|   c̄ = Σ wᵢ cᵢ / Σ wᵢ   (patches i, w = pixels)
//!   on(i)       ⇔  nᵢ·n̄ ≥ cos(max_angle) ∧ |n̄·(cᵢ − c̄)| ≤ tol(s)
//!   planar(s)   ⇔  Σ_{on(i)} wᵢ ≥ min_inliers · Σ wᵢ;  then n̄, c̄ refitted on the on(i)
//!   join(a, b)  ⇔  both large and planar, no boundary between them,
//!                  ∠(n̄a, n̄b) ≤ max_angle, |n̄a·(c̄b − c̄a)| ≤ tol(a), |n̄b·(c̄a − c̄b)| ≤ tol(b)
//!   tol(s)      =  offset_scale · depth of c̄
//! ```
//!
//! Segments that share a boundary were cut there on purpose (a poster on its wall, a
//! flat book on its desk): only pieces with no boundary between them are joined, and a
//! join never brings two touching segments together through a third.

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
    /// Pixel share of a segment's patches that must lie on its plane for it to be planar.
    pub min_inliers: f32,
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

    /// Pixel-weighted mean normal and centroid of each segment over the patches `keep` admits.
    fn mean_planes(
        stats: &[PatchStats],
        segment_of_patch: &[u32],
        count: usize,
        keep: impl Fn(usize) -> bool,
    ) -> Vec<Plane> {
        let mut sums = vec![([0.0f64; 3], [0.0f64; 3], 0u64); count];
        for (i, (st, &s)) in stats.iter().zip(segment_of_patch).enumerate() {
            if !keep(i) {
                continue;
            }
            let (n, c, w) = &mut sums[s as usize];
            let pw = f64::from(st.pixels);
            for k in 0..3 {
                n[k] += pw * f64::from(st.normal[k]);
                c[k] += pw * f64::from(st.centroid[k]);
            }
            *w += u64::from(st.pixels);
        }
        sums.iter()
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
            .collect()
    }

    fn on_plane(&self, st: &PatchStats, p: &Plane) -> bool {
        let offset = dot(p.normal, sub(st.centroid, p.centroid));
        dot(st.normal, p.normal) >= self.max_angle.cos() && offset.abs() <= self.tolerance(p)
    }

    /// Each segment's plane, fitted on the patches that lie on its all-patch mean plane; planar
    /// when those hold `min_inliers` of its pixels. A share, not a mean, so a few patches
    /// blended across the segment's border neither tilt the plane nor make a flat wall look
    /// curved.
    fn planes(&self, stats: &[PatchStats], segment_of_patch: &[u32], count: usize) -> Vec<Plane> {
        let all = Self::mean_planes(stats, segment_of_patch, count, |_| true);
        let inlier: Vec<bool> = stats
            .iter()
            .zip(segment_of_patch)
            .map(|(st, &s)| self.on_plane(st, &all[s as usize]))
            .collect();
        let mut planes = Self::mean_planes(stats, segment_of_patch, count, |i| inlier[i]);
        for (p, a) in planes.iter_mut().zip(&all) {
            p.planar &= a.planar
                && f64::from(p.pixels) >= f64::from(self.min_inliers) * f64::from(a.pixels.max(1));
            // Size is the whole segment's, not its inliers'.
            p.pixels = a.pixels;
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
        let touch = |a: usize, b: usize| touching.contains(&(a.min(b) as u32, a.max(b) as u32));
        // Groups of `large` segments, joined pairwise; a join never puts two touching
        // segments in one group, not even through a third (a picture on its wall and a piece
        // of that wall behind a bookshelf).
        // Groups of indices into `large`.
        let mut group: Vec<Vec<usize>> = (0..large.len()).map(|k| vec![k]).collect();
        let mut group_of: Vec<usize> = (0..large.len()).collect();
        for i in 0..large.len() {
            for j in i + 1..large.len() {
                let (pa, pb) = (&planes[large[i]], &planes[large[j]]);
                let (ga, gb) = (group_of[i], group_of[j]);
                if ga == gb || dot(pa.normal, pb.normal) < min_cos {
                    continue;
                }
                let gap = sub(pb.centroid, pa.centroid);
                let coplanar = dot(pa.normal, gap).abs() <= self.tolerance(pa)
                    && dot(pb.normal, gap).abs() <= self.tolerance(pb);
                let touches = group[ga]
                    .iter()
                    .any(|&x| group[gb].iter().any(|&y| touch(large[x], large[y])));
                if !coplanar || touches {
                    continue;
                }
                let moved = std::mem::take(&mut group[gb]);
                for &k in &moved {
                    group_of[k] = ga;
                }
                group[ga].extend(moved);
            }
        }
        let mut sets = UnionFind::default();
        sets.reset(count, 0.0);
        for members in &group {
            for pair in members.windows(2) {
                sets.union(large[pair[0]] as u32, large[pair[1]] as u32);
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
        min_inliers: 0.9,
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
    fn a_wall_with_a_patch_blended_across_its_border_is_still_planar() {
        // Two pieces of one wall either side of a bookshelf, 12 patches each; one patch of
        // each straddles the wall's border and has a normal bent by 0.5 rad. The mean cosine
        // (0.990) would call the wall curved; 11 of 12 patches (92 %) lie on its plane.
        let n = [0.0, 0.0, -1.0];
        let bent = [0.479, 0.0, -0.878];
        let mut stats = Vec::new();
        let mut segment_of_patch = Vec::new();
        for (segment, x0) in [(0u32, -2.0f32), (1, 1.0)] {
            for i in 0..12 {
                let normal = if i == 0 { bent } else { n };
                stats.push(patch(300, [x0 + 0.1 * i as f32, 0.0, 3.5], normal));
                segment_of_patch.push(segment);
            }
        }
        let (seg, count) = RULES.join(&stats, &[], &segment_of_patch, 2);
        assert_eq!(count, 1, "{seg:?}");
        let strict = CoplanarRules {
            min_inliers: 1.0,
            ..RULES
        };
        let (_, count) = strict.join(&stats, &[], &segment_of_patch, 2);
        assert_eq!(
            count, 2,
            "with every patch required on the plane the pieces stay apart"
        );
    }

    #[test]
    fn a_picture_stays_apart_from_its_wall_through_another_piece_of_that_wall() {
        // Wall left (0) with a picture (1) on it, wall right (2) behind a bookshelf: 0–2 and
        // 1–2 may join (no boundary), 0–1 touch. The picture must not reach the left wall
        // through the right one.
        let n = [0.0, 0.0, -1.0];
        let stats = vec![
            patch(800, [-1.5, 0.0, 3.5], n),
            patch(300, [-1.2, -0.3, 3.49], n),
            patch(800, [1.5, 0.0, 3.5], n),
        ];
        let edges = [PatchEdge {
            a: 0,
            b: 1,
            pairs: 20,
            steps: 0,
        }];
        let (seg, count) = RULES.join(&stats, &edges, &[0, 1, 2], 3);
        assert_eq!(count, 2, "{seg:?}");
        assert_eq!(seg[0], seg[2], "the wall is one segment");
        assert_ne!(seg[1], seg[0], "the picture is apart");
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
