//! One call for the end of `opengs run`: score the run directory's map and record it.

use std::error::Error;
use std::path::Path;

use opengs_datasets::RgbdSource;
use opengs_eval::read_tum_trajectory;
use opengs_eval::RunDir;
use opengs_splat::{read_ply_file, GaussianMap};

use crate::dataset_frames::evaluate_dataset_quality;
use crate::metrics_json::{write_quality_metrics, write_report_json};
use crate::report::QualityReport;
use crate::QualityError;

/// Reads a 3DGS PLY map; errors name the file.
pub fn read_map(path: &Path) -> Result<GaussianMap, QualityError> {
    read_ply_file(path).map_err(|e| QualityError::Map {
        path: path.to_path_buf(),
        // An I/O error's message is in its source (the PLY error only repeats the path).
        message: e
            .source()
            .map_or_else(|| e.to_string(), |cause| cause.to_string()),
    })
}

/// Scores `run_dir/map.ply` rendered at the poses of `run_dir/trajectory.txt` (every
/// `every_n`-th) against `source`, the run's dataset; writes up to 4 side-by-side PNGs to
/// `run_dir/renders`, the per-frame scores to `run_dir/quality.json`, and merges `psnr_db`,
/// `ssim`, `quality_frames` into `run_dir/metrics.json`.
pub fn evaluate_run_quality(
    run_dir: &Path,
    source: &mut dyn RgbdSource,
    every_n: usize,
) -> Result<QualityReport, QualityError> {
    let run = RunDir::new(run_dir);
    let map = read_map(&run.map())?;
    let trajectory = read_tum_trajectory(&run.trajectory())?;
    let report =
        evaluate_dataset_quality(&map, source, &trajectory, every_n, Some(&run.renders_dir()))?;
    write_report_json(&run.quality(), &report)?;
    write_quality_metrics(run_dir, &report, "")?;
    Ok(report)
}
