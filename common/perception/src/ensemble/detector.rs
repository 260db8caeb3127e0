//! YOLO-World with a text-feature prompt: boxes for the prompted classes.

use std::path::{Path, PathBuf};

use ndarray::Array3;
use ort::session::Session;

use super::image::{letterbox, nms};
use crate::class_match::Detection;
use crate::model_check::{load_checked, session_signature, ModelRole};
use crate::npy::Matrix;
use crate::sam::{model_error, tensor};
use crate::{PerceptionError, SegmenterInput};

/// Input side when the model leaves it dynamic (YOLO-World exports use 640).
const DEFAULT_SIDE: usize = 640;

pub struct Detector {
    session: Session,
    path: PathBuf,
    side: usize,
    /// The export's fixed number of prompts (e.g. 81), if any: fewer prompts
    /// are padded with zero features, more are cut.
    fixed_prompts: Option<usize>,
    /// Boxes scoring below this are dropped (ultralytics' default 0.25).
    pub score_threshold: f32,
    /// Class-agnostic NMS on box IoU (YOLO-World's deploy default 0.7).
    pub nms_iou: f32,
    pub max_detections: usize,
}

impl Detector {
    /// Loads `path`; `text_dim` is the width of the text features it will get.
    pub fn new(path: &Path, text_dim: usize, threads: usize) -> Result<Self, PerceptionError> {
        let session = load_checked(path, ModelRole::Detector, threads)?;
        let sig = session_signature(&session);
        let input = |name: &str| {
            sig.inputs
                .iter()
                .find(|t| t.name == name)
                .map(|t| t.shape.clone())
                .ok_or_else(|| model_error(path, format!("no input named {name}")))
        };
        let images = input("images")?;
        let text = input("text_features")?;
        if images[2] > 0 && images[3] > 0 && images[2] != images[3] {
            return Err(model_error(
                path,
                format!("images input {images:?} is not square"),
            ));
        }
        let side = if images[2] > 0 {
            images[2] as usize
        } else {
            DEFAULT_SIDE
        };
        if text[2] > 0 && text[2] as usize != text_dim {
            return Err(model_error(
                path,
                format!(
                    "takes {}-wide text features, the text embeddings file has {text_dim}",
                    text[2]
                ),
            ));
        }
        Ok(Self {
            session,
            path: path.to_path_buf(),
            side,
            fixed_prompts: (text[1] > 0).then_some(text[1] as usize),
            score_threshold: 0.25,
            nms_iou: 0.7,
            max_detections: 100,
        })
    }

    /// Boxes of the classes `prompts` (indices into `names` and rows of
    /// `features`), in image pixels, best first.
    pub fn detect(
        &mut self,
        input: &SegmenterInput,
        prompts: &[usize],
        names: &[String],
        features: &Matrix,
    ) -> Result<Vec<Detection>, PerceptionError> {
        let prompts = match self.fixed_prompts {
            Some(k) => &prompts[..prompts.len().min(k)],
            None => prompts,
        };
        if prompts.is_empty() {
            return Ok(Vec::new());
        }
        let k = self.fixed_prompts.unwrap_or(prompts.len());
        let dim = features.cols;
        let mut text = Array3::<f32>::zeros((1, k, dim));
        for (slot, &tag) in prompts.iter().enumerate() {
            let row = features.row(tag);
            // CLIP text features are compared after L2 normalisation.
            let norm = row.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
            for (d, v) in row.iter().enumerate() {
                text[[0, slot, d]] = v / norm;
            }
        }
        let (w, h) = (input.width as usize, input.height as usize);
        let (image, geometry) = letterbox(input.rgb, w, h, self.side);
        let path = &self.path;
        let outputs = self
            .session
            .run(ort::inputs![
                "images" => tensor(&image, path)?,
                "text_features" => tensor(&text, path)?,
            ])
            .map_err(|e| model_error(path, e))?;
        let output = |name: &str| {
            outputs
                .get(name)
                .ok_or_else(|| model_error(path, format!("no output named {name}")))?
                .try_extract_array::<f32>()
                .map_err(|e| model_error(path, e))
        };
        let scores = output("scores")?;
        let boxes = output("boxes")?;
        let (ss, bs) = (scores.shape().to_vec(), boxes.shape().to_vec());
        if ss.len() != 3 || bs.len() != 3 || bs[2] != 4 || ss[1] != bs[1] || ss[2] < prompts.len() {
            return Err(model_error(
                path,
                format!("scores {ss:?} and boxes {bs:?} do not fit [1,N,{k}] and [1,N,4]"),
            ));
        }
        let mut found_boxes = Vec::new();
        let mut found = Vec::new();
        for n in 0..ss[1] {
            let best = (0..prompts.len())
                .map(|c| (c, scores[[0, n, c]]))
                .filter(|(_, s)| s.is_finite())
                .max_by(|a, b| a.1.total_cmp(&b.1));
            let Some((c, score)) = best else { continue };
            if score < self.score_threshold {
                continue;
            }
            let b = [
                boxes[[0, n, 0]],
                boxes[[0, n, 1]],
                boxes[[0, n, 2]],
                boxes[[0, n, 3]],
            ];
            if b.iter().all(|v| v.is_finite()) {
                found_boxes.push(b);
                found.push((c, score));
            }
        }
        let scores: Vec<f32> = found.iter().map(|f| f.1).collect();
        Ok(
            nms(&found_boxes, &scores, self.nms_iou, self.max_detections)
                .into_iter()
                .map(|i| Detection {
                    bbox: geometry.to_image(found_boxes[i]),
                    class: names[prompts[found[i].0]].clone(),
                    score: found[i].1.clamp(0.0, 1.0),
                })
                .collect(),
        )
    }
}
