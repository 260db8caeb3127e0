//! An input frame's buffers in the forms the metrics need.

use opengs_datasets::RgbdFrame;
use opengs_geometry::Intrinsics;

use crate::QualityError;

/// Checks that `frame`'s buffers match its size and the camera's (frames are external input).
pub fn check_frame(frame: &RgbdFrame, intrinsics: &Intrinsics) -> Result<(), QualityError> {
    frame
        .check_buffers(intrinsics)
        .map_err(|message| QualityError::Frame {
            index: frame.index,
            message,
        })
}

/// True where the input has depth: the pixels PSNR / SSIM are evaluated on (docs/METHOD.md §9).
pub fn valid_depth_mask(frame: &RgbdFrame) -> Vec<bool> {
    frame.depth.iter().map(|&d| d != 0).collect()
}
