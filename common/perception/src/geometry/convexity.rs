//! Patch adjacency and the verdict on every shared boundary: a depth step,
//! a concave crease, or a weak geometric boundary confirmed by colour cut;
//! everything else (flat, convex) joins.

use super::patches::{ContinuityMap, PatchStats, Patches, NO_PATCH};
use crate::classic::normals::{cross, dot, is_known, sub};

/// |cos| between the centroid offset and the crease line above which the
/// convexity sign is not trusted (LCCP's singular configuration, ~37°).
const SINGULAR_COS: f32 = 0.8;

/// Two adjacent patches and the pixel pairs along their shared boundary.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PatchEdge {
    pub a: u32,
    pub b: u32,
    /// 4-neighbour pixel pairs across the boundary.
    pub pairs: u32,
    /// Of those, the pairs that are not depth-continuous.
    pub steps: u32,
}

/// Thresholds of the boundary verdict.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryRules {
    /// Share of step pairs from which a boundary is a depth step.
    pub step_share: f32,
    /// Concave boundaries bend by more than this (radians) to cut.
    pub concave_angle: f32,
    /// Normal offset between the two patches' planes, relative to depth,
    /// that counts as full geometric evidence (a book on a desk).
    pub offset_scale: f32,
    /// Geometric evidence (0..1) from which colour may decide.
    pub weak_evidence: f32,
    /// RGB distance of patch means (channels 0..1) that cuts weak boundaries.
    pub colour_cut: f32,
}

/// The verdict on one boundary: `evidence` in [0, 1] is how strong the
/// reason to separate is (1 = depth step), kept for the confidence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Verdict {
    pub cut: bool,
    pub evidence: f32,
}

/// Adjacent patch pairs (`a` < `b`) with their boundary pair counts.
pub fn patch_edges(
    patches: &Patches,
    steps: &ContinuityMap,
    width: usize,
    out: &mut Vec<PatchEdge>,
) {
    let of = &patches.of;
    let mut pairs: Vec<(u32, u32, bool)> = Vec::new();
    let mut push = |i: usize, j: usize| {
        let (pi, pj) = (of[i], of[j]);
        if pi != pj && pi != NO_PATCH && pj != NO_PATCH {
            let step = !steps.joins(i, j, width);
            pairs.push((pi.min(pj), pi.max(pj), step));
        }
    };
    for i in 0..of.len() {
        if (i + 1) % width != 0 {
            push(i, i + 1);
        }
        if i + width < of.len() {
            push(i, i + width);
        }
    }
    pairs.sort_unstable_by_key(|&(a, b, _)| (a, b));
    out.clear();
    for (a, b, step) in pairs {
        match out.last_mut() {
            Some(e) if (e.a, e.b) == (a, b) => {
                e.pairs += 1;
                e.steps += step as u32;
            }
            _ => out.push(PatchEdge {
                a,
                b,
                pairs: 1,
                steps: step as u32,
            }),
        }
    }
}

impl BoundaryRules {
    /// Step → cut; concave beyond the angle → cut; convex or flat → join,
    /// unless the weaker evidence (a small bend or plane offset, a few
    /// steps) meets a colour edge.
    pub fn verdict(&self, edge: &PatchEdge, a: &PatchStats, b: &PatchStats) -> Verdict {
        let step_share = edge.steps as f32 / edge.pairs.max(1) as f32;
        if step_share >= self.step_share {
            return Verdict {
                cut: true,
                evidence: 1.0,
            };
        }
        if !is_known(a.normal) || !is_known(b.normal) {
            // No normal, no convexity: never a bridge; the small-piece rule
            // gives such a patch (a few pixels at an edge) to one side.
            return Verdict {
                cut: true,
                evidence: 0.0,
            };
        }
        let mut evidence = step_share / self.step_share;
        {
            let d = sub(a.centroid, b.centroid);
            let bend = dot(a.normal, b.normal).clamp(-1.0, 1.0).acos();
            // LCCP: convex when (n_a − n_b)·(x_a − x_b) > 0; normals face the
            // camera. Its sanity check: with x_a − x_b along the planes'
            // intersection line (small patches side by side on a crease) the
            // sign is noise, so such a boundary is not trusted as convex.
            let line = cross(a.normal, b.normal);
            let (d_len, line_len) = (dot(d, d).sqrt(), dot(line, line).sqrt());
            let along_crease = dot(d, line).abs() > SINGULAR_COS * d_len * line_len;
            let convex = !along_crease && dot(sub(a.normal, b.normal), d) > 0.0;
            if !convex {
                let concavity = bend / self.concave_angle;
                if concavity >= 1.0 {
                    return Verdict {
                        cut: true,
                        evidence: (0.5 * concavity).min(1.0),
                    };
                }
                evidence = evidence.max(concavity);
            }
            let depth = 0.5 * (a.centroid[2] + b.centroid[2]);
            let offset = 0.5 * (dot(a.normal, d).abs() + dot(b.normal, d).abs());
            // A bend of the surface also offsets the planes: only count the
            // offset of (nearly) parallel planes, i.e. a height step.
            let parallel = (1.0 - bend / self.concave_angle).max(0.0);
            evidence = evidence.max(parallel * offset / (depth * self.offset_scale));
        }
        let evidence = evidence.min(1.0);
        let colour = sub(a.colour, b.colour);
        let cut = evidence >= self.weak_evidence && dot(colour, colour).sqrt() >= self.colour_cut;
        Verdict {
            cut,
            evidence: if cut { 0.5 * evidence } else { evidence },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RULES: BoundaryRules = BoundaryRules {
        step_share: 0.5,
        concave_angle: 0.25,
        offset_scale: 0.01,
        weak_evidence: 0.35,
        colour_cut: 0.25,
    };

    fn patch(centroid: [f32; 3], normal: [f32; 3], colour: f32) -> PatchStats {
        let len = dot(normal, normal).sqrt();
        PatchStats {
            pixels: 64,
            centroid,
            normal: normal.map(|c| c / len),
            colour: [colour; 3],
        }
    }

    fn edge(steps: u32) -> PatchEdge {
        PatchEdge {
            a: 0,
            b: 1,
            pairs: 10,
            steps,
        }
    }

    #[test]
    fn convex_ridge_joins_and_concave_crease_cuts() {
        // Seen from the camera at the origin looking +z, normals face -z.
        // Ridge: left face tilts left, right face tilts right, ridge nearest.
        let left = patch([-0.1, 0.0, 1.0], [-1.0, 0.0, -1.0], 0.5);
        let right = patch([0.1, 0.0, 1.0], [1.0, 0.0, -1.0], 0.5);
        assert!(!RULES.verdict(&edge(0), &left, &right).cut);
        // Inside corner: left wall faces right, right wall faces left.
        let left = patch([-0.1, 0.0, 1.0], [1.0, 0.0, -1.0], 0.5);
        let right = patch([0.1, 0.0, 1.0], [-1.0, 0.0, -1.0], 0.5);
        let v = RULES.verdict(&edge(0), &left, &right);
        assert!(v.cut && v.evidence > 0.9, "{v:?}");
    }

    #[test]
    fn steps_cut_and_colour_cuts_only_with_geometric_evidence() {
        let floor = patch([0.0, 0.0, 1.0], [0.0, 0.0, -1.0], 0.1);
        let white = patch([0.1, 0.0, 1.0], [0.0, 0.0, -1.0], 0.9);
        assert_eq!(
            RULES.verdict(&edge(6), &floor, &floor),
            Verdict {
                cut: true,
                evidence: 1.0
            }
        );
        // Coplanar black and white patches: a checker, not a boundary.
        assert!(!RULES.verdict(&edge(0), &floor, &white).cut);
        // A book 1 cm higher and white: cut; the same offset in one colour joins.
        let book = patch([0.1, 0.0, 0.99], [0.0, 0.0, -1.0], 0.9);
        assert!(RULES.verdict(&edge(0), &floor, &book).cut);
        let grey_book = patch([0.1, 0.0, 0.99], [0.0, 0.0, -1.0], 0.1);
        assert!(!RULES.verdict(&edge(0), &floor, &grey_book).cut);
    }
}
