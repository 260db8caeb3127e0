//! Step 4c: segments that meet at a crease, not a depth step, and are one material are one
//! object cut by LCCP's concavity rule: a sofa's seat and back, a cabinet's doors and
//! its plinth. Both must be object-sized, so a wall's corner and the floor under a sofa
//! stay cuts.
//!
//! ```text
//!   boundary(a, b) =  patch edges between segments a and b: pairs p, step pairs q
//!   join(a, b)     ⇔  q ≤ max_step_share · p        (a crease, not an occlusion)
//!                  ∧  |a|, |b| ≤ max_share · frame   (parts of an object, not surfaces)
//!                  ∧  same colour(ā, b̄)             (one material up to shading)
//! ```
//!
//! Colour is what tells a sofa's seat from a box on a table when both meet the same
//! concave crease, and it is the only evidence here: a book the colour of the table it
//! lies on joins it. Means over whole segments, not patches, so a texture's mean is
//! compared with the same texture's mean. The colour test is stricter than the coplanar
//! join's (chromaticity within 0.03, brightness within 1.35×; the built-in room's
//! bookshelf boards and back measured 0.022 and 1.03–1.17×, scene 6's sofa 0.001–0.004
//! and up to 1.27×): on scenes 2 and 6 the coplanar join's 0.05 and 2× also joined books
//! to their table and a ball to its box. A saturated colour (chromaticity 0.1 or more from
//! grey) within 0.01 is one material up to 2.5×: a chair's backrest in its own shade.

use std::collections::BTreeMap;

use super::colour::{mean_colours, same_colour_within};
use super::convexity::PatchEdge;
use super::patches::PatchStats;
use super::regions::regroup;
use crate::classic::union_find::UnionFind;

/// Chromaticity gap and brightness factor within which two sides of a crease are one material.
pub(super) const MAX_CHROMA_GAP: f32 = 0.03;
pub(super) const MAX_SHADING: f32 = 1.35;
/// A saturated colour (chromaticity this far from grey) kept within `SAME_HUE_GAP` is one
/// material up to `SATURATED_SHADING`: a chair's back facing away from the light, 2.05× darker
/// than its seat at a gap of 0.001. Greys are left out: every grey has one chromaticity.
const MIN_SATURATION: f32 = 0.1;
const SAME_HUE_GAP: f32 = 0.01;
const SATURATED_SHADING: f32 = 2.5;

/// Two sides of a crease in one material up to shading.
fn one_material(a: [f32; 3], b: [f32; 3]) -> bool {
    let saturation = |c: [f32; 3]| {
        let sum = c[0] + c[1] + c[2];
        let grey = 1.0 / 3.0;
        let d = c.map(|x| x / sum.max(1e-6) - grey);
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    };
    same_colour_within(a, b, MAX_CHROMA_GAP, MAX_SHADING)
        || (saturation(a).min(saturation(b)) >= MIN_SATURATION
            && same_colour_within(a, b, SAME_HUE_GAP, SATURATED_SHADING))
}

/// Thresholds of the crease join.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CreaseRules {
    /// Largest share of a boundary's pixel pairs that may be depth steps.
    pub max_step_share: f32,
    /// Largest segment that joins, as a share of the patches' pixels; 0 turns the join off.
    pub max_share: f32,
}

impl CreaseRules {
    /// Joins same-coloured object-sized segments across crease boundaries; returns the new
    /// segment of every patch and the new count (dense, in first-seen order).
    pub fn join(
        &self,
        stats: &[PatchStats],
        edges: &[PatchEdge],
        segment_of_patch: &[u32],
        count: usize,
    ) -> (Vec<u32>, usize) {
        if self.max_share <= 0.0 {
            return (segment_of_patch.to_vec(), count);
        }
        let mut pixels = vec![0u64; count];
        for (st, &s) in stats.iter().zip(segment_of_patch) {
            pixels[s as usize] += u64::from(st.pixels);
        }
        let total: u64 = pixels.iter().sum();
        let max_pixels = (f64::from(self.max_share) * total as f64) as u64;
        let mut boundaries: BTreeMap<(u32, u32), (u32, u32)> = BTreeMap::new();
        for e in edges {
            let (a, b) = (
                segment_of_patch[e.a as usize],
                segment_of_patch[e.b as usize],
            );
            if a != b {
                let entry = boundaries.entry((a.min(b), a.max(b))).or_default();
                entry.0 += e.pairs;
                entry.1 += e.steps;
            }
        }
        let colours = mean_colours(stats, segment_of_patch, count);
        let mut sets = UnionFind::default();
        sets.reset(count, 0.0);
        for (&(a, b), &(pairs, steps)) in &boundaries {
            let crease = steps as f32 <= self.max_step_share * pairs as f32;
            let parts = pixels[a as usize] <= max_pixels && pixels[b as usize] <= max_pixels;
            let (ca, cb) = (colours[a as usize], colours[b as usize]);
            if crease && parts && one_material(ca, cb) {
                sets.join(a, b);
            }
        }
        regroup(&mut sets, segment_of_patch, count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RULES: CreaseRules = CreaseRules {
        max_step_share: 0.25,
        max_share: 0.15,
    };

    /// Segment i is one patch of `pixels[i]` in `colours[i]` (geometry does not matter here).
    fn patches(pixels: &[u32], colours: &[[f32; 3]]) -> Vec<PatchStats> {
        pixels
            .iter()
            .zip(colours)
            .map(|(&pixels, &colour)| PatchStats {
                pixels,
                centroid: [0.0, 0.0, 2.0],
                normal: [0.0, 0.0, -1.0],
                colour,
            })
            .collect()
    }

    fn edge(a: u32, b: u32, pairs: u32, steps: u32) -> PatchEdge {
        PatchEdge { a, b, pairs, steps }
    }

    const FABRIC: [f32; 3] = [0.55, 0.30, 0.25];

    #[test]
    fn a_sofas_seat_and_back_join_and_a_box_on_it_does_not() {
        // Seat (0) lit from above, back (1) in its own shade (0.8×), a blue box on the seat
        // (2), the floor under the sofa (3: 60 % of the frame, the fabric's colour).
        let shaded = FABRIC.map(|c| 0.8 * c);
        let stats = patches(
            &[800, 700, 200, 6000],
            &[FABRIC, shaded, [0.2, 0.3, 0.6], FABRIC],
        );
        let edges = [
            edge(0, 1, 60, 2),  // the concave crease between seat and back
            edge(0, 2, 30, 0),  // where the box stands on the seat
            edge(0, 3, 80, 70), // the seat's front edge over the floor: a depth step
            edge(1, 3, 10, 0),  // the back's foot on the floor: a crease
        ];
        let (seg, count) = RULES.join(&stats, &edges, &[0, 1, 2, 3], 4);
        assert_eq!(count, 3, "{seg:?}");
        assert_eq!(seg[0], seg[1], "seat and back are one sofa");
        assert_ne!(seg[0], seg[2], "the box is another colour");
        assert_ne!(seg[1], seg[3], "the floor is a surface, not a part");
    }

    #[test]
    fn parts_joined_through_a_shared_part_are_one_object() {
        // A sofa's arm (0) and back (1) each meet its seat (2) at a crease, not each other;
        // the wall behind (3) is another colour. Joining seat to arm, then seat to back, must
        // keep the arm (the union once re-hung the seat under the back and lost the arm).
        let stats = patches(&[500, 500, 500, 9000], &[FABRIC, FABRIC, FABRIC, [0.5; 3]]);
        let edges = [edge(0, 2, 40, 0), edge(1, 2, 40, 0)];
        let (seg, count) = RULES.join(&stats, &edges, &[0, 1, 2, 3], 4);
        assert_eq!(count, 2, "{seg:?}");
        assert!(seg[0] == seg[1] && seg[1] == seg[2], "{seg:?}");
    }

    #[test]
    fn a_boundary_of_depth_steps_or_another_shade_stays_cut() {
        // Two fabric pieces of 5 % of the frame each: one over the other (a depth step along
        // 40 % of the boundary); then across a crease, but one 1.5× as bright as the other.
        let stats = patches(&[500, 500, 9000], &[FABRIC, FABRIC, [0.5; 3]]);
        let (_, count) = RULES.join(&stats, &[edge(0, 1, 50, 20)], &[0, 1, 2], 3);
        assert_eq!(count, 3, "an occlusion is no crease");
        // Greys all share one chromaticity: a 1.5× brighter grey is another material.
        let grey = [0.3; 3];
        let stats = patches(&[500, 500, 9000], &[grey, grey.map(|c| 1.5 * c), [0.5; 3]]);
        let (_, count) = RULES.join(&stats, &[edge(0, 1, 50, 0)], &[0, 1, 2], 3);
        assert_eq!(count, 3, "a brighter grey is another material");
        // The same two pieces across a crease, beside a wall (not adjacent) that makes each
        // 5 % of the frame: one object, unless the join is off.
        let stats = patches(&[500, 500, 9000], &[FABRIC, FABRIC, [0.5; 3]]);
        let off = CreaseRules {
            max_share: 0.0,
            ..RULES
        };
        let (_, count) = off.join(&stats, &[edge(0, 1, 50, 0)], &[0, 1, 2], 3);
        assert_eq!(count, 3, "max_share 0 turns the join off");
        let (_, count) = RULES.join(&stats, &[edge(0, 1, 50, 0)], &[0, 1, 2], 3);
        assert_eq!(count, 2);
    }

    #[test]
    fn a_saturated_colour_in_its_own_shade_is_one_material() {
        // Scene 6's chair (noisy, keyframe 84): seat and backrest means, one hue, the back
        // 2.05× darker: one material. Not grey, and not another hue at the same shading.
        let (seat, back) = ([0.639, 0.338, 0.409], [0.312, 0.165, 0.199]);
        assert!(one_material(seat, back));
        assert!(!one_material([0.6; 3], [0.29; 3]), "greys 2× apart");
        let other_hue = [0.312, 0.175, 0.189]; // chromaticity 0.02 away
        assert!(!one_material(seat, other_hue));
        assert!(!one_material(seat, seat.map(|c| c / 3.0)), "3× darker");
        assert!(
            one_material(seat, seat.map(|c| c / 1.3)),
            "the first rule still holds"
        );
        let stats = patches(&[500, 500, 9000], &[seat, back, [0.5; 3]]);
        let (_, count) = RULES.join(&stats, &[edge(0, 1, 50, 0)], &[0, 1, 2], 3);
        assert_eq!(count, 2, "seat and backrest join across their crease");
    }
}
