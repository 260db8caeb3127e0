//! Read-modify-write of a run's metrics.json, so quality numbers join what is there.

use std::path::Path;

use serde_json::{Map, Value};

use crate::report::QualityReport;
use crate::QualityError;

use opengs_eval::RunDir;

/// Merges `entries` into the JSON object in `path` (created when absent; other keys kept).
pub fn merge_metrics_json(path: &Path, entries: Map<String, Value>) -> Result<(), QualityError> {
    let json_error = |message: String| QualityError::Json {
        path: path.to_path_buf(),
        message,
    };
    let mut object = match std::fs::read_to_string(path) {
        Ok(text) => match serde_json::from_str::<Value>(&text) {
            Ok(Value::Object(m)) => m,
            Ok(_) => return Err(json_error("not a JSON object".into())),
            Err(e) => return Err(json_error(e.to_string())),
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Map::new(),
        Err(error) => {
            return Err(QualityError::Io {
                path: path.to_path_buf(),
                error,
            })
        }
    };
    object.extend(entries);
    let text = serde_json::to_string_pretty(&Value::Object(object))
        .map_err(|e| json_error(e.to_string()))?;
    std::fs::write(path, text + "\n").map_err(|error| QualityError::Io {
        path: path.to_path_buf(),
        error,
    })
}

/// Adds `psnr_db{suffix}`, `ssim{suffix}`, `holes_pct{suffix}` and `quality_frames{suffix}` to
/// `run_dir/metrics.json` (suffix "" after a run, "_refined" after `opengs refine`).
pub fn write_quality_metrics(
    run_dir: &Path,
    report: &QualityReport,
    suffix: &str,
) -> Result<(), QualityError> {
    let mut entries = Map::new();
    entries.insert(format!("psnr_db{suffix}"), Value::from(report.psnr_db));
    entries.insert(format!("ssim{suffix}"), Value::from(report.ssim));
    entries.insert(format!("holes_pct{suffix}"), Value::from(report.holes_pct));
    entries.insert(
        format!("quality_frames{suffix}"),
        Value::from(report.frames_evaluated),
    );
    merge_metrics_json(&RunDir::new(run_dir).metrics(), entries)
}

/// Writes the whole report (per-frame scores included) as pretty JSON to `path`.
pub fn write_report_json(path: &Path, report: &QualityReport) -> Result<(), QualityError> {
    let text = serde_json::to_string_pretty(report).map_err(|e| QualityError::Json {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    std::fs::write(path, text + "\n").map_err(|error| QualityError::Io {
        path: path.to_path_buf(),
        error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch_dir(name: &str) -> std::path::PathBuf {
        let dir =
            std::env::temp_dir().join(format!("opengs-quality-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir
    }

    fn report(psnr_db: f64) -> QualityReport {
        QualityReport {
            frames_evaluated: 3,
            psnr_db,
            ssim: 0.9,
            holes_pct: 0.25,
            frames_without_depth: 0,
            per_frame: Vec::new(),
            pngs: Vec::new(),
        }
    }

    #[test]
    fn merges_into_existing_metrics_and_creates_missing_ones() {
        let dir = scratch_dir("merge");
        let path = dir.join("metrics.json");
        std::fs::write(
            &path,
            r#"{"frames": 10, "ate_rmse_cm": 1.5, "psnr_db": 1.0}"#,
        )
        .expect("write");
        write_quality_metrics(&dir, &report(30.5), "").expect("merge");
        write_quality_metrics(&dir, &report(31.0), "_refined").expect("merge");
        let v: Value =
            serde_json::from_str(&std::fs::read_to_string(&path).expect("read")).expect("json");
        assert_eq!(v["frames"], 10);
        assert_eq!(v["ate_rmse_cm"], 1.5);
        assert_eq!(v["psnr_db"], 30.5);
        assert_eq!(v["psnr_db_refined"], 31.0);
        assert_eq!(v["holes_pct"], 0.25);
        assert_eq!(v["quality_frames_refined"], 3);

        let fresh = scratch_dir("fresh");
        write_quality_metrics(&fresh, &report(20.0), "").expect("create");
        let v: Value = serde_json::from_str(
            &std::fs::read_to_string(fresh.join("metrics.json")).expect("read"),
        )
        .expect("json");
        assert_eq!(v["ssim"], 0.9);

        std::fs::write(&path, "[1, 2]").expect("write");
        let e = write_quality_metrics(&dir, &report(1.0), "").expect_err("not an object");
        assert!(
            e.to_string().contains("metrics.json: not a JSON object"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
        let _ = std::fs::remove_dir_all(&fresh);
    }
}
