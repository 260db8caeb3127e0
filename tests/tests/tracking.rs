//! End-to-end tracking: `opengs run` on the synthetic room along a real TUM trajectory.

use std::path::PathBuf;
use std::process::Command;

use opengs_e2e::{binary, opengs_run, serial};

fn fr1_xyz() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data/tum_trajectories/freiburg1_xyz-groundtruth.txt")
}

/// Runs the pipeline and returns metrics.json.
fn run(frames: usize, noise: bool) -> serde_json::Value {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("run");
    let run_id = format!("t{}-track{}", std::process::id(), noise as u8);
    let mut cmd = opengs_run(&run_id, &out);
    cmd.args([
        "--frames",
        &frames.to_string(),
        // Tracking is done when the data ends; the map's final optimisation has its own test.
        "--finish-steps",
        "0",
        "--trajectory",
    ])
    .arg(fr1_xyz());
    if noise {
        cmd.arg("--noise");
    }
    let output = cmd.output().expect("opengs run");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(stdout.contains("ATE"), "{stdout}");
    let metrics: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("metrics.json")).expect("metrics.json"),
    )
    .expect("json");
    // `opengs eval` recomputes the same numbers from the files.
    let eval = Command::new(binary("opengs"))
        .arg("eval")
        .arg(&out)
        .output()
        .expect("eval");
    assert!(eval.status.success());
    let again: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("metrics.json")).expect("metrics.json"),
    )
    .expect("json");
    assert_eq!(metrics, again);
    // `opengs eval --scores` renders and labels the map again: the run's own end scores.
    let scored = Command::new(binary("opengs"))
        .args(["eval", "--scores"])
        .arg(&out)
        .output()
        .expect("eval --scores");
    assert!(
        scored.status.success(),
        "{}",
        String::from_utf8_lossy(&scored.stderr)
    );
    let rescored: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("metrics.json")).expect("metrics.json"),
    )
    .expect("json");
    for key in ["psnr_db", "ssim", "holes_pct", "miou", "acc", "miou_raw"] {
        let (a, b) = (metrics[key].as_f64(), rescored[key].as_f64());
        // Parallel sums may round the last bit differently.
        let same = matches!((a, b), (Some(a), Some(b)) if (a - b).abs() <= 1e-9 * a.abs().max(1.0));
        assert!(same, "{key}: {a:?} vs {b:?}");
    }
    // The trajectory has one TUM line per frame.
    let traj = std::fs::read_to_string(out.join("trajectory.txt")).expect("trajectory");
    assert_eq!(traj.lines().filter(|l| !l.starts_with('#')).count(), frames);
    metrics
}

#[test]
fn noise_free_run_has_sub_centimetre_ate() {
    let _serial = serial();
    let m = run(120, false);
    let rmse = m["ate_rmse_cm"].as_f64().expect("ate_rmse_cm");
    assert!(rmse < 1.0, "ATE RMSE {rmse} cm");
    assert!(m["ate_mean_cm"].as_f64().expect("mean") <= rmse);
}

#[test]
fn kinect_noise_run_stays_under_three_centimetres() {
    let _serial = serial();
    let m = run(120, true);
    let rmse = m["ate_rmse_cm"].as_f64().expect("ate_rmse_cm");
    assert!(rmse < 3.0, "ATE RMSE {rmse} cm");
}

/// `opengs bench track`: the tracker alone over 40 frames of the room along fr1_xyz (fast
/// hand-held motion) reports its time percentiles, no lost frame, and a pose error that
/// matches what the pipeline reaches (millimetres), all without starting a stage.
#[test]
fn bench_track_times_the_tracker_alone() {
    let output = Command::new(binary("opengs"))
        .args(["bench", "track", "--frames", "40", "--slow-ms", "100000"])
        .arg("--trajectory")
        .arg(fr1_xyz())
        .output()
        .expect("opengs bench track");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(stdout.contains("per frame: p50"), "{stdout}");
    assert!(stdout.contains("(40 frames, 1 thread(s))"), "{stdout}");
    assert!(stdout.contains("lost 0 of 40"), "{stdout}");
    let error_cm: f64 = stdout
        .split("position error RMSE ")
        .nth(1)
        .and_then(|rest| rest.split(" cm").next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no error figure in: {stdout}"));
    assert!(error_cm < 0.5, "{stdout}");
}
