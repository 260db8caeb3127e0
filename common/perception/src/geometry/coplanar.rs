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
//!   join(a, b)  ⇔  both planar pieces, at least one of them large, no boundary between them,
//!                  ∠(n̄a, n̄b) ≤ max_angle, |n̄a·(c̄b − c̄a)| ≤ tol(a), |n̄b·(c̄a − c̄b)| ≤ tol(b)
//!   tol(s)      =  offset_scale · depth of c̄
//!   large(s)    ⇔  |s| ≥ min_share · frame;  piece(s) ⇔ |s| ≥ piece_share · frame
//! ```
//!
//! A small piece joins only a group that holds a large segment, never another small piece
//! alone: a floor seen between chairs and table legs comes in pieces of 0.5–5 % of the frame
//! (scene 6: 4.8, 2.9, 1.1, 0.8 % beside one of 5.6 %), while two small coplanar faces
//! apart from each other are as often two objects (the fronts of two boxes side by side).
//! A piece must also have the colour of the segment it joins, up to shading
//! ([`same_colour`](super::colour::same_colour)): the back of a bookshelf seen between its boards lies in its wall's
//! plane, 1–2 cm proud, but is another material (the built-in room: brown against grey,
//! chromaticity 0.2 apart; floor pieces measured 0.001–0.01 apart, 0.8–1.2× as bright).
//! Pairs are taken largest first, so the pieces of a wall join before a picture on it can
//! reach one of them.
//!
//! Segments that share a boundary were cut there on purpose (a poster on its wall, a
//! flat book on its desk): only pieces with no boundary between them are joined, and a
//! join never brings two touching segments together through a third.

use std::collections::HashSet;

use opengs_geometry::nalgebra::{Matrix3, Vector3};

use super::colour::{mean_colours, same_colour};
use super::convexity::PatchEdge;
use super::patches::PatchStats;
use super::regions::regroup;
use crate::classic::union_find::UnionFind;

/// Thresholds of the coplanar join.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoplanarRules {
    /// Smallest large segment, as a share of the patches' pixels.
    pub min_share: f32,
    /// Smallest piece that may join a group holding a large segment (same unit).
    pub piece_share: f32,
    /// Largest angle (radians) between normals of one plane.
    pub max_angle: f32,
    /// Plane offset per metre of depth still in one plane.
    pub offset_scale: f32,
    /// Pixel share of a segment's patches that must lie on its plane for it to be planar.
    pub min_inliers: f32,
    /// How far a patch's normal strays from its plane under the frame's depth noise, in
    /// radians per metre of depth for a patch one coarse pixel wide (σ(z) over the patch's
    /// width, √pixels); a patch's angle allowance is the larger of that and `max_angle`
    /// (Kinect-like noise: 10° at 3.4 m for a full patch, so a flat wall would otherwise
    /// count as curved and the floor around a table stay in pieces).
    pub normal_noise: f32,
}

/// Refits of a segment's plane on its inliers after the first: with depth noise the first
/// plane, through every patch, leans with the pixel normals and leaves the far end of a
/// floor off it; fitted again on the patches it keeps, it comes back to the floor.
const PLANE_REFITS: usize = 2;

/// Steps of the dominant-face start of [`CoplanarRules::dominant_planes`] …
const DOMINANT_STEPS: usize = 3;
/// … and the angle of the patches each step averages: of two faces at right angles the larger
/// is always within 45° of their mean.
const DOMINANT_ANGLE: f32 = std::f32::consts::FRAC_PI_4;

/// The angle allowance never exceeds this (radians): a noisy frame must not make a box's
/// faces one plane.
const FLAT_LIMIT: f32 = 0.5;

/// A segment's plane and how well its patches fit it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Plane {
    /// Unit normal, facing the camera.
    pub normal: [f32; 3],
    pub centroid: [f32; 3],
    /// The whole segment's pixels.
    pub pixels: u32,
    /// Of those, the pixels of the patches the plane was fitted on.
    pub inliers: u32,
    pub planar: bool,
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// The normal of the plane through a segment's patch centroids (least eigenvector of their
/// spread), turned to agree with `mean_normal`; `None` when the centroids do not span a
/// plane (a strip, one patch) or it leans more than `FLAT_LIMIT` from the mean normal.
/// Depth noise runs along the rays and tilts averaged pixel normals by a few hundredths of
/// a radian, which over a floor 3 m deep puts its far end off its own plane; the centroids
/// average it out.
fn centroid_normal(spread: &Matrix3<f64>, mean_normal: [f32; 3]) -> Option<[f32; 3]> {
    let eigen = spread.symmetric_eigen();
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
    let (least, middle) = (eigen.eigenvalues[order[0]], eigen.eigenvalues[order[1]]);
    if !(middle > MIN_SPREAD && least < SPAN_RATIO * middle) {
        return None;
    }
    let v = eigen.eigenvectors.column(order[0]);
    let mean = Vector3::from(mean_normal.map(f64::from));
    let cos = v.dot(&mean);
    if cos.abs() < f64::from(FLAT_LIMIT.cos()) {
        return None;
    }
    let n = v * cos.signum();
    Some([n[0] as f32, n[1] as f32, n[2] as f32])
}

/// Least over middle eigenvalue of the centroid spread below which the centroids span a plane …
const SPAN_RATIO: f64 = 0.1;
/// … whose middle eigenvalue (m², pixel-weighted mean) is at least this: centroids spread
/// 2 cm or more both ways, not a line.
const MIN_SPREAD: f64 = 0.02 * 0.02;

/// Signed distance of a patch's centroid from a plane, positive on the camera's side.
pub(super) fn plane_offset(st: &PatchStats, p: &Plane) -> f32 {
    dot(p.normal, sub(st.centroid, p.centroid))
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
                    inliers: w as u32,
                    planar: len > 0.0,
                }
            })
            .collect();
        // Spread of the patch centroids about each segment's centroid (pixel-weighted).
        let mut spread = vec![Matrix3::<f64>::zeros(); count];
        for (i, (st, &s)) in stats.iter().zip(segment_of_patch).enumerate() {
            if !keep(i) {
                continue;
            }
            let p = &planes[s as usize];
            let d = Vector3::from(sub(st.centroid, p.centroid).map(f64::from));
            spread[s as usize] += d * d.transpose() * f64::from(st.pixels);
        }
        for (p, m) in planes.iter_mut().zip(&spread) {
            if let Some(n) = centroid_normal(&(m / f64::from(p.pixels.max(1))), p.normal) {
                p.normal = n;
            }
        }
        planes
    }

    fn on_plane(&self, st: &PatchStats, p: &Plane) -> bool {
        self.parallel(st, p) && plane_offset(st, p).abs() <= self.tolerance(p)
    }

    /// Whether a patch's normal lies along the plane's, within `max_angle` or what the
    /// frame's depth noise bends a patch of its size and depth by.
    pub(super) fn parallel(&self, st: &PatchStats, p: &Plane) -> bool {
        let width = (st.pixels.max(1) as f32).sqrt();
        let allowance = self
            .max_angle
            .max(self.normal_noise * st.centroid[2].abs() / width);
        dot(st.normal, p.normal) >= allowance.min(FLAT_LIMIT).cos()
    }

    /// Each segment's plane, fitted on the patches that lie on its all-patch mean plane; planar
    /// when those hold `min_inliers` of its pixels. A share, not a mean, so a few patches
    /// blended across the segment's border neither tilt the plane nor make a flat wall look
    /// curved.
    pub(super) fn planes(
        &self,
        stats: &[PatchStats],
        segment_of_patch: &[u32],
        count: usize,
    ) -> Vec<Plane> {
        self.fit(stats, segment_of_patch, count, 0)
    }

    /// [`Self::planes`] started from each segment's dominant face instead of its mean: the
    /// mean normal moved `DOMINANT_STEPS` times to the mean of the patches within
    /// `DOMINANT_ANGLE` of it. A desk seen with its legs has a mean normal tilted off its top by
    /// the legs, far enough that no patch of the top lies on the mean plane; the top is what
    /// things lie on.
    pub(super) fn dominant_planes(
        &self,
        stats: &[PatchStats],
        segment_of_patch: &[u32],
        count: usize,
    ) -> Vec<Plane> {
        self.fit(stats, segment_of_patch, count, DOMINANT_STEPS)
    }

    /// The mean plane of each segment, moved `dominant_steps` times towards its dominant face,
    /// then refitted on its inliers.
    fn fit(
        &self,
        stats: &[PatchStats],
        segment_of_patch: &[u32],
        count: usize,
        dominant_steps: usize,
    ) -> Vec<Plane> {
        let all = Self::mean_planes(stats, segment_of_patch, count, |_| true);
        let mut start = all.clone();
        for _ in 0..dominant_steps {
            let near: Vec<bool> = stats
                .iter()
                .zip(segment_of_patch)
                .map(|(st, &s)| dot(st.normal, start[s as usize].normal) >= DOMINANT_ANGLE.cos())
                .collect();
            let moved = Self::mean_planes(stats, segment_of_patch, count, |i| near[i]);
            for (old, new) in start.iter_mut().zip(moved) {
                // A segment with no patch near its mean (none dominates) keeps the mean.
                if new.planar {
                    *old = new;
                }
            }
        }
        self.refit(stats, segment_of_patch, count, start, &all)
    }

    /// Refits `planes` on their inliers (`PLANE_REFITS` + 1 times) and marks each planar when
    /// its inliers hold `min_inliers` of `all`'s pixels.
    fn refit(
        &self,
        stats: &[PatchStats],
        segment_of_patch: &[u32],
        count: usize,
        mut planes: Vec<Plane>,
        all: &[Plane],
    ) -> Vec<Plane> {
        for _ in 0..=PLANE_REFITS {
            let inlier: Vec<bool> = stats
                .iter()
                .zip(segment_of_patch)
                .map(|(st, &s)| self.on_plane(st, &planes[s as usize]))
                .collect();
            planes = Self::mean_planes(stats, segment_of_patch, count, |i| inlier[i]);
        }
        for (p, a) in planes.iter_mut().zip(all) {
            p.planar &= a.planar
                && f64::from(p.pixels) >= f64::from(self.min_inliers) * f64::from(a.pixels.max(1));
            // Size is the whole segment's, not its inliers'.
            p.inliers = p.pixels;
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
        let min_pixels = ((self.min_share as f64 * total as f64) as u32).max(1);
        let piece_pixels =
            ((self.piece_share.min(self.min_share) as f64 * total as f64) as u32).max(1);
        // Planar segments of at least a piece's size, largest first: pairs are then tried large–large before large–small.
        let mut candidates: Vec<usize> = (0..count)
            .filter(|&s| planes[s].planar && planes[s].pixels >= piece_pixels)
            .collect();
        candidates.sort_by_key(|&s| (std::cmp::Reverse(planes[s].pixels), s));
        if candidates.len() < 2 || planes[candidates[0]].pixels < min_pixels {
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
        let colours = mean_colours(stats, segment_of_patch, count);
        let min_cos = self.max_angle.cos();
        let touch = |a: usize, b: usize| touching.contains(&(a.min(b) as u32, a.max(b) as u32));
        // Groups of indices into `candidates`, joined pairwise; a join never puts two touching
        // segments in one group, not even through a third (a picture on its wall and a piece
        // of that wall behind a bookshelf), and a group without a candidates segment joins only
        // one with.
        let mut group: Vec<Vec<usize>> = (0..candidates.len()).map(|k| vec![k]).collect();
        let mut group_of: Vec<usize> = (0..candidates.len()).collect();
        let mut anchored: Vec<bool> = candidates
            .iter()
            .map(|&s| planes[s].pixels >= min_pixels)
            .collect();
        for i in 0..candidates.len() {
            for j in i + 1..candidates.len() {
                let (pa, pb) = (&planes[candidates[i]], &planes[candidates[j]]);
                let (ga, gb) = (group_of[i], group_of[j]);
                if ga == gb
                    || !(anchored[ga] || anchored[gb])
                    || dot(pa.normal, pb.normal) < min_cos
                {
                    continue;
                }
                let gap = sub(pb.centroid, pa.centroid);
                let coplanar = dot(pa.normal, gap).abs() <= self.tolerance(pa)
                    && dot(pb.normal, gap).abs() <= self.tolerance(pb);
                let touches = group[ga].iter().any(|&x| {
                    group[gb]
                        .iter()
                        .any(|&y| touch(candidates[x], candidates[y]))
                });
                // `candidates` runs largest first: b is the smaller, a piece when under min_pixels.
                let foreign_piece = pb.pixels < min_pixels
                    && !same_colour(colours[candidates[i]], colours[candidates[j]]);
                if !coplanar || touches || foreign_piece {
                    continue;
                }
                let moved = std::mem::take(&mut group[gb]);
                for &k in &moved {
                    group_of[k] = ga;
                }
                group[ga].extend(moved);
                anchored[ga] |= anchored[gb];
            }
        }
        let mut sets = UnionFind::default();
        sets.reset(count, 0.0);
        for members in &group {
            for pair in members.windows(2) {
                sets.join(candidates[pair[0]] as u32, candidates[pair[1]] as u32);
            }
        }
        regroup(&mut sets, segment_of_patch, count)
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
        piece_share: 0.05,
        max_angle: 0.1,
        offset_scale: 0.012,
        min_inliers: 0.9,
        normal_noise: 0.0,
    };

    /// A desk top (normal up, y = 0.75, 3 × 4 patches of 100 px) with two legs (normal towards
    /// the camera, 5 patches of 100 px each, 30 % of the segment) in one segment.
    fn desk_with_legs() -> Vec<PatchStats> {
        let up = [0.0, -1.0, 0.0];
        let front = [0.0, 0.0, -1.0];
        let mut stats = Vec::new();
        for i in 0..3 {
            for j in 0..4 {
                stats.push(patch(
                    100,
                    [-0.3 + 0.3 * i as f32, -0.45, 1.6 + 0.1 * j as f32],
                    up,
                ));
            }
        }
        for x in [-0.4, 0.4] {
            for k in 0..5 {
                stats.push(patch(100, [x, -0.3 + 0.15 * k as f32, 1.55], front));
            }
        }
        stats
    }

    #[test]
    fn a_desk_with_its_legs_is_planar_from_its_dominant_face_not_from_its_mean() {
        let stats = desk_with_legs();
        let seg = vec![0; stats.len()];
        let rules = CoplanarRules {
            min_inliers: 0.5,
            ..RULES
        };
        // The mean normal leans 37° towards the legs: no patch of the top lies on it.
        let mean = rules.planes(&stats, &seg, 1)[0];
        assert!(!mean.planar, "{mean:?}");
        let dominant = rules.dominant_planes(&stats, &seg, 1)[0];
        assert!(dominant.planar, "{dominant:?}");
        assert_eq!((dominant.inliers, dominant.pixels), (1200, 2200));
        assert!(
            dot(dominant.normal, [0.0, -1.0, 0.0]) > 0.999,
            "{dominant:?}"
        );
        assert!((dominant.centroid[1] + 0.45).abs() < 1e-4, "{dominant:?}");
    }

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

    /// Two pieces of one plane facing the camera at depth `z`, `per_piece` patches each, the
    /// first patch of each with its normal bent by 0.5 rad.
    fn two_pieces_one_patch_bent(per_piece: usize, z: f32) -> (Vec<PatchStats>, Vec<u32>) {
        let n = [0.0, 0.0, -1.0];
        let bent = [0.479, 0.0, -0.878];
        let mut stats = Vec::new();
        let mut segment_of_patch = Vec::new();
        for (segment, x0) in [(0u32, -2.0f32), (1, 1.0)] {
            for i in 0..per_piece {
                let normal = if i == 0 { bent } else { n };
                stats.push(patch(300, [x0 + 0.1 * i as f32, 0.0, z], normal));
                segment_of_patch.push(segment);
            }
        }
        (stats, segment_of_patch)
    }

    #[test]
    fn a_wall_with_a_patch_blended_across_its_border_is_still_planar() {
        // Two pieces of one wall either side of a bookshelf, 12 patches each; one patch of
        // each straddles the wall's border and has a normal bent by 0.5 rad. The mean cosine
        // (0.990) would call the wall curved; 11 of 12 patches (92 %) lie on its plane.
        let (stats, segment_of_patch) = two_pieces_one_patch_bent(12, 3.5);
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
    fn a_noisy_floor_with_a_ninth_of_its_patches_bent_is_planar_by_default() {
        // The floor either side of a table leg with Kinect-like noise (scene 5, 3 m): 89 % of
        // its pixels face like its plane, the patches along the leg's edges do not. Required
        // 90 % of them, the two pieces stayed two floor labels in the map.
        let (stats, segment_of_patch) = two_pieces_one_patch_bent(9, 3.0);
        let default = CoplanarRules {
            min_inliers: super::super::GeometryParams::default().coplanar_inliers,
            ..RULES
        };
        let (_, count) = default.join(&stats, &[], &segment_of_patch, 2);
        assert_eq!(count, 1);
        let (_, count) = RULES.join(&stats, &[], &segment_of_patch, 2);
        assert_eq!(count, 2, "at 90 % the pieces are not planar");
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

    #[test]
    fn small_floor_pieces_join_the_large_floor_but_two_small_faces_stay_apart() {
        // Floor (segment 0, 2000 px) and two floor pieces between table legs (1, 2: 80 px
        // each, 3 % of the frame), on y = 1.2; two box fronts side by side 0.3 m apart
        // (3, 4: 80 px each), coplanar with each other, facing the camera. Nothing touches.
        let up = [0.0, -1.0, 0.0];
        let front = [0.0, 0.0, -1.0];
        let mut stats = Vec::new();
        let mut segment_of_patch = Vec::new();
        let mut add = |segment: u32, pixels: u32, centroid: [f32; 3], normal: [f32; 3]| {
            stats.push(patch(pixels, centroid, normal));
            segment_of_patch.push(segment);
        };
        for i in 0..20 {
            let (col, row) = ((i % 5) as f32, (i / 5) as f32);
            add(0, 100, [-1.0 + 0.4 * col, 1.2, 1.5 + 0.5 * row], up);
        }
        for (segment, x) in [(1u32, -0.2f32), (2, 0.3)] {
            for (dx, dz) in [(0.0, 0.0), (0.1, 0.0), (0.0, 0.1), (0.1, 0.1)] {
                add(segment, 20, [x + dx, 1.2, 2.5 + dz], up);
            }
        }
        for (segment, x) in [(3u32, -0.5f32), (4, 0.1)] {
            for (dx, dy) in [(0.0, 0.0), (0.1, 0.0), (0.0, 0.1), (0.1, 0.1)] {
                add(segment, 20, [x + dx, 0.5 + dy, 2.0], front);
            }
        }
        let pieces = CoplanarRules {
            piece_share: 0.01,
            ..RULES
        };
        let (seg, count) = pieces.join(&stats, &[], &segment_of_patch, 5);
        let first = |segment: u32| {
            seg[segment_of_patch
                .iter()
                .position(|&s| s == segment)
                .expect("segment has patches")]
        };
        assert_eq!(count, 3, "{seg:?}");
        assert_eq!(first(0), first(1), "a floor piece joins the floor");
        assert_eq!(first(0), first(2), "a floor piece joins the floor");
        assert_ne!(
            first(3),
            first(4),
            "two small faces without a large one stay apart"
        );
        // Pieces under `piece_share` stay as they are.
        let (_, count) = RULES.join(&stats, &[], &segment_of_patch, 5);
        assert_eq!(count, 5);
    }

    #[test]
    fn a_piece_joins_only_in_its_surfaces_colour_up_to_shading() {
        // Grey wall (segment 0) 3.5 m away; pieces of the same plane that touch nothing:
        // the wall behind a lamp, in shadow (1: the same grey at 0.6× the brightness), and
        // the back of a bookshelf 1 cm proud, seen between its boards (2: brown, the built-in
        // room's colours).
        let n = [0.0, 0.0, -1.0];
        let grey = [0.588, 0.607, 0.590];
        let mut stats = Vec::new();
        let mut segment_of_patch = Vec::new();
        for i in 0..20 {
            let mut p = patch(
                100,
                [-1.5 + 0.15 * i as f32, -0.5 + 0.05 * (i % 4) as f32, 3.5],
                n,
            );
            p.colour = grey;
            stats.push(p);
            segment_of_patch.push(0);
        }
        for (segment, x, colour) in [
            (1u32, 1.8f32, grey.map(|c| 0.6 * c)),
            (2, 1.0, [0.375, 0.230, 0.147]),
        ] {
            for (dx, dy) in [(0.0, 0.0), (0.1, 0.0), (0.0, 0.1), (0.1, 0.1)] {
                let mut p = patch(25, [x + dx, 0.5 + dy, 3.49], n);
                p.colour = colour;
                stats.push(p);
                segment_of_patch.push(segment);
            }
        }
        let pieces = CoplanarRules {
            piece_share: 0.01,
            ..RULES
        };
        let (seg, count) = pieces.join(&stats, &[], &segment_of_patch, 3);
        assert_eq!(count, 2, "{seg:?}");
        assert_eq!(seg[0], seg[20], "the shaded wall joins the wall");
        assert_ne!(seg[0], seg[24], "the bookshelf's back stays apart");
    }

    #[test]
    fn the_pieces_of_a_wall_join_before_a_picture_on_it_reaches_one() {
        // Picture (segment 0) on the left wall (2), which it touches; right wall (1) behind a
        // bookshelf. Taken in id order the picture would join the right wall first and
        // leave the wall in two; taken largest first the wall joins, the picture stays out.
        let n = [0.0, 0.0, -1.0];
        let stats = vec![
            patch(300, [-1.2, -0.3, 3.49], n),
            patch(800, [1.5, 0.0, 3.5], n),
            patch(900, [-1.5, 0.0, 3.5], n),
        ];
        let edges = [PatchEdge {
            a: 0,
            b: 2,
            pairs: 20,
            steps: 0,
        }];
        let (seg, count) = RULES.join(&stats, &edges, &[0, 1, 2], 3);
        assert_eq!(count, 2, "{seg:?}");
        assert_eq!(seg[1], seg[2], "the wall is one segment");
        assert_ne!(seg[0], seg[1], "the picture is apart");
    }

    /// Two floor pieces either side of a table, patches from 1.5 to 4 m deep on y = 1.2,
    /// `per_piece` patches each, with normals `normal_of(i)`.
    fn floor_pieces(per_piece: usize, normal_of: impl Fn(usize) -> [f32; 3]) -> Vec<PatchStats> {
        let mut stats = Vec::new();
        for x in [-1.2f32, 0.8] {
            for i in 0..per_piece {
                let (col, row) = ((i % 4) as f32, (i / 4) as f32);
                let z = 1.5 + 2.5 * row / ((per_piece / 4 - 1).max(1) as f32);
                stats.push(patch(64, [x + 0.1 * col, 1.2, z], normal_of(i)));
            }
        }
        stats
    }

    #[test]
    fn floor_pieces_whose_normals_lean_toward_the_camera_join_through_their_centroids() {
        // Depth noise along the rays leans the averaged normals 0.04 rad toward the camera:
        // a plane from the mean normal misses the far patches by 5 cm (1.25 m × 0.04) against
        // a 3.3 cm allowance, so the pieces would not be planar; the centroids lie on y = 1.2.
        let (c, s) = (0.04f32.cos(), 0.04f32.sin());
        let stats = floor_pieces(24, |_| [0.0, -c, -s]);
        let segment_of_patch: Vec<u32> = (0..48).map(|i| u32::from(i >= 24)).collect();
        let planes = RULES.planes(&stats, &segment_of_patch, 2);
        for p in &planes {
            assert!(p.planar, "{p:?}");
            assert!(dot(p.normal, [0.0, -1.0, 0.0]) > 0.9999, "{p:?}");
        }
        let (_, count) = RULES.join(&stats, &[], &segment_of_patch, 2);
        assert_eq!(count, 1, "one floor");
    }

    #[test]
    fn a_noisy_floor_with_stray_patches_is_planar_after_refitting_on_its_inliers() {
        // One floor piece (24 patches, 1.5–4 m deep on y = 1.2) whose pixel normals lean
        // 0.04 rad toward the camera, plus three stray patches of a chair leg 0.6 m above it
        // (90 px, 5.5 %). The strays keep the centroids of all patches from spanning a plane,
        // so the first plane takes the leaning mean normal and misses the far patches; refit
        // on the patches near the centroid it is the floor, and 94 % of the pixels lie on it.
        let (c, s) = (0.04f32.cos(), 0.04f32.sin());
        let mut stats = floor_pieces(24, |_| [0.0, -c, -s]);
        stats.truncate(24);
        for k in 0..3 {
            stats.push(patch(
                30,
                [-1.0, 0.6, 2.0 + 0.3 * k as f32],
                [1.0, 0.0, 0.0],
            ));
        }
        let segment_of_patch = vec![0u32; stats.len()];
        let planes = RULES.planes(&stats, &segment_of_patch, 1);
        assert!(planes[0].planar, "{:?}", planes[0]);
        assert!(
            dot(planes[0].normal, [0.0, -1.0, 0.0]) > 0.9999,
            "{:?}",
            planes[0]
        );
    }

    #[test]
    fn noisy_patch_normals_count_on_the_plane_by_the_frames_noise() {
        // Patch normals scattered ±0.12 rad about the floor's, as Kinect-like noise leaves
        // them 2–3 m away: beyond the 0.1 rad of a clean frame, within a noisy frame's
        // allowance (0.8 rad per metre and pixel of width: 0.8 × 1.5 m / 8 px = 0.15 rad at
        // the nearest patches).
        let tilt = |i: usize| {
            let a: f32 = if i.is_multiple_of(2) { 0.12 } else { -0.12 };
            [a.sin(), -a.cos(), 0.0]
        };
        let stats = floor_pieces(24, tilt);
        let segment_of_patch: Vec<u32> = (0..48).map(|i| u32::from(i >= 24)).collect();
        let (_, clean) = RULES.join(&stats, &[], &segment_of_patch, 2);
        assert_eq!(
            clean, 2,
            "a clean frame's allowance calls the pieces curved"
        );
        let noisy = CoplanarRules {
            normal_noise: 0.8,
            ..RULES
        };
        let (_, count) = noisy.join(&stats, &[], &segment_of_patch, 2);
        assert_eq!(count, 1, "a noisy frame's allowance sees one floor");
        // However noisy the frame, a box's top and its side are never one plane.
        let very_noisy = CoplanarRules {
            normal_noise: 50.0,
            ..RULES
        };
        let side = [-1.0, 0.0, 0.0];
        let mut faces = vec![patch(400, [0.0, 0.5, 2.0], [0.0, -1.0, 0.0])];
        faces.push(patch(400, [0.3, 0.6, 2.0], side));
        let (_, count) = very_noisy.join(&faces, &[], &[0, 0], 1);
        assert_eq!(count, 1);
        let planes = very_noisy.planes(&faces, &[0, 0], 1);
        assert!(!planes[0].planar, "{:?}", planes[0]);
    }
}
