//! End-to-end: a ROS 2 bag (`opengs synth --format rosbag2`) through the real pipeline, and
//! a broken bag refused before any stage starts.

use std::path::Path;
use std::process::Command;

use opengs_e2e::{binary, opengs_run, serial};

const FRAMES: usize = 20;

fn synth_bag(out: &Path) {
    let synth = Command::new(binary("opengs"))
        .args([
            "synth",
            "--format",
            "rosbag2",
            "--frames",
            &FRAMES.to_string(),
            "--out",
        ])
        .arg(out)
        .output()
        .expect("synth runs");
    assert!(
        synth.status.success(),
        "{}",
        String::from_utf8_lossy(&synth.stderr)
    );
}

fn data_lines(path: &Path) -> usize {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .count()
}

#[test]
fn a_rosbag2_dataset_runs_through_the_pipeline() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let bag = dir.path().join("bag");
    synth_bag(&bag);
    let out = dir.path().join("run");
    let run = opengs_run(&format!("t{}-rosbag2", std::process::id()), &out)
        .arg("--dataset")
        .arg(format!("rosbag2:{}", bag.display()))
        .args(["--finish-steps", "0"])
        .output()
        .expect("run");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let metrics: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("metrics.json")).expect("metrics.json"),
    )
    .expect("metrics parse");
    // A verified pose per frame, and ground truth for each from the bag's pose topic.
    assert_eq!(metrics["frames"].as_u64(), Some(FRAMES as u64), "{metrics}");
    assert_eq!(data_lines(&out.join("trajectory.txt")), FRAMES);
    assert_eq!(data_lines(&out.join("groundtruth.txt")), FRAMES);
    let ate = metrics["ate_rmse_cm"].as_f64().expect("ate_rmse_cm");
    assert!(ate < 2.0, "ATE {ate} cm: {metrics}");
    let record = std::fs::read_to_string(out.join("run.json")).expect("run.json");
    assert!(record.contains("rosbag2:"), "{record}");
}

#[test]
fn a_truncated_bag_is_refused_naming_the_file() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let bag = dir.path().join("cut");
    synth_bag(&bag);
    let file = bag.join("cut_0.mcap");
    let bytes = std::fs::read(&file).expect("bag file");
    std::fs::write(&file, &bytes[..bytes.len() / 2]).expect("truncate");
    let run = opengs_run(
        &format!("t{}-rosbag2-cut", std::process::id()),
        &dir.path().join("run"),
    )
    .arg("--dataset")
    .arg(format!("rosbag2:{}", bag.display()))
    .output()
    .expect("run");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("cut_0.mcap") && stderr.contains("truncated"),
        "{stderr}"
    );
    assert!(!dir.path().join("run/trajectory.txt").exists());
}
