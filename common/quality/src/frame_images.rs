//! An input frame's buffers in the forms the metrics and the trainer need.

use opengs_datasets::RgbdFrame;
use opengs_geometry::Intrinsics;
use opengs_splat::TargetFrame;

use crate::QualityError;

/// Checks that `frame`'s buffers match its size and the camera's (frames are external input).
pub fn check_frame(frame: &RgbdFrame, intrinsics: &Intrinsics) -> Result<(), QualityError> {
    let error = |message: String| QualityError::Frame {
        index: frame.index,
        message,
    };
    let (w, h) = (frame.width, frame.height);
    if (w, h) != (intrinsics.width, intrinsics.height) {
        return Err(error(format!(
            "image is {w}x{h} but the camera is {}x{}",
            intrinsics.width, intrinsics.height
        )));
    }
    let n = w as usize * h as usize;
    if frame.rgb.len() != 3 * n || frame.depth.len() != n {
        return Err(error(format!(
            "{} RGB bytes and {} depth values for {w}x{h}",
            frame.rgb.len(),
            frame.depth.len()
        )));
    }
    if !(frame.depth_scale.is_finite() && frame.depth_scale > 0.0) {
        return Err(error(format!("depth scale {} ≤ 0", frame.depth_scale)));
    }
    Ok(())
}

/// True where the input has depth: the pixels PSNR / SSIM are evaluated on (METHOD §9).
pub fn valid_depth_mask(frame: &RgbdFrame) -> Vec<bool> {
    frame.depth.iter().map(|&d| d != 0).collect()
}

/// Depth in metres, 0 where missing.
pub fn depth_metres(frame: &RgbdFrame) -> Vec<f32> {
    let k = 1.0 / frame.depth_scale;
    frame.depth.iter().map(|&d| d as f32 * k).collect()
}

/// The frame as a training target at full resolution (call [`check_frame`] first).
pub fn target_frame(frame: &RgbdFrame) -> TargetFrame {
    let rgb: Vec<[u8; 3]> = frame
        .rgb
        .chunks_exact(3)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    TargetFrame::from_rgb8(frame.width, frame.height, &rgb, &depth_metres(frame))
}
