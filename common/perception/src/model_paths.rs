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

/// Everything needed to build any segmenter kind.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SegmenterOptions {
    pub classic: crate::ClassicParams,
    /// Required for `sam` and `mobilesamv2`.
    pub sam_models: Option<SamModelPaths>,
    /// ONNX Runtime intra-op threads (0 = 1).
    pub threads: usize,
}
