//! Surface patches: every grid cell split into its pieces of continuous
//! surface (no depth step, no sharp normal change inside a piece), with the
//! mean point, normal and colour of each piece.

use crate::classic::downscale::CoarseFrame;
use crate::classic::normals::{dot, is_known, sub, SurfaceGeometry};

/// Patch index of a pixel without depth.
pub const NO_PATCH: u32 = u32::MAX;

/// When two neighbouring pixels lie on one continuous surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Continuity {
    /// Relative depth step (step / depth) off the surface's own slope
    /// that separates.
    pub max_jump: f32,
    /// Noise dead zone in inverse depth (1/m): k·σ(1/z).
    pub inverse_noise: f32,
    /// Below this cosine to its mean normal so far a patch does not grow.
    pub min_normal_cos: f32,
    /// Nor across this RGB distance (channels 0..1): a patch never
    /// straddles a colour edge, so colour can still decide between patches.
    pub max_colour: f32,
}

/// Depth continuity of every pixel with its right and lower neighbour.
#[derive(Debug, Clone, Default)]
pub struct ContinuityMap {
    pub right: Vec<bool>,
    pub down: Vec<bool>,
}

impl ContinuityMap {
    /// Whether 4-neighbours `i` and `j` (either order) are continuous.
    pub fn joins(&self, i: usize, j: usize, width: usize) -> bool {
        let (a, b) = (i.min(j), i.max(j));
        if b == a + 1 {
            self.right[a]
        } else {
            debug_assert_eq!(b, a + width);
            self.down[a]
        }
    }
}

impl Continuity {
    /// Continuity along rows and columns. Inverse depth w = 1/z is affine
    /// in pixel coordinates on any plane, so a step is judged by how far
    /// w_b misses the line continued from a's side (through a and the two
    /// pixels before it) or from b's side (b and the two after it): a
    /// slanted floor seen at a grazing angle has large but regular steps;
    /// an occluding edge breaks the line on both sides. The line needs
    /// three pixels: through two, one mixed pixel between a chair seat and
    /// the floor behind it halves the step and passes for a steep plane.
    pub fn map(&self, depth_m: &[f32], width: usize, height: usize) -> ContinuityMap {
        let inv: Vec<f32> = depth_m
            .iter()
            .map(|&z| if z > 0.0 { 1.0 / z } else { 0.0 })
            .collect();
        let tolerance = |w: f32| self.max_jump * w + self.inverse_noise;
        let valid = |p: Option<usize>| p.map(|p| inv[p]).filter(|&w| w > 0.0);
        // The per-pixel slope of the line through `w` and the two valid
        // pixels beyond it (`near`, then `far`), when those three are one line.
        let slope = |w: f32, near: Option<usize>, far: Option<usize>| {
            let (near, far) = (valid(near)?, valid(far)?);
            let (outer, inner) = (near - far, w - near);
            ((inner - outer).abs() <= tolerance(w.max(near).max(far))).then_some(inner)
        };
        let judge = |before: [Option<usize>; 2], a: usize, b: usize, after: [Option<usize>; 2]| {
            let (wa, wb) = (inv[a], inv[b]);
            if wa <= 0.0 || wb <= 0.0 {
                return false;
            }
            let step = wb - wa;
            let from_before = slope(wa, before[0], before[1]).map(|s| (step - s).abs());
            // Seen from b's side the line runs backwards: its slope towards a is −s.
            let from_after = slope(wb, after[0], after[1]).map(|s| (step + s).abs());
            let residual = [from_before, from_after]
                .into_iter()
                .flatten()
                .fold(step.abs(), f32::min);
            residual <= tolerance(wa.max(wb))
        };
        let mut right = vec![false; width * height];
        let mut down = vec![false; width * height];
        for y in 0..height {
            for x in 0..width {
                let i = y * width + x;
                if x + 1 < width {
                    let before = [(x > 0).then(|| i - 1), (x > 1).then(|| i - 2)];
                    let after = [
                        (x + 2 < width).then(|| i + 2),
                        (x + 3 < width).then(|| i + 3),
                    ];
                    right[i] = judge(before, i, i + 1, after);
                }
                if y + 1 < height {
                    let before = [(y > 0).then(|| i - width), (y > 1).then(|| i - 2 * width)];
                    let after = [
                        (y + 2 < height).then(|| i + 2 * width),
                        (y + 3 < height).then(|| i + 3 * width),
                    ];
                    down[i] = judge(before, i, i + width, after);
                }
            }
        }
        ContinuityMap { right, down }
    }
}

fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// Mean geometry and colour of one patch; `normal` is zero when none of
/// its pixels had a normal.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PatchStats {
    pub pixels: u32,
    pub centroid: [f32; 3],
    pub normal: [f32; 3],
    pub colour: [f32; 3],
}

/// Patch index per coarse pixel (`NO_PATCH` without depth) and the stats.
#[derive(Debug, Clone, Default)]
pub struct Patches {
    pub of: Vec<u32>,
    pub stats: Vec<PatchStats>,
}

/// Flood-fills each `cell` × `cell` block of the coarse grid over
/// 4-neighbours that are depth- and normal-continuous.
pub fn build_patches(
    frame: &CoarseFrame,
    geo: &SurfaceGeometry,
    cell: usize,
    continuity: &Continuity,
    steps: &ContinuityMap,
) -> Patches {
    let (w, h) = (frame.width, frame.height);
    let cell = cell.max(1);
    let mut of = vec![NO_PATCH; w * h];
    let mut count = 0u32;
    let mut stack = Vec::new();
    // Normals are compared with the patch's running mean, not pixel to
    // pixel: a smoothed crease bends a little per pixel but a lot from the
    // patch, and the mean is steadier under noise than one seed pixel.
    let joins = |sum: [f32; 3], a: usize, b: usize| {
        let nb = geo.normals[b];
        let dc = sub(frame.rgb[a], frame.rgb[b]);
        let len = dot(sum, sum).sqrt();
        steps.joins(a, b, w)
            && (len <= 1e-6 || !is_known(nb) || dot(sum, nb) >= continuity.min_normal_cos * len)
            && dot(dc, dc) <= continuity.max_colour * continuity.max_colour
    };
    for cy in (0..h).step_by(cell) {
        for cx in (0..w).step_by(cell) {
            let (x1, y1) = ((cx + cell).min(w), (cy + cell).min(h));
            for y in cy..y1 {
                for x in cx..x1 {
                    let seed = y * w + x;
                    if of[seed] != NO_PATCH || frame.depth_m[seed] <= 0.0 {
                        continue;
                    }
                    of[seed] = count;
                    let mut normal_sum = geo.normals[seed];
                    stack.push(seed);
                    while let Some(i) = stack.pop() {
                        let (px, py) = (i % w, i / w);
                        let neighbours = [
                            (px > cx).then(|| i - 1),
                            (px + 1 < x1).then(|| i + 1),
                            (py > cy).then(|| i - w),
                            (py + 1 < y1).then(|| i + w),
                        ];
                        for j in neighbours.into_iter().flatten() {
                            if of[j] == NO_PATCH && joins(normal_sum, i, j) {
                                of[j] = count;
                                normal_sum = add(normal_sum, geo.normals[j]);
                                stack.push(j);
                            }
                        }
                    }
                    count += 1;
                }
            }
        }
    }
    let stats = patch_stats(frame, geo, &of, count as usize);
    Patches { of, stats }
}

/// Means of points, known normals (renormalised) and colours per patch.
fn patch_stats(
    frame: &CoarseFrame,
    geo: &SurfaceGeometry,
    of: &[u32],
    count: usize,
) -> Vec<PatchStats> {
    // [point sum, normal sum, colour sum] per patch, in f64: 64+ terms each.
    let mut sums = vec![([0.0f64; 3], [0.0f64; 3], [0.0f64; 3], 0u32); count];
    for (i, &p) in of.iter().enumerate() {
        if p == NO_PATCH {
            continue;
        }
        let s = &mut sums[p as usize];
        for c in 0..3 {
            s.0[c] += geo.points[i][c] as f64;
            s.1[c] += geo.normals[i][c] as f64;
            s.2[c] += frame.rgb[i][c] as f64;
        }
        s.3 += 1;
    }
    sums.iter()
        .map(|(point, normal, colour, n)| {
            let inv = 1.0 / (*n).max(1) as f64;
            let len = dot(normal.map(|c| c as f32), normal.map(|c| c as f32)).sqrt();
            PatchStats {
                pixels: *n,
                centroid: point.map(|c| (c * inv) as f32),
                normal: if len > 1e-6 {
                    normal.map(|c| c as f32 / len)
                } else {
                    [0.0; 3]
                },
                colour: colour.map(|c| (c * inv) as f32),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_geometry::Intrinsics;

    /// What `map` reads: 4 % steps and no noise (normal and colour limits do not enter it).
    const ONE_ROW: Continuity = Continuity {
        max_jump: 0.04,
        inverse_noise: 0.0,
        min_normal_cos: 0.5,
        max_colour: 1.0,
    };

    #[test]
    fn grazing_planes_are_continuous_and_occlusions_are_not() {
        // One row: a plane at a grazing angle (1/z affine, 10 % steps),
        // then a jump back to 1 m.
        let depth: Vec<f32> = (0..6)
            .map(|u| 1.0 / (1.0 - 0.09 * u as f32))
            .chain([1.0, 1.0])
            .collect();
        let c = ONE_ROW;
        let m = c.map(&depth, 8, 1);
        assert!(m.right[..5].iter().all(|&j| j), "{:?}", m.right);
        assert!(!m.right[5]);
        assert!(m.right[6]);
    }

    #[test]
    fn one_mixed_pixel_between_two_surfaces_is_no_steep_plane() {
        // A seat at 1.46 m, one pixel halfway in inverse depth, the floor at
        // 2.12 m: the two equal steps lie on one line through two pixels
        // (the old rule joined all three), but not through three.
        let (seat, floor) = (1.0 / 1.46f32, 1.0 / 2.12f32);
        let depth: Vec<f32> = [seat, seat, seat, 0.5 * (seat + floor), floor, floor, floor]
            .iter()
            .map(|w| 1.0 / w)
            .collect();
        let c = ONE_ROW;
        let m = c.map(&depth, 7, 1);
        assert_eq!(
            m.right[..6],
            [true, true, false, false, true, true],
            "{:?}",
            m.right
        );
    }

    #[test]
    fn cells_split_at_depth_steps_and_skip_holes() {
        // 8x4 grid, cell 4: left half at 1 m, right half steps from 1 m to
        // 2 m at column 6; one hole.
        let (w, h) = (8, 4);
        let mut depth: Vec<f32> = (0..w * h)
            .map(|i| if i % w >= 6 { 2.0 } else { 1.0 })
            .collect();
        depth[0] = 0.0;
        let frame = CoarseFrame {
            width: w,
            height: h,
            rgb: vec![[0.5; 3]; w * h],
            depth_m: depth.clone(),
        };
        let k = Intrinsics::new(100.0, 100.0, 3.5, 1.5, w as u32, h as u32);
        let geo = SurfaceGeometry::from_depth(&depth, w, h, &k, 0.05);
        let continuity = Continuity {
            max_jump: 0.05,
            inverse_noise: 0.0,
            min_normal_cos: 0.5,
            max_colour: 1.0,
        };
        let steps = continuity.map(&depth, w, h);
        let p = build_patches(&frame, &geo, 4, &continuity, &steps);
        assert_eq!(p.of[0], NO_PATCH);
        assert_eq!(p.stats.len(), 3, "{:?}", p.of);
        assert_eq!(p.of[1], p.of[3 * w + 3]);
        assert_ne!(p.of[4], p.of[6]);
        assert_eq!(p.stats[p.of[1] as usize].pixels, 15);
        assert!((p.stats[p.of[6] as usize].centroid[2] - 2.0).abs() < 1e-6);
    }
}
