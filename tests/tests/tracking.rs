//! End-to-end tracking: `opengs run` on the synthetic room along a real TUM trajectory.

use std::path::PathBuf;
use std::process::Command;

use opengs_e2e::{binary, opengs_run, serial};

fn fr1_xyz() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data/tum_trajectories/freiburg1_xyz-groundtruth.txt")
}

/// Runs `cmd` (an `opengs run` into `out`) and checks it succeeded: its output and metrics.json.
fn finished(cmd: &mut Command, out: &std::path::Path) -> (String, serde_json::Value) {
    let output = cmd.output().expect("opengs run");
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let metrics = serde_json::from_str(
        &std::fs::read_to_string(out.join("metrics.json")).expect("metrics.json"),
    )
    .expect("json");
    (stdout, metrics)
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
    let (stdout, metrics) = finished(&mut cmd, &out);
    assert!(stdout.contains("ATE"), "{stdout}");
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
    let dir = tempfile::tempdir().expect("tmp");
    let per_frame = dir.path().join("frames.tsv");
    let output = Command::new(binary("opengs"))
        .args(["bench", "track", "--frames", "40", "--slow-ms", "100000"])
        .arg("--trajectory")
        .arg(fr1_xyz())
        .arg("--frames-out")
        .arg(&per_frame)
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
    // Every frame after the first is registered, in at least one fine iteration.
    let registered: usize = stdout
        .split("fine iterations per registered frame: median ")
        .nth(1)
        .and_then(|rest| rest.split(" (").nth(1))
        .and_then(|rest| rest.split(" frames)").next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no iteration figure in: {stdout}"));
    assert_eq!(registered, 39, "{stdout}");
    let error_cm: f64 = stdout
        .split("position error RMSE ")
        .nth(1)
        .and_then(|rest| rest.split(" cm").next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no error figure in: {stdout}"));
    assert!(error_cm < 0.5, "{stdout}");
    // `--frames-out`: a line per frame, whose errors make the printed RMSE.
    let table = std::fs::read_to_string(&per_frame).expect("frames-out written");
    let rows: Vec<Vec<&str>> = table
        .lines()
        .skip(1)
        .map(|l| l.split('\t').collect())
        .collect();
    assert_eq!(rows.len(), 40, "{table}");
    assert_eq!(rows[0][2], "Initial", "{table}");
    assert!(rows[1..].iter().all(|r| r[2] == "Tracked"), "{table}");
    let errors: Vec<f64> = rows
        .iter()
        .map(|r| r[5].parse().expect("error cm"))
        .collect();
    let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    assert!((rmse - error_cm).abs() < 0.002, "{rmse} against {error_cm}");
}

/// A recording that starts 0.8 s and 2.2 s before its next frames (fr2_desk from 40 s, scene
/// 7 with noise): the second frame fits under the 0.70 a pose after a gap needs of the
/// one-frame model, and so does the third. Tracking starts again at each; the two starts given
/// up are reported lost and never mapped, and every frame after them is tracked (before,
/// 899 of 900 frames were lost).
#[test]
fn a_recording_that_starts_before_gaps_starts_tracking_again_after_them() {
    let _serial = serial();
    let fr2_desk = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data/tum_trajectories/fr2_desk_groundtruth.txt");
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("run");
    let mut cmd = opengs_run(&format!("t{}-restart", std::process::id()), &out);
    cmd.args([
        "--scene",
        "7",
        "--noise",
        "--start",
        "40",
        "--frames",
        "60",
        "--finish-steps",
        "0",
        "--gt-first-pose",
        "--trajectory",
    ])
    .arg(fr2_desk);
    let (stdout, metrics) = finished(&mut cmd, &out);
    assert_eq!(metrics["frames_lost"], 2, "{stdout}");
    // Both had a pose (each a start) until the next frame gave it up.
    assert!(
        stdout.contains("tracking started again soon after its start: 2 of them had a pose"),
        "{stdout}"
    );
    assert_eq!(metrics["frames"], 58, "{stdout}");
    let rmse = metrics["ate_rmse_cm"].as_f64().expect("ate_rmse_cm");
    assert!(rmse < 1.0, "ATE RMSE {rmse} cm");
    let lost = std::fs::read_to_string(out.join("lost.txt")).expect("lost.txt");
    let lost_seqs: Vec<&str> = lost
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.split_whitespace().nth(1))
        .collect();
    assert_eq!(lost_seqs, ["0", "1"], "{lost}");
    // The mapper got its first keyframe from the third frame, the start that stood.
    let mapped = std::fs::read_to_string(out.join("keyframes.txt")).expect("keyframes.txt");
    assert_eq!(mapped.lines().next(), Some("2"), "{mapped}");
    let log = std::fs::read_to_string(out.join("logs/tracker.log")).expect("tracker.log");
    assert_eq!(
        log.matches("tracking starts again here").count(),
        2,
        "{log}"
    );
}

/// A one-frame recording: no later frame verifies for its start to stand on, and the tracker
/// holds the keyframes since a start back until one does; the sensor's last-frame mark lets
/// them go, so the frame is mapped and scored.
#[test]
fn a_one_frame_recording_is_mapped() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("run");
    let mut cmd = opengs_run(&format!("t{}-one", std::process::id()), &out);
    cmd.args(["--frames", "1", "--finish-steps", "0"]);
    let (_, metrics) = finished(&mut cmd, &out);
    let mapped = std::fs::read_to_string(out.join("keyframes.txt")).expect("keyframes.txt");
    assert_eq!(mapped.trim(), "0");
    assert!(
        metrics["psnr_db"].as_f64().is_some_and(|p| p > 15.0),
        "{metrics}"
    );
}
