//! End-of-run scores of a written run directory: ATE of the trajectory, render quality
//! (PSNR/SSIM/holes) and labels (mIoU) against the dataset's ground truth. A scorer that
//! fails is reported and skipped: the run's outputs are already written.

use std::path::Path;

use opengs_eval::RunDir;

use opengs_quality::{RunMetrics, SemanticReport};

use crate::run_options::RunOptions;

/// What could be scored.
#[derive(Debug, Default)]
pub struct Scores {
    pub metrics: Option<RunMetrics>,
    pub quality: Option<opengs_quality::QualityReport>,
    pub semantics: Option<SemanticReport>,
}

/// Scores `run`; `has_poses` says whether the run produced a trajectory at all.
pub fn score(run: &RunDir, opts: &RunOptions, has_poses: bool) -> Scores {
    if !has_poses {
        return Scores::default();
    }
    let metrics = opengs_quality::evaluate_run_trajectory(run.root())
        .map_err(|e| eprintln!("metrics: {e:#}"))
        .ok();
    // Scores need the map, poses, and a dataset with ground truth to compare with.
    let scorable = opts.quality_every > 0 && run.map().exists();
    let quality = score_against_dataset(
        opts,
        scorable,
        &format!(
            "rendered views against every {}th frame",
            opts.quality_every
        ),
        |dir, source, every| Ok(opengs_quality::evaluate_run_quality(dir, source, every)?),
    );
    let semantics = score_against_dataset(
        opts,
        scorable,
        "labels (mIoU)",
        opengs_quality::evaluate_run_semantics,
    );
    Scores {
        metrics,
        quality,
        semantics,
    }
}

/// Runs one scorer over the run's dataset; a failure is printed, not fatal.
fn score_against_dataset<T>(
    opts: &RunOptions,
    scorable: bool,
    what: &str,
    score: impl FnOnce(&Path, &mut dyn opengs_datasets::RgbdSource, usize) -> anyhow::Result<T>,
) -> Option<T> {
    if !scorable {
        return None;
    }
    eprintln!("scoring {what} ...");
    let scored = opts
        .dataset
        .spec()
        .and_then(|spec| Ok(opengs_datasets::open_dataset(&spec)?))
        .and_then(|mut source| score(&opts.out_dir, source.as_mut(), opts.quality_every));
    scored.map_err(|e| eprintln!("scoring {what}: {e:#}")).ok()
}
