//! Step 4d: a flat object in its own colour on a surface (a picture on a wall, a rug on the
//! floor, a sheet on a desk) has no geometry to cut it by, so colour alone has to, and colour
//! alone must never cut a texture. What tells them apart: a texture repeats its colours all
//! over its surface; a flat object is one plain colour found nowhere else on it, in one
//! compact piece with an outline.
//!
//! ```text
//!   regions of segment H  =  its patches joined where adjacent patch means differ ≤ step
//!   R is a flat object    ⇔  min_share · frame ≤ |R| ≤ ½ |H|,  |H| ≥ 5 % of the frame   (an object on a surface)
//!                         ∧  |R| ≥ 0.65 · bbox(R),  ≥ 6 px · its long side             (one piece, not a net or a strip)
//!                         ∧  colour(R) ≠ mean colour(H∖R)                              (not a texture blended far away)
//!                         ∧  |H∖R in R's colour| ≤ ¼ |R|                               (no texture's repeat)
//!                         ∧  R's patch means within 0.05 RMS of colour(R)              (one plain material)
//!                         ∧  R flat, in the plane of the patches around it             (no geometry to cut by)
//!                         ∧  half of R's border against patches ≥ 0.15 from colour(R)  (an outline, not a gradient)
//! ```
//!
//! A checker square, a brick or a stripe fails the repeat test (its colour is half the
//! surface); the mortar between bricks is unique but a net over the whole wall and fails the
//! fill test; a textured picture is many small regions and is not found (missed, never cut
//! wrongly). Colours are one colour as the crease join has them: chromaticity within 0.03,
//! brightness within 1.35×. Regions grow by small steps, not by that test: its shading factor
//! let antialiased edge patches chain a white picture into its grey wall (0.5 → 0.6 → 0.71 →
//! 0.92). Without the flatness test a box's shaded face split off its lit top; without the
//! blend test scene 1's striped floor beyond 3 m, one blended colour, split off the floor
//! near the camera; without the plainness and outline tests a wavy monitor screen's bands did.

use super::colour::same_colour_within;
use super::convexity::PatchEdge;
use super::creases::{MAX_CHROMA_GAP, MAX_SHADING};
use super::patches::{PatchStats, NO_PATCH};
use crate::classic::normals::{dot, is_known, sub};
use crate::classic::union_find::UnionFind;

/// RGB distance of two adjacent patches' means within which they are one colour region (a
/// plain surface's shading changes by less from patch to patch).
const REGION_STEP: f32 = 0.08;
/// Smallest segment a flat object lies on, as a share of the frame: a surface (wall, floor,
/// table), not an object's face (scene 3's striped book cover had one stripe of each colour
/// in view: a stripe in a colour found nowhere else on the cover).
const MIN_HOST_SHARE: f64 = 0.05;
/// Largest object split off a surface (here and in [`super::raised`]), as a share of the
/// segment it lies in: the rest is the surface.
pub(super) const MAX_HOST_SHARE: f64 = 0.5;
/// Pixels of the rest of the segment in the object's colour, per pixel of the object.
const MAX_REPEAT: f64 = 0.25;
/// Smallest share of its bounding box a flat object fills: pictures, mats and posters seen in
/// perspective filled 0.69–0.93 on the suite, the bands of a wavy texture 0.54–0.65.
const MIN_FILL: f64 = 0.65;
/// Largest RMS distance of a flat object's patch means from its mean colour: one plain
/// material (0.016–0.048 on the suite), not a gradient chained in small steps (a wavy
/// monitor screen's bands, 0.056–0.072).
const MAX_DEVIATION: f32 = 0.05;
/// Smallest mean width of a flat object across its longer side, in coarse pixels: a lit edge
/// of a monitor, a strip a few pixels wide, is a face seen edge-on (scene 8), not an object.
const MIN_WIDTH: f64 = 6.0;
/// Normals within this angle (radians, cosine below) are one plane.
const MAX_BEND_COS: f32 = 0.988; // 0.155 rad, 8.9°
/// Share of a flat object's pixels whose normal lies in its plane (noise bends the rest).
const MIN_FLAT: f64 = 0.8;
/// RGB distance of patch means across an outline (the boundary verdict's colour edge), and
/// the share of the border's pixel pairs that must cross one.
const OUTLINE_CONTRAST: f32 = 0.15;
const MIN_OUTLINE: f64 = 0.5;

/// Threshold of the flat-object split.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlatObjectRules {
    /// Smallest flat object, as a share of the patches' pixels; 0 turns the split off.
    pub min_share: f32,
}

impl FlatObjectRules {
    /// Splits every flat object off the segment it lies in; returns the new segment of every
    /// patch and the new count (split objects numbered after the old segments).
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
        let total: u64 = stats.iter().map(|s| u64::from(s.pixels)).sum();
        let mut host_pixels = vec![0u64; count];
        // Pixel-weighted colour sums of every segment.
        let mut host_colour = vec![[0.0f64; 3]; count];
        for (st, &s) in stats.iter().zip(segment_of_patch) {
            host_pixels[s as usize] += u64::from(st.pixels);
            for (sum, &c) in host_colour[s as usize].iter_mut().zip(&st.colour) {
                *sum += f64::from(st.pixels) * f64::from(c);
            }
        }
        let one_colour =
            |a: [f32; 3], b: [f32; 3]| same_colour_within(a, b, MAX_CHROMA_GAP, MAX_SHADING);
        // Colour regions: patches of one segment joined across edges with nearly equal means
        // (a step, not `one_colour`: its shading factor let antialiased edge patches chain a
        // white picture into its grey wall, 0.5 → 0.6 → 0.71 → 0.92).
        let mut sets = UnionFind::default();
        sets.reset(stats.len(), 0.0);
        for e in edges {
            let (a, b) = (e.a as usize, e.b as usize);
            let d = sub(stats[a].colour, stats[b].colour);
            if segment_of_patch[a] == segment_of_patch[b] && dot(d, d) <= REGION_STEP * REGION_STEP
            {
                sets.join(e.a, e.b);
            }
        }
        let regions = Regions::of(&mut sets, stats, patch_of, width);
        let min_pixels = (f64::from(self.min_share) * total as f64) as u64;
        let mut next = count as u32;
        for r in &regions.list {
            let host = segment_of_patch[r.patches[0] as usize] as usize;
            let sized = r.pixels >= min_pixels
                && host_pixels[host] as f64 >= MIN_HOST_SHARE * total as f64
                && r.pixels as f64 <= MAX_HOST_SHARE * host_pixels[host] as f64;
            let compact = r.pixels as f64 >= MIN_FILL * r.bbox_area() as f64
                && r.pixels as f64 >= MIN_WIDTH * r.bbox_long_side() as f64;
            if !sized || !compact {
                continue;
            }
            // The rest of the host's mean colour: what a fine texture blends into far away.
            let rest = (host_pixels[host] - r.pixels).max(1) as f64;
            let rest_colour: [f32; 3] = std::array::from_fn(|c| {
                ((host_colour[host][c] - r.colour[c] as f64 * r.pixels as f64) / rest) as f32
            });
            if one_colour(rest_colour, r.colour) {
                continue;
            }
            // Pixels elsewhere on the host in the region's colour: the texture's repeat.
            let repeat: u64 = stats
                .iter()
                .enumerate()
                .filter(|&(p, st)| {
                    segment_of_patch[p] as usize == host
                        && regions.of_patch[p] != r.id
                        && one_colour(st.colour, r.colour)
                })
                .map(|(_, st)| u64::from(st.pixels))
                .sum();
            if repeat as f64 > MAX_REPEAT * r.pixels as f64
                || r.deviation(stats) > MAX_DEVIATION
                || !flat_and_outlined(r, &regions.of_patch, stats, edges, segment_of_patch)
            {
                continue;
            }
            for &p in &r.patches {
                out[p as usize] = next;
            }
            next += 1;
        }
        (out, next as usize)
    }
}

/// Whether region `r` is flat, lies in the plane of its host's patches that border it, and
/// stands out in colour from most of that border.
fn flat_and_outlined(
    r: &Region,
    region_of_patch: &[u32],
    stats: &[PatchStats],
    edges: &[PatchEdge],
    segment_of_patch: &[u32],
) -> bool {
    let weighted_mean = |patches: &mut dyn Iterator<Item = usize>| {
        let mut sum = [0.0f32; 3];
        for p in patches {
            if is_known(stats[p].normal) {
                let w = stats[p].pixels as f32;
                for (s, &n) in sum.iter_mut().zip(&stats[p].normal) {
                    *s += w * n;
                }
            }
        }
        let len = dot(sum, sum).sqrt();
        (len > 1e-6).then(|| sum.map(|c| c / len))
    };
    let Some(normal) = weighted_mean(&mut r.patches.iter().map(|&p| p as usize)) else {
        return false;
    };
    let in_plane =
        |p: usize| is_known(stats[p].normal) && dot(stats[p].normal, normal) >= MAX_BEND_COS;
    let flat: u64 = r
        .patches
        .iter()
        .filter(|&&p| in_plane(p as usize))
        .map(|&p| u64::from(stats[p as usize].pixels))
        .sum();
    if (flat as f64) < MIN_FLAT * r.pixels as f64 {
        return false;
    }
    let host = segment_of_patch[r.patches[0] as usize];
    // The border: edges from the region to the rest of its host, (inside, outside, pairs).
    let border: Vec<(usize, usize, u32)> = edges
        .iter()
        .filter_map(|e| {
            let (a, b) = (e.a as usize, e.b as usize);
            let (ra, rb) = (region_of_patch[a] == r.id, region_of_patch[b] == r.id);
            match (ra, rb) {
                (true, false) if segment_of_patch[b] == host => Some((a, b, e.pairs)),
                (false, true) if segment_of_patch[a] == host => Some((b, a, e.pairs)),
                _ => None,
            }
        })
        .collect();
    let (mut outline, mut pairs) = (0u64, 0u64);
    for &(_, outside, n) in &border {
        let d = sub(r.colour, stats[outside].colour);
        if dot(d, d) >= OUTLINE_CONTRAST * OUTLINE_CONTRAST {
            outline += u64::from(n);
        }
        pairs += u64::from(n);
    }
    if (outline as f64) < MIN_OUTLINE * pairs as f64 {
        return false;
    }
    weighted_mean(&mut border.iter().map(|&(_, outside, _)| outside))
        .is_some_and(|n| dot(n, normal) >= MAX_BEND_COS)
}

/// One colour region: its patches, pixels, mean colour and pixel bounding box.
pub(super) struct Region {
    pub id: u32,
    pub patches: Vec<u32>,
    pub pixels: u64,
    pub colour: [f32; 3],
    pub bbox: [usize; 4],
}

impl Region {
    pub(super) fn bbox_area(&self) -> u64 {
        let [x0, y0, x1, y1] = self.bbox;
        ((x1 + 1 - x0) * (y1 + 1 - y0)) as u64
    }

    /// RMS distance of the region's patch means from its mean colour, pixel-weighted.
    fn deviation(&self, stats: &[PatchStats]) -> f32 {
        let sum: f64 = self
            .patches
            .iter()
            .map(|&p| {
                let st = &stats[p as usize];
                let d = sub(st.colour, self.colour);
                f64::from(st.pixels) * f64::from(dot(d, d))
            })
            .sum();
        (sum / self.pixels.max(1) as f64).sqrt() as f32
    }

    pub(super) fn bbox_long_side(&self) -> u64 {
        let [x0, y0, x1, y1] = self.bbox;
        (x1 + 1 - x0).max(y1 + 1 - y0) as u64
    }
}

/// The connected sets of patches a union-find holds, as regions.
pub(super) struct Regions {
    pub list: Vec<Region>,
    /// Region id (its set root) of every patch.
    pub of_patch: Vec<u32>,
}

impl Regions {
    pub(super) fn of(
        sets: &mut UnionFind,
        stats: &[PatchStats],
        patch_of: &[u32],
        width: usize,
    ) -> Self {
        let of_patch: Vec<u32> = (0..stats.len() as u32).map(|p| sets.find(p)).collect();
        let mut index = vec![usize::MAX; stats.len()];
        let mut list: Vec<Region> = Vec::new();
        for (p, &root) in of_patch.iter().enumerate() {
            let i = match index[root as usize] {
                usize::MAX => {
                    index[root as usize] = list.len();
                    list.push(Region {
                        id: root,
                        patches: Vec::new(),
                        pixels: 0,
                        colour: [0.0; 3],
                        bbox: [usize::MAX, usize::MAX, 0, 0],
                    });
                    list.len() - 1
                }
                i => i,
            };
            let r = &mut list[i];
            let n = u64::from(stats[p].pixels);
            // Running pixel-weighted mean colour.
            let w = n as f32 / (r.pixels + n).max(1) as f32;
            for (c, &x) in r.colour.iter_mut().zip(&stats[p].colour) {
                *c += w * (x - *c);
            }
            r.pixels += n;
            r.patches.push(p as u32);
        }
        for (i, &p) in patch_of.iter().enumerate() {
            if p == NO_PATCH {
                continue;
            }
            let b = &mut list[index[of_patch[p as usize] as usize]].bbox;
            let (x, y) = (i % width, i / width);
            *b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
        }
        Self { list, of_patch }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RULES: FlatObjectRules = FlatObjectRules { min_share: 0.01 };

    const WALL: [f32; 3] = [0.8, 0.8, 0.75];
    const TAN: [f32; 3] = [0.8, 0.6, 0.35];

    /// A `w` × `h` grid of one-pixel patches coloured by `paint`, all one segment, with
    /// 4-neighbour edges.
    fn grid(w: usize, h: usize, paint: impl Fn(usize, usize) -> [f32; 3]) -> Vec<u32> {
        let stats: Vec<PatchStats> = (0..w * h)
            .map(|i| PatchStats {
                pixels: 1,
                centroid: [0.0, 0.0, 2.0],
                normal: [0.0, 0.0, -1.0],
                colour: paint(i % w, i / w),
            })
            .collect();
        let mut edges = Vec::new();
        for i in 0..w * h {
            let pairs = 1;
            if (i + 1) % w != 0 {
                edges.push(PatchEdge {
                    a: i as u32,
                    b: i as u32 + 1,
                    pairs,
                    steps: 0,
                });
            }
            if i + w < w * h {
                edges.push(PatchEdge {
                    a: i as u32,
                    b: (i + w) as u32,
                    pairs,
                    steps: 0,
                });
            }
        }
        let patch_of: Vec<u32> = (0..(w * h) as u32).collect();
        let (out, count) = RULES.split(&stats, &edges, &patch_of, w, &vec![0; w * h], 1);
        assert!(out.iter().all(|&s| (s as usize) < count));
        out
    }

    #[test]
    fn a_picture_on_a_plain_wall_is_split_off() {
        // 40 × 30 wall, a 12 × 8 picture (8 % of it).
        let picture = |x: usize, y: usize| (10..22).contains(&x) && (5..13).contains(&y);
        let out = grid(40, 30, |x, y| if picture(x, y) { TAN } else { WALL });
        for y in 0..30 {
            for x in 0..40 {
                assert_eq!(out[y * 40 + x] != 0, picture(x, y), "pixel ({x}, {y})");
            }
        }
    }

    #[test]
    fn a_checker_stripes_and_bricks_stay_one_surface() {
        let (dark, light) = ([0.2, 0.2, 0.25], [0.9, 0.9, 0.85]);
        // Checker squares of 6 px: each dark square is unique in shape but not in colour.
        let checker = grid(40, 30, |x, y| {
            if (x / 6 + y / 6) % 2 == 0 {
                dark
            } else {
                light
            }
        });
        assert!(checker.iter().all(|&s| s == 0), "checker split");
        let stripes = grid(40, 30, |x, _| if (x / 3) % 2 == 0 { dark } else { TAN });
        assert!(stripes.iter().all(|&s| s == 0), "stripes split");
        // Bricks 8 × 3 with a one-pixel mortar net: the mortar's colour is unique, but the
        // net fills about a third of its box, the whole wall.
        let mortar = [0.85, 0.85, 0.85];
        let brick = [0.6, 0.25, 0.2];
        let bricks = grid(40, 30, |x, y| {
            let shift = if (y / 4) % 2 == 0 { 0 } else { 4 };
            if y % 4 == 3 || (x + shift) % 9 == 8 {
                mortar
            } else {
                brick
            }
        });
        assert!(bricks.iter().all(|&s| s == 0), "bricks split");
    }

    #[test]
    fn a_picture_in_a_wall_colour_or_too_small_stays() {
        let picture = |x: usize, y: usize| (10..22).contains(&x) && (5..13).contains(&y);
        // The picture's colour repeats on the wall: a second patch of it, as large.
        let repeated = grid(40, 30, |x, y| {
            if picture(x, y) || ((25..37).contains(&x) && (15..23).contains(&y)) {
                TAN
            } else {
                WALL
            }
        });
        assert!(repeated.iter().all(|&s| s == 0));
        // 2 × 2: under 1 % of the frame.
        let tiny = grid(40, 30, |x, y| if x < 2 && y < 2 { TAN } else { WALL });
        assert!(tiny.iter().all(|&s| s == 0));
    }
}
