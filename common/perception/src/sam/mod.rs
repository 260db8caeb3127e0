//! SAM-family ONNX runners (SAM ViT, MobileSAMv2 share the exported
//! encoder/decoder signature): the encoder runs once per frame, the prompt
//! decoder once per prompt, then automatic mask generation. Prompts are a
//! point grid (SAM's automatic mask generator) or, with a box-proposal model
//! (MobileSAMv2), one box per proposed object: the two corners with labels
//! 2 and 3, the standard SAM decoder export's box encoding.

mod amg;
mod bitmask;
mod preprocess;
mod proposals;
pub(crate) mod runtime;

pub use amg::AmgParams;
pub use proposals::BoxProposer;

use std::path::{Path, PathBuf};

pub use crate::SamModelPaths;

use ndarray::{Array1, Array2, Array3, Array4, ArrayD};
use ort::session::Session;
use ort::value::TensorRef;

use crate::model_check::{load_checked, ModelRole};
use crate::{PerceptionError, Segmentation, Segmenter, SegmenterInput, SegmenterKind};
use preprocess::{encoder_input, resize_scale};

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
        Ok(Self {
            kind,
            encoder: load_checked(&paths.encoder, ModelRole::Encoder, threads)?,
            decoder: load_checked(&paths.decoder, ModelRole::Decoder, threads)?,
            encoder_path: paths.encoder.clone(),
            decoder_path: paths.decoder.clone(),
            proposer: None,
            params,
            frames_done: 0,
        })
    }

    /// Prompts the decoder with the boxes of a proposal model (MobileSAMv2)
    /// instead of the point grid.
    pub fn with_box_proposals(mut self, proposer: BoxProposer) -> Self {
        self.proposer = Some(proposer);
        self
    }

    fn embed(&mut self, input: &SegmenterInput) -> Result<ArrayD<f32>, PerceptionError> {
        let image = encoder_input(input.rgb, input.width as usize, input.height as usize);
        let path = self.encoder_path.clone();
        let outputs = self
            .encoder
            .run(ort::inputs!["image" => tensor(&image, &path)?])
            .map_err(|e| model_error(&path, e))?;
        let embeddings = outputs
            .get("image_embeddings")
            .ok_or_else(|| model_error(&path, "no output named image_embeddings"))?
            .try_extract_array::<f32>()
            .map_err(|e| model_error(&path, e))?;
        Ok(embeddings.to_owned())
    }

    /// Decoder logits [C, H, W] and predicted IoUs [C] for one prompt:
    /// `points` in image pixels with SAM's labels (1 = foreground point,
    /// −1 = padding, 2/3 = box corners).
    fn decode(
        &mut self,
        embeddings: &ArrayD<f32>,
        points: &[([f32; 2], f32)],
        input: &SegmenterInput,
    ) -> Result<(ArrayD<f32>, Vec<f32>), PerceptionError> {
        let scale = resize_scale(input.width as usize, input.height as usize);
        let coords = Array3::from_shape_vec(
            (1, points.len(), 2),
            points
                .iter()
                .flat_map(|(p, _)| [p[0] * scale, p[1] * scale])
                .collect(),
        )
        .map_err(|e| PerceptionError::InvalidInput(e.to_string()))?;
        let labels =
            Array2::from_shape_vec((1, points.len()), points.iter().map(|p| p.1).collect())
                .map_err(|e| PerceptionError::InvalidInput(e.to_string()))?;
        let mask_input = Array4::<f32>::zeros((1, 1, 256, 256));
        let has_mask = Array1::from_vec(vec![0.0f32]);
        let size = Array1::from_vec(vec![input.height as f32, input.width as f32]);
        let path = self.decoder_path.clone();
        let outputs = self
            .decoder
            .run(ort::inputs![
                "image_embeddings" => tensor(embeddings, &path)?,
                "point_coords" => tensor(&coords, &path)?,
                "point_labels" => tensor(&labels, &path)?,
                "mask_input" => tensor(&mask_input, &path)?,
                "has_mask_input" => tensor(&has_mask, &path)?,
                "orig_im_size" => tensor(&size, &path)?,
            ])
            .map_err(|e| model_error(&path, e))?;
        let output = |name: &str| {
            outputs
                .get(name)
                .ok_or_else(|| model_error(&path, format!("no output named {name}")))?
                .try_extract_array::<f32>()
                .map_err(|e| model_error(&path, e))
        };
        let masks = output("masks")?;
        let ious = output("iou_predictions")?;
        let shape = masks.shape().to_vec();
        let (h, w) = (input.height as usize, input.width as usize);
        if shape.len() != 4 || shape[0] != 1 || shape[2] != h || shape[3] != w {
            return Err(model_error(
                &path,
                format!("masks has shape {shape:?}, expected [1, C, {h}, {w}]"),
            ));
        }
        let ious: Vec<f32> = ious.iter().copied().collect();
        if ious.len() != shape[1] {
            return Err(model_error(
                &path,
                format!("{} IoU predictions for {} masks", ious.len(), shape[1]),
            ));
        }
        let masks = masks
            .to_owned()
            .into_shape_with_order(vec![shape[1], h, w])
            .map_err(|e| model_error(&path, e))?;
        Ok((masks, ious))
    }
}

impl Segmenter for SamSegmenter {
    fn name(&self) -> &str {
        self.kind.as_str()
    }

    fn segment(&mut self, input: &SegmenterInput) -> Result<Segmentation, PerceptionError> {
        input.validate()?;
        let (w, h) = (input.width as usize, input.height as usize);
        let embeddings = self.embed(input)?;
        let mut candidates = Vec::new();
        if let Some(proposer) = &mut self.proposer {
            // MobileSAMv2: one box prompt per proposed object; of the
            // decoder's masks, the one of highest predicted IoU that passes
            // the filters.
            let boxes = proposer.propose(input)?;
            for b in boxes {
                let prompt = [([b[0], b[1]], 2.0), ([b[2], b[3]], 3.0)];
                let (masks, ious) = self.decode(&embeddings, &prompt, input)?;
                let mut order: Vec<usize> = (0..ious.len()).collect();
                order.sort_by(|&a, &b| ious[b].total_cmp(&ious[a]));
                let best = order.into_iter().find_map(|c| {
                    let logits = masks.index_axis(ndarray::Axis(0), c);
                    amg::candidate(logits.as_slice().unwrap_or(&[]), w, ious[c], &self.params)
                });
                candidates.extend(best);
            }
        } else {
            for point in amg::point_grid(self.params.points_per_side, w, h) {
                // One positive point plus SAM's padding point (label −1) for "no box".
                let prompt = [(point, 1.0), ([0.0, 0.0], -1.0)];
                let (masks, ious) = self.decode(&embeddings, &prompt, input)?;
                for (c, &iou) in ious.iter().enumerate() {
                    let logits = masks.index_axis(ndarray::Axis(0), c);
                    let logits = logits.as_slice().unwrap_or(&[]);
                    if let Some(m) = amg::candidate(logits, w, iou, &self.params) {
                        candidates.push(m);
                    }
                }
            }
        }
        let kept = amg::non_max_suppression(candidates, self.params.nms_iou_thresh);
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
