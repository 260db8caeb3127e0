//! SAM-family ONNX runners (SAM ViT, MobileSAMv2 share the exported
//! encoder/decoder signature): the encoder runs once per frame, the prompt
//! decoder once per prompt, then automatic mask generation ([`amg`]). Prompts
//! are a point grid (SAM's automatic mask generator) or, with a box-proposal
//! model (MobileSAMv2), one box per proposed object: the two corners with
//! labels 2 and 3, the standard SAM decoder export's box encoding.
//!
//! Both take the same cheap path: the decoder is asked only for
//! `iou_predictions` and the 256 × 256 `low_res_masks` (with a small
//! `orig_im_size`, so an export that computes `masks` anyway upsamples to
//! little), masks are filtered and suppressed there, and only the kept ones
//! are upsampled to the frame. The standard export (and `models check`'s
//! decoder role) fixes the prompt batch at 1 (`point_coords[1, N, 2]`, the N
//! points being one prompt), so prompts run one decoder call each; what is
//! batched is the per-frame setup: the embeddings and constant inputs are
//! bound once and only the two prompt points change between calls.

mod amg;
mod bitmask;
mod preprocess;
mod proposals;
#[cfg(test)]
mod reference;
pub(crate) mod runtime;

pub use amg::{
    AmgParams, LowResFrame, MaskGenerator, Survivor, DEFAULT_POINTS_PER_SIDE,
    EXACT_STABILITY_MARGIN, LOW_RES_SIDE,
};
pub use proposals::BoxProposer;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

pub use crate::SamModelPaths;

use ndarray::{Array1, Array2, Array3, Array4, ArrayD, IxDyn};
use ort::session::{HasSelectedOutputs, OutputSelector, RunOptions, Session};
use ort::value::TensorRef;

use crate::model_check::{load_checked, ModelRole};
use crate::{PerceptionError, Segmentation, Segmenter, SegmenterInput, SegmenterKind};
use preprocess::{encoder_input_into, resize_scale};

/// Wall time spent inside model runs (encoder, decoder, box proposals),
/// shared with whoever splits a frame's cost into model time and ours (the bench).
#[derive(Debug, Clone, Default)]
pub struct ModelClock(Arc<AtomicU64>);

impl ModelClock {
    /// Time accumulated since the last `take`, and restarts from zero.
    pub fn take(&self) -> Duration {
        Duration::from_nanos(self.0.swap(0, Ordering::Relaxed))
    }

    pub(crate) fn add(&self, d: Duration) {
        self.0
            .fetch_add(d.as_nanos().min(u64::MAX as u128) as u64, Ordering::Relaxed);
    }

    /// Runs `f` (one model inference) and adds its wall time.
    pub(crate) fn time<T>(&self, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        self.add(start.elapsed());
        out
    }
}

/// Class-agnostic "segment everything" with a SAM-style model pair.
pub struct SamSegmenter {
    kind: SegmenterKind,
    encoder: Session,
    decoder: Session,
    encoder_path: PathBuf,
    decoder_path: PathBuf,
    proposer: Option<BoxProposer>,
    params: AmgParams,
    frames_done: u64,
    clock: ModelClock,
    /// Reused from frame to frame: encoder input, embeddings, decoder inputs, AMG buffers.
    image: Array4<f32>,
    embeddings: ArrayD<f32>,
    prompt: PromptInputs,
    decoder_options: RunOptions<HasSelectedOutputs>,
    generator: MaskGenerator,
}

/// The decoder's inputs; per prompt only the two points change.
struct PromptInputs {
    /// [1, 2, 2] in the 1024 frame: a point plus SAM's padding point, or two box corners.
    coords: Array3<f32>,
    labels: Array2<f32>,
    mask_input: Array4<f32>,
    has_mask: Array1<f32>,
    /// The size `masks` would have: the low-resolution frame's, not the image's.
    size: Array1<f32>,
}

impl std::fmt::Debug for SamSegmenter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SamSegmenter")
            .field("kind", &self.kind)
            .field("encoder", &self.encoder_path)
            .field("decoder", &self.decoder_path)
            .field("box_prompts", &self.proposer.is_some())
            .field("params", &self.params)
            .finish()
    }
}

impl SamSegmenter {
    /// Loads both models; `kind` must be `Sam` or `MobileSamV2`.
    pub fn new(
        kind: SegmenterKind,
        paths: &SamModelPaths,
        params: AmgParams,
        threads: usize,
    ) -> Result<Self, PerceptionError> {
        if !matches!(kind, SegmenterKind::Sam | SegmenterKind::MobileSamV2) {
            return Err(PerceptionError::InvalidInput(format!(
                "{kind} is not a SAM-family segmenter"
            )));
        }
        let decoder_options = RunOptions::new()
            .map_err(|e| model_error(&paths.decoder, e))?
            .with_outputs(
                OutputSelector::no_default()
                    .with("iou_predictions")
                    .with("low_res_masks"),
            );
        Ok(Self {
            kind,
            encoder: load_checked(&paths.encoder, ModelRole::Encoder, threads)?,
            decoder: load_checked(&paths.decoder, ModelRole::Decoder, threads)?,
            encoder_path: paths.encoder.clone(),
            decoder_path: paths.decoder.clone(),
            proposer: None,
            params,
            frames_done: 0,
            clock: ModelClock::default(),
            image: Array4::zeros((0, 0, 0, 0)),
            embeddings: ArrayD::zeros(IxDyn(&[0])),
            prompt: PromptInputs {
                coords: Array3::zeros((1, 2, 2)),
                labels: Array2::zeros((1, 2)),
                mask_input: Array4::zeros((1, 1, LOW_RES_SIDE, LOW_RES_SIDE)),
                has_mask: Array1::zeros(1),
                size: Array1::zeros(2),
            },
            decoder_options,
            generator: MaskGenerator::default(),
        })
    }

    /// Prompts the decoder with the boxes of a proposal model (MobileSAMv2)
    /// instead of the point grid.
    pub fn with_box_proposals(mut self, mut proposer: BoxProposer) -> Self {
        proposer.clock = self.clock.clone();
        self.proposer = Some(proposer);
        self
    }

    /// Adds this runner's model time to `clock` (the bench reads it).
    pub fn with_model_clock(mut self, clock: ModelClock) -> Self {
        if let Some(p) = &mut self.proposer {
            p.clock = clock.clone();
        }
        self.clock = clock;
        self
    }

    /// Runs the encoder into `self.embeddings`.
    fn embed(&mut self, input: &SegmenterInput) -> Result<(), PerceptionError> {
        encoder_input_into(
            &mut self.image,
            input.rgb,
            input.width as usize,
            input.height as usize,
        );
        let path = &self.encoder_path;
        let inputs = ort::inputs!["image" => tensor(&self.image, path)?];
        let encoder = &mut self.encoder;
        let outputs = self
            .clock
            .time(|| encoder.run(inputs))
            .map_err(|e| model_error(path, e))?;
        let embeddings = outputs
            .get("image_embeddings")
            .ok_or_else(|| model_error(path, "no output named image_embeddings"))?
            .try_extract_array::<f32>()
            .map_err(|e| model_error(path, e))?;
        if self.embeddings.shape() != embeddings.shape() {
            self.embeddings = ArrayD::zeros(embeddings.raw_dim());
        }
        self.embeddings.assign(&embeddings);
        Ok(())
    }

    /// One decoder run for the prompt `points` (image pixels, SAM's labels:
    /// 1 = foreground point, −1 = padding, 2/3 = box corners); its masks go
    /// to the generator: all of them, or with `best_only` the one of highest
    /// predicted IoU that passes the filters.
    fn decode(
        &mut self,
        points: [([f32; 2], f32); 2],
        prompt: usize,
        best_only: bool,
        scale: f32,
    ) -> Result<(), PerceptionError> {
        for (k, (p, label)) in points.iter().enumerate() {
            self.prompt.coords[[0, k, 0]] = p[0] * scale;
            self.prompt.coords[[0, k, 1]] = p[1] * scale;
            self.prompt.labels[[0, k]] = *label;
        }
        let path = &self.decoder_path;
        let p = &self.prompt;
        let inputs = ort::inputs![
            "image_embeddings" => tensor(&self.embeddings, path)?,
            "point_coords" => tensor(&p.coords, path)?,
            "point_labels" => tensor(&p.labels, path)?,
            "mask_input" => tensor(&p.mask_input, path)?,
            "has_mask_input" => tensor(&p.has_mask, path)?,
            "orig_im_size" => tensor(&p.size, path)?,
        ];
        let (decoder, options) = (&mut self.decoder, &self.decoder_options);
        let outputs = self
            .clock
            .time(|| decoder.run_with_options(inputs, options))
            .map_err(|e| model_error(path, e))?;
        let output = |name: &str| {
            outputs
                .get(name)
                .ok_or_else(|| model_error(path, format!("no output named {name}")))?
                .try_extract_array::<f32>()
                .map_err(|e| model_error(path, e))
        };
        let masks = output("low_res_masks")?;
        let ious = output("iou_predictions")?;
        let shape = masks.shape();
        let side = LOW_RES_SIDE;
        if shape.len() != 4 || shape[0] != 1 || shape[2] != side || shape[3] != side {
            return Err(model_error(
                path,
                format!("low_res_masks has shape {shape:?}, expected [1, C, {side}, {side}]"),
            ));
        }
        let ious = ious
            .as_slice()
            .ok_or_else(|| model_error(path, "iou_predictions is not contiguous"))?;
        if ious.len() != shape[1] {
            return Err(model_error(
                path,
                format!("{} IoU predictions for {} masks", ious.len(), shape[1]),
            ));
        }
        let masks = masks
            .as_slice()
            .ok_or_else(|| model_error(path, "low_res_masks is not contiguous"))?;
        let plane = side * side;
        self.generator.offer_prompt(
            |c| &masks[c * plane..(c + 1) * plane],
            ious,
            prompt,
            best_only,
            &self.params,
        );
        Ok(())
    }
}

impl Segmenter for SamSegmenter {
    fn name(&self) -> &str {
        self.kind.as_str()
    }

    fn segment(&mut self, input: &SegmenterInput) -> Result<Segmentation, PerceptionError> {
        input.validate()?;
        let (w, h) = (input.width as usize, input.height as usize);
        self.embed(input)?;
        let frame = LowResFrame::new(w, h, LOW_RES_SIDE);
        self.generator.begin(frame);
        self.prompt.size.assign(&Array1::from_vec(vec![
            frame.rows as f32,
            frame.cols as f32,
        ]));
        let scale = resize_scale(w, h);
        let boxes = match &mut self.proposer {
            Some(proposer) => Some(proposer.propose(input)?),
            None => None,
        };
        if let Some(boxes) = boxes {
            // MobileSAMv2: one box prompt per proposed object, one mask each.
            for (i, b) in boxes.iter().enumerate() {
                self.decode([([b[0], b[1]], 2.0), ([b[2], b[3]], 3.0)], i, true, scale)?;
            }
        } else {
            for (i, point) in amg::point_grid(self.params.points_per_side, w, h)
                .into_iter()
                .enumerate()
            {
                // One positive point plus SAM's padding point (label −1) for "no box".
                self.decode([(point, 1.0), ([0.0, 0.0], -1.0)], i, false, scale)?;
            }
        }
        self.generator.suppress(self.params.nms_iou_thresh);
        let kept = self.generator.upsample_kept(self.params.min_mask_pixels);
        let seed = self.params.seed ^ self.frames_done.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        self.frames_done += 1;
        Ok(amg::paint(kept, input.width, input.height, seed))
    }
}

pub(crate) fn tensor<'a, D: ndarray::Dimension + 'static>(
    array: &'a ndarray::Array<f32, D>,
    path: &Path,
) -> Result<TensorRef<'a, f32>, PerceptionError> {
    TensorRef::from_array_view(array).map_err(|e| model_error(path, e))
}

pub(crate) fn model_error(path: &Path, e: impl std::fmt::Display) -> PerceptionError {
    PerceptionError::Model {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}
