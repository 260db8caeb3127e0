//! "Segment everything" without weights: Felzenszwalb–Huttenlocher graph
//! segmentation over colour, depth gaps and normal angles (docs/METHOD.md §6).

mod confidence;
pub(crate) mod downscale;
mod felzenszwalb;
pub(crate) mod graph;
pub(crate) mod labels;
pub(crate) mod noise;
pub(crate) mod normals;
pub(crate) mod smoothing;
pub(crate) mod union_find;
pub(crate) mod upsample;

pub use graph::EdgeWeights;

use crate::{PerceptionError, Segmentation, Segmenter, SegmenterInput};
use downscale::CoarseFrame;
use graph::{Edge, NoiseTolerance};
use noise::DepthNoiseModel;
use normals::SurfaceGeometry;
use union_find::UnionFind;
use upsample::FullFrame;

/// Tuning of the classic segmenter; sizes are in coarse pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassicParams {
    /// Work on `downscale` × `downscale` blocks (2 = half resolution).
    pub downscale: u32,
    /// FH scale k: larger gives larger segments.
    pub k: f32,
    /// Segments smaller than this (coarse pixels) join their best neighbour.
    pub min_size: u32,
    pub weights: EdgeWeights,
    /// 8-connected pixel graph (else 4-connected).
    pub eight_connected: bool,
    /// Relative depth step beyond which normals are not differenced.
    pub normal_max_jump: f32,
    /// Window radius (coarse pixels) of the noise-gated depth smoothing
    /// applied before normals and gaps; 0 = off.
    pub smoothing_radius: u32,
    /// Seeds the per-frame shuffle of label ids.
    pub seed: u64,
}

impl Default for ClassicParams {
    fn default() -> Self {
        Self {
            downscale: 2,
            k: 8.0,
            min_size: 40,
            weights: EdgeWeights {
                colour: 0.5,
                depth: 2.0,
                depth_gap_scale: 0.01,
                depth_cap: 4.0,
                depth_to_missing: 0.5,
                normal: 2.0,
                noise_sigmas: 3.0,
            },
            eight_connected: true,
            normal_max_jump: 0.05,
            smoothing_radius: 2,
            seed: 0x5e6_c1a5,
        }
    }
}

/// Classic graph-based segmenter; keeps its buffers between frames.
#[derive(Debug, Clone, Default)]
pub struct ClassicSegmenter {
    params: ClassicParams,
    frames_done: u64,
    edges: Vec<Edge>,
    scratch: Vec<Edge>,
    sets: UnionFind,
}

impl ClassicSegmenter {
    pub fn new(params: ClassicParams) -> Result<Self, PerceptionError> {
        let w = &params.weights;
        let finite_non_negative = [
            w.colour,
            w.depth,
            w.depth_cap,
            w.depth_to_missing,
            w.normal,
            w.noise_sigmas,
            params.k,
        ]
        .iter()
        .all(|x| x.is_finite() && *x >= 0.0);
        let positive = |x: f32| x.is_finite() && x > 0.0;
        let valid = params.downscale > 0
            && finite_non_negative
            && positive(w.depth_gap_scale)
            && positive(params.normal_max_jump);
        if !valid {
            return Err(PerceptionError::InvalidInput(format!(
                "classic segmenter parameters out of range: {params:?}"
            )));
        }
        Ok(Self {
            params,
            ..Self::default()
        })
    }

    pub fn params(&self) -> &ClassicParams {
        &self.params
    }
}

impl Segmenter for ClassicSegmenter {
    fn name(&self) -> &str {
        "classic"
    }

    fn segment(&mut self, input: &SegmenterInput) -> Result<Segmentation, PerceptionError> {
        input.validate()?;
        let p = self.params;
        let factor = p.downscale as usize;
        let coarse = CoarseFrame::of_input(input, factor);
        let camera = coarse_camera(input, factor, coarse.width, coarse.height);
        let noise = DepthNoiseModel::estimate(&coarse.depth_m, coarse.width, coarse.height);
        let radius = p.smoothing_radius as usize;
        let smoothed = smoothing::smooth_depth(
            &coarse.depth_m,
            coarse.width,
            coarse.height,
            radius,
            &noise,
            p.weights.noise_sigmas,
        );
        // Averaging a (2r+1)² window divides the noise by about 2r+1.
        let smoothed_sigma = noise.inverse_depth_sigma / (2 * radius + 1) as f32;
        let tolerance = NoiseTolerance::new(
            smoothed_sigma,
            camera.fx.min(camera.fy) as f32,
            p.weights.noise_sigmas,
        );
        let geometry = SurfaceGeometry::from_depth(
            &smoothed,
            coarse.width,
            coarse.height,
            &camera,
            p.normal_max_jump,
        );
        graph::build_sorted_edges(
            &coarse,
            &geometry,
            &p.weights,
            &tolerance,
            p.eight_connected,
            &mut self.edges,
            &mut self.scratch,
        );
        let vertices = coarse.width * coarse.height;
        felzenszwalb::segment_graph(&self.edges, vertices, p.k, p.min_size, &mut self.sets);
        let (segment_of, count) = labels::compact_components(&mut self.sets, vertices);
        let confidence = confidence::segment_confidence(&self.edges, &segment_of, count);
        let frame_seed = p.seed ^ self.frames_done.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        self.frames_done += 1;
        let label_of_segment = labels::shuffled_label_ids(count, frame_seed);
        let full = FullFrame::of_input(input);
        let full_segments =
            upsample::upsample_segments(&full, &coarse, &segment_of, factor, &p.weights, &noise);
        Ok(labels::segmentation(
            input.width,
            input.height,
            &full_segments,
            &label_of_segment,
            &confidence,
        ))
    }
}

/// The input camera at the coarse grid (block centres as pixel centres).
pub(crate) fn coarse_camera(
    input: &SegmenterInput,
    factor: usize,
    width: usize,
    height: usize,
) -> opengs_geometry::Intrinsics {
    let mut k = input.intrinsics.scaled(1.0 / factor as f64);
    k.width = width as u32;
    k.height = height as u32;
    k
}
