//! The ensemble semantic information generator (docs/METHOD.md §6): a tagger
//! proposes class names, an open-vocabulary detector turns them into boxes,
//! and every mask of the class-agnostic segmenter takes the class of the
//! box it overlaps with IoU > 0.5 (else `None`, score 0.0; see
//! [`crate::class_match`]).
//!
//! Export layouts (the names and shapes the runners feed and read; checked
//! at load time and by `opengs models check`):
//!
//! - **Tagger** — RAM/RAM++ as exported by recognize-anything's ONNX script
//!   (`torch.onnx.export(..., input_names=["image"], output_names=["tag"])`):
//!   `image[1,3,384,384]` float32, the frame stretched to 384×384 and
//!   ImageNet-normalised → `tag[1,T]`, one score per line of the tag list
//!   (`ram_tag_list.txt`, T = 4585 for RAM++). `tag` holds probabilities or
//!   the export's 0/1 decisions; an output named `logits` gets a sigmoid.
//!   Tags above 0.68 (RAM++'s class threshold) are proposed.
//! - **Detector** — YOLO-World with the text prompt as an input, the
//!   layout of `wkentaro/yolo-world-onnx` (`input_names=["images",
//!   "text_features"], output_names=["scores", "boxes"]`):
//!   `images[1,3,640,640]` (letterboxed, grey 114 border, RGB / 255) and
//!   `text_features[1,K,512]` (one L2-normalised CLIP text feature per
//!   prompted class) → `scores[1,N,K]` (sigmoid) and `boxes[1,N,4]`
//!   (x0, y0, x1, y1 in the 640 frame). The CLIP text features of the tags
//!   come precomputed in a `.npy` float32 `[T, 512]` file (row t = tag t),
//!   so no text encoder or tokenizer runs per frame. An export with a fixed
//!   K (e.g. 81) gets the prompts padded with zero features. Boxes scoring
//!   ≥ 0.25 survive class-agnostic NMS at IoU 0.7.
//!
//! Without a tagger the detector is prompted with every tag of the list.

mod detector;
mod image;
mod tagger;

pub use detector::Detector;
pub use image::{box_iou, letterbox, nms, Letterbox};
pub use tagger::{Tagger, DEFAULT_TAG_THRESHOLD};

use std::path::Path;

use crate::class_match::{classify, Detection};
use crate::npy::{read_f32_matrix, Matrix};
use crate::{EnsembleModelPaths, PerceptionError, Segmentation, Segmenter, SegmenterInput};

/// Tagger (optional) + detector with their tag names and text features.
pub struct Ensemble {
    tagger: Option<Tagger>,
    detector: Detector,
    tags: Vec<String>,
    features: Matrix,
}

impl std::fmt::Debug for Ensemble {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ensemble")
            .field("tagger", &self.tagger.is_some())
            .field("tags", &self.tags.len())
            .finish()
    }
}

impl Ensemble {
    /// Loads the models; the detector, tag list and text embeddings are required.
    pub fn new(paths: &EnsembleModelPaths, threads: usize) -> Result<Self, PerceptionError> {
        let missing = |what: &str| PerceptionError::Unavailable {
            kind: "ensemble".into(),
            reason: format!("needs {what}"),
        };
        let detector_path = paths
            .detector
            .as_ref()
            .ok_or_else(|| missing("a detector model (--detector) to turn tags into boxes"))?;
        let tag_list = paths
            .tag_list
            .as_ref()
            .ok_or_else(|| missing("a tag list (--tag-list), one class name per line"))?;
        let embeddings = paths.text_embeddings.as_ref().ok_or_else(|| {
            missing("the tags' text features (--text-embeddings, .npy float32 [tags, dim])")
        })?;
        let tags = read_tag_list(tag_list)?;
        let features = read_f32_matrix(embeddings)?;
        if features.rows != tags.len() {
            return Err(PerceptionError::File {
                path: embeddings.clone(),
                message: format!(
                    "{} rows of text features but {} has {} tags",
                    features.rows,
                    tag_list.display(),
                    tags.len()
                ),
            });
        }
        let tagger = paths
            .tagger
            .as_ref()
            .map(|p| Tagger::new(p, tags.len(), threads))
            .transpose()?;
        Ok(Self {
            tagger,
            detector: Detector::new(detector_path, features.cols, threads)?,
            tags,
            features,
        })
    }

    pub fn tags(&self) -> &[String] {
        &self.tags
    }

    /// Tag indices proposed for this frame (all tags without a tagger).
    pub fn proposed_tags(&mut self, input: &SegmenterInput) -> Result<Vec<usize>, PerceptionError> {
        match &mut self.tagger {
            Some(t) => Ok(t.present(input)?.into_iter().map(|(i, _)| i).collect()),
            None => Ok((0..self.tags.len()).collect()),
        }
    }

    /// Tagger → detector: the frame's boxes with class names.
    pub fn detections(
        &mut self,
        input: &SegmenterInput,
    ) -> Result<Vec<Detection>, PerceptionError> {
        let prompts = self.proposed_tags(input)?;
        self.detector
            .detect(input, &prompts, &self.tags, &self.features)
    }
}

/// Reads one tag per line; blank lines are errors (they would shift indices).
pub fn read_tag_list(path: &Path) -> Result<Vec<String>, PerceptionError> {
    let error = |message: String| PerceptionError::File {
        path: path.to_path_buf(),
        message,
    };
    let text = std::fs::read_to_string(path).map_err(|e| error(e.to_string()))?;
    let tags: Vec<String> = text.lines().map(|l| l.trim().to_string()).collect();
    if let Some(i) = tags.iter().position(String::is_empty) {
        return Err(error(format!(
            "line {} is blank: one tag name per line",
            i + 1
        )));
    }
    if tags.is_empty() {
        return Err(error("no tags".into()));
    }
    Ok(tags)
}

/// Any segmenter plus the ensemble: its masks get class names and scores.
pub struct EnsembleSegmenter {
    inner: Box<dyn Segmenter>,
    ensemble: Ensemble,
}

impl EnsembleSegmenter {
    pub fn new(inner: Box<dyn Segmenter>, ensemble: Ensemble) -> Self {
        Self { inner, ensemble }
    }
}

impl Segmenter for EnsembleSegmenter {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn segment(&mut self, input: &SegmenterInput) -> Result<Segmentation, PerceptionError> {
        let mut seg = self.inner.segment(input)?;
        let detections = self.ensemble.detections(input)?;
        classify(&mut seg, &detections);
        Ok(seg)
    }
}
