//! `metrics.json` of a run, computed from the files in the run directory so
//! that `opengs run` and `opengs eval RUN_DIR` give the same numbers.

use std::path::Path;

use opengs_eval::RunDir;
use opengs_eval::{absolute_trajectory_error, read_tum_trajectory};
use serde::{Deserialize, Serialize};

/// Timestamps of our trajectory and ground truth come from the same frames.
const MAX_DT: f64 = 0.005;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct RunMetrics {
    /// Frames with a verified pose (`trajectory.txt`).
    pub frames: usize,
    /// Frames without one (`lost.txt`): tracking was lost, or the frame had no depth.
    pub frames_lost: usize,
    /// ATE after rigid (no-scale) Umeyama alignment over the verified poses, docs/METHOD.md §9.
    pub ate_rmse_cm: Option<f64>,
    pub ate_mean_cm: Option<f64>,
    pub ate_max_cm: Option<f64>,
    /// ATE RMSE of the tracker's own poses when trajectory.txt was refined against the map
    /// (`trajectory_tracker.txt`).
    #[serde(default)]
    pub ate_rmse_cm_tracker: Option<f64>,
}

/// The `ate_*` keys of the metrics.json at `path` that hold a number.
fn kept_ate(path: &Path) -> Vec<String> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Vec::new();
    };
    match serde_json::from_str::<serde_json::Value>(&text) {
        Ok(serde_json::Value::Object(m)) => m
            .into_iter()
            .filter(|(k, v)| k.starts_with("ate_") && v.is_number())
            .map(|(k, _)| k)
            .collect(),
        _ => Vec::new(),
    }
}

/// Computes the metrics of `run_dir` and writes `metrics.json` (without ground truth, an ATE
/// already in it is left as it is).
pub fn evaluate_run_trajectory(run_dir: &Path) -> anyhow::Result<RunMetrics> {
    let run = RunDir::new(run_dir);
    let traj_path = run.trajectory();
    let estimated = read_tum_trajectory(&traj_path)?;
    let gt_path = run.groundtruth();
    let lost_path = run.lost();
    let frames_lost = match std::fs::read_to_string(&lost_path) {
        Ok(text) => text
            .lines()
            .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
            .count(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => 0,
        Err(e) => anyhow::bail!("{}: {e}", lost_path.display()),
    };
    let mut metrics = RunMetrics {
        frames: estimated.len(),
        frames_lost,
        ate_rmse_cm: None,
        ate_mean_cm: None,
        ate_max_cm: None,
        ate_rmse_cm_tracker: None,
    };
    let has_gt = gt_path.exists();
    if has_gt {
        let gt = read_tum_trajectory(&gt_path)?;
        let ate = absolute_trajectory_error(&estimated, &gt, MAX_DT)?;
        metrics.ate_rmse_cm = Some(ate.rmse * 100.0);
        metrics.ate_mean_cm = Some(ate.mean * 100.0);
        metrics.ate_max_cm = Some(ate.max * 100.0);
        let tracker = run.trajectory_tracker();
        if tracker.exists() {
            let poses = read_tum_trajectory(&tracker)?;
            let ate = absolute_trajectory_error(&poses, &gt, MAX_DT)?;
            metrics.ate_rmse_cm_tracker = Some(ate.rmse * 100.0);
        }
    }
    // Merge: other producers (render quality, refine) keep their keys.
    let serde_json::Value::Object(mut entries) = serde_json::to_value(&metrics)? else {
        anyhow::bail!("metrics did not serialise to an object");
    };
    if !has_gt {
        // No ground truth now (e.g. removed after the run): an ATE already there is kept.
        let kept = kept_ate(&run.metrics());
        entries.retain(|k, _| !kept.contains(k));
    }
    crate::merge_metrics_json(&run.metrics(), entries)?;
    Ok(metrics)
}
