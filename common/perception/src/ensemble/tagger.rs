//! RAM/RAM++ tagger: which of its T tags are in the image.

use std::path::{Path, PathBuf};

use ort::session::Session;

use super::image::stretch_normalised;
use crate::model_check::{load_checked, ModelRole};
use crate::sam::{model_error, tensor};
use crate::{PerceptionError, SegmenterInput};

/// RAM++'s default class threshold on the tag probability.
pub const DEFAULT_TAG_THRESHOLD: f32 = 0.68;
/// Input side when the model leaves it dynamic (RAM/RAM++ use 384).
const DEFAULT_SIDE: usize = 384;

pub struct Tagger {
    session: Session,
    path: PathBuf,
    /// Model input width, height.
    size: (usize, usize),
    output: String,
    /// The output holds logits (apply a sigmoid), not probabilities/0-1 targets.
    logits: bool,
    tags: usize,
    /// A tag is present when its probability is above this.
    pub threshold: f32,
}

impl Tagger {
    /// Loads `path`, which must output one score per line of the tag list.
    pub fn new(path: &Path, tags: usize, threads: usize) -> Result<Self, PerceptionError> {
        let session = load_checked(path, ModelRole::Tagger, threads)?;
        let dim = |d: i64| if d > 0 { d as usize } else { DEFAULT_SIDE };
        let shape = crate::model_check::session_signature(&session).inputs[0]
            .shape
            .clone();
        let size = (dim(shape[3]), dim(shape[2]));
        let out = session
            .outputs()
            .iter()
            .find(|o| matches!(o.name(), "tag" | "logits"))
            .ok_or_else(|| model_error(path, "no output named tag or logits"))?;
        let output = out.name().to_string();
        let declared = out.dtype().tensor_shape().and_then(|s| s.get(1).copied());
        if let Some(n) = declared.filter(|&n| n > 0 && n as usize != tags) {
            return Err(model_error(
                path,
                format!("outputs {n} tag scores but the tag list has {tags} tags"),
            ));
        }
        Ok(Self {
            logits: output == "logits",
            session,
            path: path.to_path_buf(),
            size,
            output,
            tags,
            threshold: DEFAULT_TAG_THRESHOLD,
        })
    }

    /// Probability of every tag, in tag-list order.
    pub fn scores(&mut self, input: &SegmenterInput) -> Result<Vec<f32>, PerceptionError> {
        let image = stretch_normalised(
            input.rgb,
            input.width as usize,
            input.height as usize,
            self.size.0,
            self.size.1,
        );
        let path = &self.path;
        let outputs = self
            .session
            .run(ort::inputs!["image" => tensor(&image, path)?])
            .map_err(|e| model_error(path, e))?;
        let values = outputs
            .get(&self.output)
            .ok_or_else(|| model_error(path, format!("no output named {}", self.output)))?
            .try_extract_array::<f32>()
            .map_err(|e| model_error(path, e))?;
        if values.len() != self.tags {
            return Err(model_error(
                path,
                format!(
                    "{} tag scores ({:?}) but the tag list has {} tags",
                    values.len(),
                    values.shape(),
                    self.tags
                ),
            ));
        }
        let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
        Ok(values
            .iter()
            .map(|&v| if self.logits { sigmoid(v) } else { v })
            .collect())
    }

    /// Indices of the present tags with their probability, most likely first.
    pub fn present(
        &mut self,
        input: &SegmenterInput,
    ) -> Result<Vec<(usize, f32)>, PerceptionError> {
        let mut present: Vec<(usize, f32)> = self
            .scores(input)?
            .into_iter()
            .enumerate()
            .filter(|(_, p)| *p > self.threshold)
            .collect();
        present.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        Ok(present)
    }
}
