//! Step 4e: an object lying flat on a surface, a centimetre or two proud of it (a keyboard or a
//! book on a desk, a book on a book), is joined to that surface by every boundary rule: its
//! edge is a smaller depth step than the noise allows for, and its top is parallel to the
//! desk. Boundary by boundary the step is lost in the noise and in the patches that straddle
//! the edge; over the whole surface it is not: the patches on the object's top all lie the
//! same small height above the plane the rest of the surface fits.
//!
//! ```text
//!   host H:      a segment whose plane (CoplanarRules::planes, fitted on its inliers) holds
//!                ≥ HOST_SHARE of the frame and ≥ HOST_INLIERS of H (a desk's top, not its edge)
//!   rise(i)      =  n̄_H·(cᵢ − c̄_H)   for i ∈ H with nᵢ ∥ n̄_H   (positive on the camera's side)
//!   raised(i)    ⇔  min_raise·zᵢ ≤ rise(i) ≤ MAX_RAISE
//!   R is an object on H  ⇔  R a connected set of raised patches of H,
//!                           min_share · frame ≤ |R| ≤ ½ |H|,  |R| ≥ MIN_FILL · bbox(R)
//!   a patch of H beside R with rise ≥ ½ mean rise(R) joins R     (mostly R, blended at its edge)
//! ```
//!
//! Only raised, never sunk: a screen set a few millimetres into its frame, or the floor seen
//! through a gap, is not an object on the surface. Colour plays no part, so a keyboard in one
//! of its desk's stripe colours comes apart as well as one in its own.

use super::convexity::PatchEdge;
use super::coplanar::{plane_offset, CoplanarRules, Plane};
use super::flat_objects::{Regions, MAX_HOST_SHARE};
use super::patches::PatchStats;
use crate::classic::union_find::UnionFind;

/// Smallest host, as a share of the frame: a surface things lie on (a desk, a floor, a wall).
const HOST_SHARE: f64 = 0.02;
/// Smallest share of a host's pixels on its plane: a desk's top, not its edge and legs.
const HOST_INLIERS: f64 = 0.5;
/// Largest height above the host's plane: taller objects show depth steps and faces of their own.
const MAX_RAISE: f32 = 0.1;
/// Smallest share of its bounding box an object fills: one piece, not a strip of patches
/// blended along an occluding edge.
const MIN_FILL: f64 = 0.5;

/// Each segment's plane when it is a host (a surface things lie on), else `None`.
pub(super) fn host_planes(
    planes: &CoplanarRules,
    stats: &[PatchStats],
    segment_of_patch: &[u32],
    count: usize,
) -> Vec<Option<Plane>> {
    let total: u64 = stats.iter().map(|s| u64::from(s.pixels)).sum();
    let host_pixels = (HOST_SHARE * total as f64) as u32;
    planes
        .dominant_planes(stats, segment_of_patch, count)
        .into_iter()
        .map(|p| {
            let host = p.inliers >= host_pixels
                && f64::from(p.inliers) >= HOST_INLIERS * f64::from(p.pixels);
            host.then_some(p)
        })
        .collect()
}

/// Thresholds of the raised-object split.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RaisedRules {
    /// Smallest object, as a share of the patches' pixels; 0 turns the split off.
    pub min_share: f32,
    /// Smallest height above the host's plane, per metre of depth (depth noise grows with
    /// depth; a patch's centroid averages it down, not away).
    pub min_raise: f32,
    /// How a segment's plane is fitted and when a patch is parallel to it (the coplanar join's).
    pub planes: CoplanarRules,
}

impl RaisedRules {
    /// Splits every raised object off its host; returns the new segment of every patch and
    /// the new count (split objects numbered after the old segments).
    pub fn split(
        &self,
        stats: &[PatchStats],
        edges: &[PatchEdge],
        patch_of: &[u32],
        width: usize,
        segment_of_patch: &[u32],
        count: usize,
    ) -> (Vec<u32>, usize) {
        let mut out = segment_of_patch.to_vec();
        if self.min_share <= 0.0 || stats.is_empty() {
            return (out, count);
        }
        let planes = &self.planes;
        let hosts = host_planes(planes, stats, segment_of_patch, count);
        let total: u64 = stats.iter().map(|s| u64::from(s.pixels)).sum();
        // Height above the host's plane of every patch that could lie on a host (parallel to
        // its plane), else None.
        let rise: Vec<Option<f32>> = stats
            .iter()
            .zip(segment_of_patch)
            .map(|(st, &s)| {
                hosts[s as usize]
                    .filter(|p| planes.parallel(st, p))
                    .map(|p| plane_offset(st, &p))
            })
            .collect();
        let raised: Vec<bool> = rise
            .iter()
            .zip(stats)
            .map(|(r, st)| {
                r.is_some_and(|r| r >= self.min_raise * st.centroid[2].abs() && r <= MAX_RAISE)
            })
            .collect();
        let mut sets = UnionFind::default();
        sets.reset(stats.len(), 0.0);
        for e in edges {
            let (a, b) = (e.a as usize, e.b as usize);
            if raised[a] && raised[b] && segment_of_patch[a] == segment_of_patch[b] {
                sets.join(e.a, e.b);
            }
        }
        let regions = Regions::of(&mut sets, stats, patch_of, width);
        let min_pixels = (f64::from(self.min_share) * total as f64) as u64;
        let mut next = count as u32;
        // Mean height of each split object, by its id − count.
        let mut heights: Vec<f32> = Vec::new();
        for r in &regions.list {
            let first = r.patches[0] as usize;
            if !raised[first] {
                continue;
            }
            let host = hosts[segment_of_patch[first] as usize].map_or(0, |p| u64::from(p.pixels));
            if r.pixels < min_pixels
                || r.pixels as f64 > MAX_HOST_SHARE * host as f64
                || (r.pixels as f64) < MIN_FILL * r.bbox_area() as f64
            {
                continue;
            }
            let mean_rise = r
                .patches
                .iter()
                .map(|&p| stats[p as usize].pixels as f32 * rise[p as usize].unwrap_or(0.0))
                .sum::<f32>()
                / r.pixels as f32;
            for &p in &r.patches {
                out[p as usize] = next;
            }
            heights.push(mean_rise);
            next += 1;
        }
        // A patch blended across the object's edge rises by the share of its pixels on the
        // object: above half the object's height, most of it is the object. Judged against
        // the split before any such patch joins, so one does not pull in the next.
        let split = out.clone();
        for e in edges {
            for (inside, outside) in [(e.a as usize, e.b as usize), (e.b as usize, e.a as usize)] {
                let Some(&height) = (split[inside] as usize)
                    .checked_sub(count)
                    .and_then(|k| heights.get(k))
                else {
                    continue;
                };
                let blended = split[outside] == segment_of_patch[outside]
                    && segment_of_patch[outside] == segment_of_patch[inside]
                    && rise[outside].is_some_and(|r| r >= 0.5 * height);
                if blended {
                    out[outside] = out[inside];
                }
            }
        }
        (out, next as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PLANES: CoplanarRules = CoplanarRules {
        min_share: 0.05,
        piece_share: 0.005,
        max_angle: 0.1,
        offset_scale: 0.012,
        min_inliers: 0.8,
        normal_noise: 0.0,
    };
    const RULES: RaisedRules = RaisedRules {
        min_share: 0.01,
        min_raise: 0.004,
        planes: PLANES,
    };

    /// One segment: a 12 × 12 grid of 4-pixel patches of a wall 1.5 m ahead (normal towards
    /// the camera), patches (4..8, 4..7) moved `rise` metres towards the camera. Returns the
    /// new segment of a moved patch and of a patch of the wall, and the new count.
    fn wall_with_block(rise: f32) -> (u32, u32, usize) {
        let w = 12;
        let moved = |x: usize, y: usize| (4..8).contains(&x) && (4..7).contains(&y);
        let stats: Vec<PatchStats> = (0..w * w)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let z = 1.5 - if moved(x, y) { rise } else { 0.0 };
                PatchStats {
                    pixels: 4,
                    centroid: [0.05 * x as f32, 0.05 * y as f32, z],
                    normal: [0.0, 0.0, -1.0],
                    colour: [0.5; 3],
                }
            })
            .collect();
        let mut edges = Vec::new();
        for i in 0..w * w {
            let edge = |b: usize| PatchEdge {
                a: i as u32,
                b: b as u32,
                pairs: 2,
                steps: 0,
            };
            if (i + 1) % w != 0 {
                edges.push(edge(i + 1));
            }
            if i + w < w * w {
                edges.push(edge(i + w));
            }
        }
        // Each patch is a 2 × 2 block of pixels of a 24 × 24 image.
        let patch_of: Vec<u32> = (0..24 * 24)
            .map(|p| ((p / 24 / 2) * w + (p % 24) / 2) as u32)
            .collect();
        let (seg, count) = RULES.split(&stats, &edges, &patch_of, 24, &[0; 144], 1);
        (seg[5 * w + 5], seg[0], count)
    }

    #[test]
    fn a_block_a_centimetre_and_a_half_proud_of_a_wall_splits_off() {
        let (block, wall, count) = wall_with_block(0.015);
        assert_eq!(count, 2);
        assert_ne!(block, wall);
    }

    #[test]
    fn a_block_under_the_threshold_or_sunk_stays() {
        // 0.004 per metre at 1.5 m is 6 mm: 4 mm proud stays, and so does a recess.
        for rise in [0.004, -0.015] {
            let (block, wall, count) = wall_with_block(rise);
            assert_eq!((count, block, wall), (1, 0, 0), "rise {rise}");
        }
    }
}
