//! End-to-end: `opengs bench slam --quick` runs the real pipeline on a generated room (scene
//! 1, never tuned on by the built-in room's constants) along the generated loop and along
//! fr2_desk's gap region, at the recorded 30 Hz, and reads its own rows back.

use std::process::Command;

use opengs_e2e::{binary, serial};

#[test]
fn quick_scene_suite_tracks_through_fr2_desk_gaps() {
    let _one_pipeline_at_a_time = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let out = Command::new(binary("opengs"))
        .args(["bench", "slam", "--quick", "--out-root"])
        .arg(dir.path())
        .output()
        .expect("opengs bench slam");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("worst:"), "{stdout}");
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("bench_slam.json")).expect("bench_slam.json"),
    )
    .expect("json");
    assert_eq!(json["deploy"], "desktop", "{json}");
    let rows = json["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 2, "{stdout}");
    for row in rows {
        let case = row["case"].as_str().unwrap_or_default();
        let number = |key: &str| {
            row[key]
                .as_f64()
                .unwrap_or_else(|| panic!("{case}: no {key} in {row}"))
        };
        assert!(row["error"].is_null(), "{case}: {}", row["error"]);
        assert!(number("ate_rmse_cm") < 1.0, "{case}: {row}");
        assert_eq!(number("without_pose"), 0.0, "{case}: {row}");
        assert_eq!(number("lost"), 0.0, "{case}: {row}");
        assert!(number("holes_pct") < 2.0, "{case}: {row}");
    }
    // The fr2_desk case really has the recording's gaps: its timestamps jump.
    let data = std::fs::read_dir(dir.path().join("data"))
        .expect("data")
        .filter_map(Result::ok)
        .find(|e| e.file_name().to_string_lossy().contains("fr2_desk"))
        .expect("fr2_desk dataset");
    let stamps: Vec<f64> = std::fs::read_to_string(data.path().join("rgb.txt"))
        .expect("rgb.txt")
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.split_whitespace().next()?.parse().ok())
        .collect();
    let widest = stamps.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    assert!(widest > 0.25, "widest gap {widest} s");
}

#[test]
fn a_broken_deploy_file_stops_the_bench_before_any_dataset_is_written() {
    let dir = tempfile::tempdir().expect("tmp");
    let deploy = dir.path().join("broken.toml");
    std::fs::write(&deploy, "stages = 3\n").expect("write");
    let root = dir.path().join("bench");
    let out = Command::new(binary("opengs"))
        .args(["bench", "slam", "--quick", "--deploy"])
        .arg(&deploy)
        .arg("--out-root")
        .arg(&root)
        .output()
        .expect("opengs bench slam");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(stderr.contains("--deploy"), "{stderr}");
    assert!(stderr.contains("broken.toml"), "{stderr}");
    assert!(!root.exists(), "{} was written", root.display());
}
