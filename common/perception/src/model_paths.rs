//! Where the exported ONNX models of a SAM-family segmenter live.

use std::path::PathBuf;

/// The two exported model files (SAM ViT or MobileSAMv2).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SamModelPaths {
    /// `image[1,3,1024,1024] → image_embeddings[1,256,64,64]`.
    pub encoder: PathBuf,
    /// `image_embeddings, point_coords, point_labels, mask_input,
    /// has_mask_input, orig_im_size → masks, iou_predictions, low_res_masks`.
    pub decoder: PathBuf,
}

/// The optional ensemble models that put class names on masks (docs/METHOD.md §6;
/// export layouts in the `ensemble` module and the README's models section).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct EnsembleModelPaths {
    /// RAM/RAM++ tagger: `image[1,3,384,384] → tag[1,T]` (or `logits[1,T]`).
    pub tagger: Option<PathBuf>,
    /// One tag name per line, T lines, in the tagger's output order
    /// (recognize-anything's `ram_tag_list.txt`).
    pub tag_list: Option<PathBuf>,
    /// YOLO-World with a text prompt: `images[1,3,S,S], text_features[1,K,D]
    /// → scores[1,N,K], boxes[1,N,4]`.
    pub detector: Option<PathBuf>,
    /// `.npy` float32 `[T, D]`: the detector's (CLIP) text feature of every tag.
    pub text_embeddings: Option<PathBuf>,
}

impl EnsembleModelPaths {
    /// True when any ensemble model is given.
    pub fn any(&self) -> bool {
        self.tagger.is_some()
            || self.tag_list.is_some()
            || self.detector.is_some()
            || self.text_embeddings.is_some()
    }
}

/// SAM's prompt grid on a CPU: 16² = 256 decoder runs, a quarter of SAM's 32², since every
/// real decoder run costs milliseconds and objects wider than 1/16 of the frame still get one.
pub const DEFAULT_POINTS_PER_SIDE: u32 = 16;

/// Everything needed to build any segmenter kind.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmenterOptions {
    pub classic: crate::ClassicParams,
    pub geometry: crate::GeometryParams,
    pub simulated: crate::SimulatedParams,
    /// Required for `sam` and `mobilesamv2`.
    pub sam_models: Option<SamModelPaths>,
    /// MobileSAMv2's box-proposal model (YOLOv8 export,
    /// `images[1,3,S,S] → output0[1,4+nc,N]`); `mobilesamv2` prompts the
    /// decoder with its boxes instead of a point grid.
    pub proposals: Option<PathBuf>,
    /// Tagger + open-vocabulary detector that name the masks.
    pub ensemble: EnsembleModelPaths,
    /// ONNX Runtime intra-op threads (0 = 1).
    pub threads: usize,
    /// `sam`: prompts on an N × N point grid.
    pub points_per_side: u32,
}

impl Default for SegmenterOptions {
    fn default() -> Self {
        Self {
            classic: Default::default(),
            geometry: Default::default(),
            simulated: Default::default(),
            sam_models: None,
            proposals: None,
            ensemble: Default::default(),
            threads: 0,
            points_per_side: DEFAULT_POINTS_PER_SIDE,
        }
    }
}
