//! Geometry-first segmentation without weights: objects are what depth
//! separates, texture never is (issue 18; the idea of LCCP, Stein et al.,
//! "Object Partitioning using Local Convexity", CVPR 2014).
//!
//! Recipe, on a 2× coarse grid of the RGB-D frame:
//! 1. Depth noise σ(1/z) from second differences, noise-gated smoothing,
//!    back-projected points and normals (shared with `classic`).
//! 2. Surface patches: each `cell` × `cell` block flood-filled over
//!    4-neighbours without a depth step, a colour edge, or a normal bent
//!    by more than `patch_max_bend` from the patch's mean so far; per patch
//!    the mean point x, unit normal n and colour. A step is judged in
//!    inverse depth w = 1/z, affine on planes: the step misses the line
//!    continued from either side by more than jump·w + kσ(w).
//! 3. Every boundary between adjacent patches a, b gets a verdict:
//!    - depth step: most boundary pixel pairs discontinuous → cut;
//!    - LCCP convexity: convex iff (n_a − n_b)·(x_a − x_b) > 0 (normals
//!      face the camera), not trusted when x_a − x_b runs along the crease
//!      line n_a × n_b (LCCP's sanity check); concave with bend
//!      ∠(n_a, n_b) > θ → cut; convex or flat → join (a box's faces, a
//!      ball, a wall stay whole); no normal → cut with no evidence;
//!    - colour only where geometry is undecided: weak evidence (a bend
//!      under θ, a plane offset |n·(x_a − x_b)| of parallel planes, a few
//!      step pairs) plus a colour edge between the patch means → cut (a
//!      flat book on a desk). Colour alone never cuts a boundary: a checker
//!      or brick pattern is one surface (step 4's flat objects are the one
//!      place colour alone decides, and never for a colour that repeats).
//! 4. Segments = connected components of patches over joined boundaries;
//!    pieces under `min_pixels` join the neighbour with the weakest cut;
//!    large planar segments in one plane that do not touch join, and small
//!    pieces in their colour with them ([`coplanar`]: one floor around a
//!    table's legs); object-sized segments that meet at a crease in one colour
//!    up to shading join ([`creases`]: a sofa's seat and back); a flat, plain,
//!    compact piece of a surface in a colour found nowhere else on it is split
//!    off ([`flat_objects`]: a picture on a wall, where no depth cue is left);
//!    then a connected piece of a mostly planar segment that lies parallel to
//!    its plane and a little above it is split off by height alone
//!    ([`raised`]: a keyboard on a desk, 1–2 cm proud, in any colour); last,
//!    the same test pixel by pixel on the painted segments ([`levels`]): a
//!    face parallel to a host surface and above it is an object when it lies in
//!    the host (a keyboard too narrow for whole patches), and a segment with
//!    such faces at two or more heights is a stack, split one object per
//!    height (books on a desk). A host's plane is fitted from its dominant
//!    face, so a desk seen with its legs is one.
//! 5. Holes without depth take the single segment around them, else 0.
//! 6. Confidence = boundary-length-weighted mean evidence of the segment's
//!    cut boundaries (a depth step is 1, a colour cut at most 0.5), times
//!    (confident_depth / z)² for a segment whose nearest tenth lies at z
//!    beyond `confident_depth`: depth noise grows as z², so what would part
//!    the segment is hidden more the further it lies (a stack of boxes is one
//!    segment from 2 m on, three up to 1.9 m), and a near view outweighs a
//!    far one in the consensus.
//! 7. Edge-aware upsampling to full resolution (shared with `classic`),
//!    label ids shuffled per frame like SAM's mask order.
//!
//! Decisions where the method is open:
//! - Patches are grid cells split by continuity, not LCCP's supervoxels:
//!   bounded size keeps a patch from leaking along a smooth crease, and
//!   costs one pass. Growth is checked against the patch's mean normal,
//!   so a smoothed crease (a few degrees per pixel) still stops it; what
//!   straddles a crease gets a blended normal, is cut from both sides and
//!   the small-piece rule gives it to one.
//! - Two boxes of equal height touching flush form one flat, coplanar top:
//!   no RGB-D cue separates them, so they stay one (as in LCCP).
//! - Colour joins across a crease, where LCCP always cuts: a sofa is a tall
//!   box touching a short one, and only its one material tells it from two
//!   boxes; two touching boxes of one colour are one object here.
//! - Connected components, not a graph cut: one wrong join merges two
//!   objects, but a stray wrong cut splits nothing unless it closes a
//!   contour, which is what keeps textured surfaces whole.

mod colour;
mod convexity;
mod coplanar;
mod creases;
mod flat_objects;
mod levels;
mod patches;
mod raised;
mod regions;

use crate::classic::downscale::CoarseFrame;
use crate::classic::graph::EdgeWeights;
use crate::classic::noise::DepthNoiseModel;
use crate::classic::normals::SurfaceGeometry;
use crate::classic::union_find::UnionFind;
use crate::classic::upsample::{upsample_segments, FullFrame};
use crate::classic::{coarse_camera, labels, smoothing};
use crate::{PerceptionError, Segmentation, Segmenter, SegmenterInput};
use convexity::{BoundaryRules, PatchEdge, Verdict};
use patches::Continuity;
use regions::NO_SEGMENT;

/// Tuning of the geometry segmenter; sizes are in coarse pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeometryParams {
    /// Work on `downscale` × `downscale` blocks (2 = half resolution).
    pub downscale: u32,
    /// Window radius of the noise-gated depth smoothing; 0 = off.
    pub smoothing_radius: u32,
    /// Depth-noise deviations ignored in steps and smoothing.
    pub noise_sigmas: f32,
    /// Patch grid cell side.
    pub cell: u32,
    /// Relative depth step (step / depth) between neighbours that separates.
    pub max_jump: f32,
    /// Angle (radians) from the patch's mean normal that stops its growth.
    pub patch_max_bend: f32,
    /// Share of step pairs from which a patch boundary is a depth step.
    pub step_share: f32,
    /// Concave bend (radians) from which a boundary cuts.
    pub concave_angle: f32,
    /// Plane offset / depth of parallel patches worth full evidence.
    pub offset_scale: f32,
    /// Geometric evidence (0..1) from which a colour edge cuts.
    pub weak_evidence: f32,
    /// RGB distance (channels 0..1) of patch means that is a colour edge.
    pub colour_cut: f32,
    /// Segments smaller than this join their weakest-bounded neighbour.
    pub min_pixels: u32,
    /// Planar segments of at least this share of the frame that lie in one plane
    /// (normals within `coplanar_angle`, offsets within `offset_scale` per metre) and do
    /// not touch are one surface seen around an occluder; 0 turns the join off.
    pub coplanar_min_share: f32,
    /// Smallest planar piece (share of the frame) that joins a coplanar group holding a
    /// segment of `coplanar_min_share`: the floor between chairs and table legs.
    pub coplanar_piece_share: f32,
    pub coplanar_angle: f32,
    /// Pixel share of a segment's patches that must lie on its plane (normal within
    /// `coplanar_angle`, offset within `offset_scale` per metre) for it to count as planar
    /// (0.8: with Kinect-like noise the floor under a table had 88–89 % of its pixels on its
    /// plane, the patches along the legs' edges bent, and stayed apart at 0.9).
    pub coplanar_inliers: f32,
    /// Segments of at most this share of the frame that meet at a crease (at most
    /// `crease_step_share` of the boundary's pixel pairs depth steps) in one colour up to
    /// shading are one object (a sofa's seat and back); 0 turns the join off.
    pub crease_max_share: f32,
    pub crease_step_share: f32,
    /// Smallest flat object in a colour found nowhere else on its surface, as a share of the
    /// frame, split off the surface it lies on ([`flat_objects`]: a picture on a wall); 0 turns
    /// the split off.
    pub flat_min_share: f32,
    /// Smallest object lying a little proud of a planar surface (a keyboard on a desk), as a
    /// share of the frame, split off it ([`raised`]); 0 turns the split off.
    pub raised_min_share: f32,
    /// Smallest height of such an object above the surface's plane, per metre of depth (0.004:
    /// 5 mm at 1.3 m, over a Kinect's ~5 mm depth steps there; chosen on scene 1's datasets).
    pub raised_min_raise: f32,
    /// Smallest face of a stack of flat objects (books on a desk), as a share of the frame;
    /// a segment with faces at two or more heights above its surface is split into one object
    /// per height ([`levels`]); 0 turns the split off.
    pub level_min_share: f32,
    /// Depth (m) beyond which a segment's confidence falls as (confident_depth / z)², z the
    /// depth of its nearest tenth: evidence is as strong as the depth noise lets it be;
    /// 0 turns the fall-off off.
    pub confident_depth: f32,
    /// Seeds the per-frame shuffle of label ids.
    pub seed: u64,
}

impl Default for GeometryParams {
    fn default() -> Self {
        Self {
            downscale: 2,
            smoothing_radius: 2,
            noise_sigmas: 5.0,
            cell: 8,
            max_jump: 0.04,
            patch_max_bend: 0.35,
            step_share: 0.5,
            concave_angle: 0.2,
            offset_scale: 0.012,
            weak_evidence: 0.35,
            colour_cut: 0.3,
            min_pixels: 40,
            coplanar_min_share: 0.05,
            coplanar_piece_share: 0.005,
            coplanar_angle: 0.1,
            coplanar_inliers: 0.8,
            crease_max_share: 0.15,
            crease_step_share: 0.25,
            flat_min_share: 0.005,
            raised_min_share: 0.003,
            raised_min_raise: 0.004,
            level_min_share: 0.0005,
            confident_depth: 1.5,
            seed: 0x6e0_5e9,
        }
    }
}

/// Geometry-first (LCCP-style) segmenter; keeps its buffers between frames.
#[derive(Debug, Clone, Default)]
pub struct GeometrySegmenter {
    params: GeometryParams,
    frames_done: u64,
    edges: Vec<PatchEdge>,
    sets: UnionFind,
}

impl GeometrySegmenter {
    pub fn new(params: GeometryParams) -> Result<Self, PerceptionError> {
        let positive = |x: f32| x.is_finite() && x > 0.0;
        let valid = params.downscale > 0
            && params.cell > 0
            && params.noise_sigmas.is_finite()
            && params.noise_sigmas >= 0.0
            && [
                params.max_jump,
                params.patch_max_bend,
                params.step_share,
                params.concave_angle,
                params.offset_scale,
                params.weak_evidence,
            ]
            .into_iter()
            .all(positive)
            && params.colour_cut.is_finite()
            && [
                params.coplanar_min_share,
                params.coplanar_piece_share,
                params.coplanar_angle,
                params.crease_max_share,
                params.crease_step_share,
                params.flat_min_share,
                params.raised_min_share,
                params.raised_min_raise,
                params.level_min_share,
                params.confident_depth,
            ]
            .into_iter()
            .all(|x| x.is_finite() && x >= 0.0)
            && (0.0..=1.0).contains(&params.coplanar_inliers);
        if !valid {
            return Err(PerceptionError::InvalidInput(format!(
                "geometry segmenter parameters out of range: {params:?}"
            )));
        }
        Ok(Self {
            params,
            ..Self::default()
        })
    }

    pub fn params(&self) -> &GeometryParams {
        &self.params
    }

    /// Steps 1–6 on the coarse grid: segment per coarse pixel (`NO_SEGMENT`
    /// for unfilled holes), confidence per segment.
    fn coarse_segments(
        &mut self,
        input: &SegmenterInput,
        coarse: &CoarseFrame,
        noise: &DepthNoiseModel,
    ) -> (Vec<u32>, Vec<f32>) {
        let p = self.params;
        let camera = coarse_camera(input, p.downscale as usize, coarse.width, coarse.height);
        let radius = p.smoothing_radius as usize;
        let smoothed = smoothing::smooth_depth(
            &coarse.depth_m,
            coarse.width,
            coarse.height,
            radius,
            noise,
            p.noise_sigmas,
        );
        let geometry = SurfaceGeometry::from_depth(
            &smoothed,
            coarse.width,
            coarse.height,
            &camera,
            NORMAL_MAX_JUMP,
        );
        let continuity = Continuity {
            max_jump: p.max_jump,
            // Raw (unsmoothed) coarse noise: steps are judged on raw depth;
            // a residual of two differences carries about 2σ.
            inverse_noise: 2.0 * p.noise_sigmas * noise.inverse_depth_sigma,
            min_normal_cos: p.patch_max_bend.cos(),
            max_colour: p.colour_cut,
        };
        let steps = continuity.map(&coarse.depth_m, coarse.width, coarse.height);
        let patches =
            patches::build_patches(coarse, &geometry, p.cell as usize, &continuity, &steps);
        convexity::patch_edges(&patches, &steps, coarse.width, &mut self.edges);
        let rules = BoundaryRules {
            step_share: p.step_share,
            concave_angle: p.concave_angle,
            offset_scale: p.offset_scale,
            weak_evidence: p.weak_evidence,
            colour_cut: p.colour_cut,
        };
        let verdicts: Vec<Verdict> = self
            .edges
            .iter()
            .map(|e| {
                let stats = &patches.stats;
                rules.verdict(e, &stats[e.a as usize], &stats[e.b as usize])
            })
            .collect();
        let pixels: Vec<u32> = patches.stats.iter().map(|s| s.pixels).collect();
        let (segment_of_patch, count) = regions::merge_patches(
            &self.edges,
            &verdicts,
            &pixels,
            p.min_pixels,
            &mut self.sets,
        );
        let coplanar = coplanar::CoplanarRules {
            min_share: p.coplanar_min_share,
            piece_share: p.coplanar_piece_share,
            max_angle: p.coplanar_angle,
            offset_scale: p.offset_scale,
            min_inliers: p.coplanar_inliers,
            // σ(z) = s·z² over a patch w coarse pixels wide (z·w/fx metres): twice σ / width.
            normal_noise: 2.0 * noise.inverse_depth_sigma * camera.fx as f32,
        };
        let (segment_of_patch, count) =
            coplanar.join(&patches.stats, &self.edges, &segment_of_patch, count);
        let (segment_of_patch, count) = creases::CreaseRules {
            max_share: p.crease_max_share,
            max_step_share: p.crease_step_share,
        }
        .join(&patches.stats, &self.edges, &segment_of_patch, count);
        let (segment_of_patch, count) = flat_objects::FlatObjectRules {
            min_share: p.flat_min_share,
        }
        .split(
            &patches.stats,
            &self.edges,
            &patches.of,
            coarse.width,
            &segment_of_patch,
            count,
        );
        let (segment_of_patch, count) = raised::RaisedRules {
            min_share: p.raised_min_share,
            min_raise: p.raised_min_raise,
            planes: coplanar,
        }
        .split(
            &patches.stats,
            &self.edges,
            &patches.of,
            coarse.width,
            &segment_of_patch,
            count,
        );
        let mut confidence =
            regions::segment_confidence(&self.edges, &verdicts, &segment_of_patch, count);
        let hosts = raised::host_planes(&coplanar, &patches.stats, &segment_of_patch, count);
        let mut segments =
            regions::paint_and_fill_holes(&patches.of, &segment_of_patch, coarse.width);
        let parents = levels::LevelRules {
            min_share: p.raised_min_share,
            min_level_share: p.level_min_share,
            min_raise: p.raised_min_raise,
        }
        .split(
            &mut segments,
            count,
            &geometry,
            coarse.width,
            &hosts,
            &mut self.sets,
        );
        // A piece split off by height keeps the evidence of the segment it came from.
        let inherited: Vec<f32> = parents.iter().map(|&s| confidence[s as usize]).collect();
        confidence.extend(inherited);
        if p.confident_depth > 0.0 {
            // Depth noise grows as z²: a far segment vouches less for having no boundary inside.
            let near =
                regions::near_depth(&segments, &coarse.depth_m, confidence.len(), NEAR_QUANTILE);
            for (c, z) in confidence.iter_mut().zip(near) {
                if z > p.confident_depth {
                    *c *= (p.confident_depth / z).powi(2);
                }
            }
        }
        (segments, confidence)
    }
}

impl Segmenter for GeometrySegmenter {
    fn name(&self) -> &str {
        "geometry"
    }

    fn segment(&mut self, input: &SegmenterInput) -> Result<Segmentation, PerceptionError> {
        input.validate()?;
        let p = self.params;
        let factor = p.downscale as usize;
        let coarse = CoarseFrame::of_input(input, factor);
        let noise = DepthNoiseModel::estimate(&coarse.depth_m, coarse.width, coarse.height);
        let (segments, confidence) = self.coarse_segments(input, &coarse, &noise);
        let count = confidence.len();
        let frame_seed = p.seed ^ self.frames_done.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        self.frames_done += 1;
        let mut label_of_segment = labels::shuffled_label_ids(count, frame_seed);
        // Index `count` stands for "no segment" (label 0) through the upsampling.
        label_of_segment.push(0);
        let coarse_segments: Vec<u32> = segments
            .iter()
            .map(|&s| if s == NO_SEGMENT { count as u32 } else { s })
            .collect();
        let full = FullFrame::of_input(input);
        let full_segments = upsample_segments(
            &full,
            &coarse,
            &coarse_segments,
            factor,
            &UPSAMPLE_WEIGHTS,
            &noise,
        );
        let mut confidence = confidence;
        confidence.push(0.0);
        Ok(labels::segmentation(
            input.width,
            input.height,
            &full_segments,
            &label_of_segment,
            &confidence,
        ))
    }
}

/// Share of a segment's pixels nearer than the depth its confidence is judged at.
const NEAR_QUANTILE: f32 = 0.1;

/// Relative step up to which normals difference across neighbours: wider
/// than `max_jump`, so grazing surfaces keep their normals.
const NORMAL_MAX_JUMP: f32 = 0.12;

/// Boundary pixels follow depth first, colour second (the normal term is
/// unused by the upsampling).
const UPSAMPLE_WEIGHTS: EdgeWeights = EdgeWeights {
    colour: 0.2,
    depth: 2.0,
    depth_gap_scale: 0.01,
    depth_cap: 4.0,
    depth_to_missing: 0.5,
    normal: 0.0,
    noise_sigmas: 3.0,
};

#[cfg(test)]
mod scenes;
#[cfg(test)]
mod tests;
