//! A stored RGB-D frame as the renderer's target image.

use opengs_datasets::RgbdFrame;
use opengs_splat::TargetFrame;

/// `frame` as a training target at full resolution (its buffers checked first).
pub fn target_frame(frame: &RgbdFrame) -> TargetFrame {
    let rgb: Vec<[u8; 3]> = frame
        .rgb
        .chunks_exact(3)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    TargetFrame::from_rgb8(frame.width, frame.height, &rgb, &frame.depth_metres())
}
