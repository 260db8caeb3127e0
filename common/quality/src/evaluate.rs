//! Renders a map at estimated poses and scores it against the input frames.

use std::path::{Path, PathBuf};

use opengs_datasets::RgbdFrame;
use opengs_geometry::{Intrinsics, Pose};
use opengs_splat::{render_into, Camera, GaussianMap, RenderRequest, Rendered};

use crate::frame_images::{check_frame, valid_depth_mask};
use crate::report::{FrameQuality, QualityReport, HOLE_SILHOUETTE};
use crate::side_by_side::write_side_by_side_png;
use crate::{psnr_masked, ssim_masked, QualityError};
use opengs_splat::DEFAULT_NEAR;

/// Side-by-side PNGs written per evaluation, evenly spread over the evaluated frames.
pub const MAX_PNGS: usize = 4;

/// Scores frames one at a time (so long sequences never sit in memory) and keeps the report.
pub struct QualityEvaluator<'a> {
    map: &'a GaussianMap,
    intrinsics: Intrinsics,
    near: f32,
    out_dir: Option<PathBuf>,
    rendered: Rendered,
    per_frame: Vec<FrameQuality>,
    frames_without_depth: usize,
    pngs: Vec<PathBuf>,
}

impl<'a> QualityEvaluator<'a> {
    /// PNGs go to `out_dir` when given.
    pub fn new(map: &'a GaussianMap, intrinsics: Intrinsics, out_dir: Option<&Path>) -> Self {
        Self {
            map,
            intrinsics,
            near: DEFAULT_NEAR,
            out_dir: out_dir.map(Path::to_path_buf),
            rendered: Rendered::default(),
            per_frame: Vec::new(),
            frames_without_depth: 0,
            pngs: Vec::new(),
        }
    }

    pub fn with_near(mut self, near: f32) -> Self {
        self.near = near;
        self
    }

    /// Renders `frame` at `pose` (camera-to-world) and scores it; writes its side-by-side PNG
    /// when `save_png` and an output directory was given. `None` when no pixel has depth.
    pub fn evaluate(
        &mut self,
        frame: &RgbdFrame,
        pose: &Pose,
        save_png: bool,
    ) -> Result<Option<FrameQuality>, QualityError> {
        check_frame(frame, &self.intrinsics)?;
        let valid = valid_depth_mask(frame);
        let n_valid = valid.iter().filter(|&&v| v).count();
        if n_valid == 0 {
            self.frames_without_depth += 1;
            return Ok(None);
        }
        let camera = Camera::from_pose(self.intrinsics, pose, self.near);
        render_into(
            self.map,
            &camera,
            &RenderRequest::color_depth(),
            &mut self.rendered,
        );
        let out = &self.rendered.output;
        let open = valid
            .iter()
            .zip(&out.silhouette)
            .filter(|(&v, &alpha)| v && alpha < HOLE_SILHOUETTE)
            .count();
        let q = FrameQuality {
            index: frame.index,
            timestamp: frame.timestamp,
            psnr_db: psnr_masked(&out.color, &frame.rgb, &valid),
            ssim: ssim_masked(&out.color, &frame.rgb, &valid, frame.width, frame.height),
            valid_fraction: n_valid as f64 / valid.len() as f64,
            holes: open as f64 / n_valid as f64,
        };
        self.per_frame.push(q);
        if let (true, Some(dir)) = (save_png, &self.out_dir) {
            let path = dir.join(format!("render_{:06}.png", frame.index));
            write_side_by_side_png(&path, frame, out, &valid)?;
            self.pngs.push(path);
        }
        Ok(Some(q))
    }

    /// The report; an error when no frame was scored.
    pub fn finish(self) -> Result<QualityReport, QualityError> {
        let n = self.per_frame.len();
        if n == 0 {
            let reason = match self.frames_without_depth {
                0 => "no frames given".to_string(),
                n => format!("all {n} frames lack valid depth"),
            };
            return Err(QualityError::NoFrames { reason });
        }
        let mean =
            |f: fn(&FrameQuality) -> f64| self.per_frame.iter().map(f).sum::<f64>() / n as f64;
        // Weighted by each frame's valid pixels: the share of all scored pixels left open.
        let (open, valid) = self.per_frame.iter().fold((0.0, 0.0), |(o, v), q| {
            (o + q.holes * q.valid_fraction, v + q.valid_fraction)
        });
        Ok(QualityReport {
            frames_evaluated: n,
            holes_pct: 100.0 * open / valid,
            psnr_db: mean(|q| q.psnr_db),
            ssim: mean(|q| q.ssim),
            frames_without_depth: self.frames_without_depth,
            per_frame: self.per_frame,
            pngs: self.pngs,
        })
    }
}

/// Positions (0-based, among `total` evaluated frames) of `count` evenly spread PNGs,
/// first and last included.
pub fn png_positions(total: usize, count: usize) -> Vec<usize> {
    match (total, count) {
        (0, _) | (_, 0) => Vec::new(),
        (_, 1) => vec![total / 2],
        _ => {
            let mut p: Vec<usize> = (0..count)
                .map(|i| (i * (total - 1) + (count - 1) / 2) / (count - 1))
                .collect();
            p.dedup();
            p
        }
    }
}

/// Scores every `every_n`-th of `frames` (frame, camera-to-world estimated pose) rendered
/// from `map`; with `out_dir`, writes up to [`MAX_PNGS`] side-by-side PNGs there, spread
/// over the frames the iterator's size hint announces. Skipped frames are still pulled
/// from the iterator: for a dataset read lazily, use
/// [`crate::evaluate_dataset_quality`], which never reads them.
pub fn evaluate_render_quality(
    map: &GaussianMap,
    frames: impl IntoIterator<Item = (RgbdFrame, Pose)>,
    intrinsics: Intrinsics,
    every_n: usize,
    out_dir: Option<&Path>,
) -> Result<QualityReport, QualityError> {
    let every_n = every_n.max(1);
    let frames = frames.into_iter();
    let (lower, upper) = frames.size_hint();
    let selected = upper.unwrap_or(lower).div_ceil(every_n);
    let pngs = png_positions(selected, MAX_PNGS);
    let mut eval = QualityEvaluator::new(map, intrinsics, out_dir);
    for (k, (frame, pose)) in frames.step_by(every_n).enumerate() {
        eval.evaluate(&frame, &pose, pngs.contains(&k))?;
    }
    eval.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_positions_are_spread_and_bounded() {
        assert_eq!(png_positions(100, 4), vec![0, 33, 66, 99]);
        assert_eq!(png_positions(3, 4), vec![0, 1, 2]);
        assert_eq!(png_positions(1, 4), vec![0]);
        assert_eq!(png_positions(9, 1), vec![4]);
        assert!(png_positions(0, 4).is_empty());
    }
}
