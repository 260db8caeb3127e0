//! A run's trajectory joined with its dataset: evaluation and keyframe loading that read
//! only the frames they use.

use std::path::Path;

use opengs_datasets::{RgbdFrame, RgbdSource};
use opengs_eval::TimedPose;
use opengs_geometry::Pose;
use opengs_splat::GaussianMap;

use crate::evaluate::{png_positions, QualityEvaluator, MAX_PNGS};
use crate::frame_match::FrameMatcher;
use crate::report::QualityReport;
use crate::QualityError;

/// Scores `map` on every `every_n`-th pose of `trajectory` (a run's trajectory.txt) against
/// the dataset frame with the same timestamp; poses with no such frame are skipped.
/// With `out_dir`, writes up to [`MAX_PNGS`] evenly spread side-by-side PNGs there.
pub fn evaluate_dataset_quality(
    map: &GaussianMap,
    source: &mut dyn RgbdSource,
    trajectory: &[TimedPose],
    every_n: usize,
    out_dir: Option<&Path>,
) -> Result<QualityReport, QualityError> {
    let intrinsics = source.intrinsics();
    let selected: Vec<&TimedPose> = trajectory.iter().step_by(every_n.max(1)).collect();
    let pngs = png_positions(selected.len(), MAX_PNGS);
    let mut eval = QualityEvaluator::new(map, intrinsics, out_dir);
    let mut matcher = FrameMatcher::new(source);
    let mut unmatched = 0;
    for (k, p) in selected.iter().enumerate() {
        match matcher.frame_at(p.timestamp)? {
            Some(frame) => {
                eval.evaluate(&frame, &p.pose, pngs.contains(&k))?;
            }
            None => unmatched += 1,
        }
    }
    if unmatched == selected.len() && !selected.is_empty() {
        return Err(QualityError::NoFrames {
            reason: format!(
                "none of {} trajectory timestamps matches a dataset frame within 1 ms \
                 (is it the dataset the run used?)",
                selected.len()
            ),
        });
    }
    eval.finish()
}

/// The frames of every `every_n`-th pose of `trajectory`, with their poses, read into
/// memory (for refinement); poses with no frame within 1 ms are skipped and counted.
pub fn load_posed_frames(
    source: &mut dyn RgbdSource,
    trajectory: &[TimedPose],
    every_n: usize,
) -> Result<(Vec<(RgbdFrame, Pose)>, usize), QualityError> {
    let mut matcher = FrameMatcher::new(source);
    let (mut frames, mut unmatched) = (Vec::new(), 0);
    for p in trajectory.iter().step_by(every_n.max(1)) {
        match matcher.frame_at(p.timestamp)? {
            Some(frame) => frames.push((frame, p.pose)),
            None => unmatched += 1,
        }
    }
    Ok((frames, unmatched))
}
