//! End-to-end semantic loop: segmenter → consensus ↔ mapper on the synthetic room, scored with
//! one global label ↔ instance matching on label maps rendered at held-out poses.

use std::path::Path;
use std::process::Command;

use opengs_e2e::{opengs_run, serial};

/// Frames of the synthetic loop used by these runs, and the sensor rate: slow enough that the
/// mapper and consensus see most keyframes on a loaded 2-core machine.
const FRAMES: &str = "300";
const RATE: &str = "8";

/// `opengs run` on the synthetic room with `segmenter`, into `out`.
fn command(segmenter: &str, out: &Path, run_id: &str) -> Command {
    let mut cmd = opengs_run(run_id, out);
    cmd.args([
        "--segmenter",
        segmenter,
        "--frames",
        FRAMES,
        "--max-rate",
        RATE,
        "--quality-every",
        "15",
        // The final optimisation sharpens colour, not labels; it has its own test.
        "--finish-steps",
        "0",
    ]);
    cmd
}

fn run(segmenter: &str, out: &Path) -> (serde_json::Value, serde_json::Value) {
    let output = command(
        segmenter,
        out,
        &format!("t{}-sem-{segmenter}", std::process::id()),
    )
    .output()
    .expect("opengs run");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(stdout.contains("mIoU"), "{stdout}");
    // Even without a final optimisation the newest keyframe's labels reach the map.
    let keyframes = std::fs::read_to_string(out.join("keyframes.txt")).expect("keyframes.txt");
    let last = keyframes.lines().last().expect("a keyframe");
    let mapper_log = std::fs::read_to_string(out.join("logs/mapper.log")).expect("mapper.log");
    assert!(
        mapper_log.contains(&format!("consensus #{last}:")),
        "the last keyframe #{last}'s consensus was not applied\n{mapper_log}"
    );
    let read = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join(name)).expect(name)).expect(name)
    };
    (read("metrics.json"), read("semantics.json"))
}

#[test]
fn prior_segments_give_one_label_per_object() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("run");
    let (metrics, semantics) = run("prior", &out);
    let miou = metrics["miou"].as_f64().expect("miou");
    let raw = metrics["miou_raw"].as_f64().expect("miou_raw");
    assert!(miou >= 90.0, "mIoU {miou}\n{semantics:#}");
    // Ground truth scored against itself.
    assert!((raw - 100.0).abs() < 1e-9, "raw {raw}");
    let per_frame = metrics["miou_raw_per_frame"]
        .as_f64()
        .expect("miou_raw_per_frame");
    assert!((per_frame - 100.0).abs() < 1e-9, "per frame {per_frame}");
    // Every object that is more than a sliver of the views carries one dominant label.
    let instances = semantics["map"]["instances"].as_array().expect("instances");
    let total: f64 = instances
        .iter()
        .map(|i| i["pixels"].as_f64().unwrap_or(0.0))
        .sum();
    for i in instances {
        let pixels = i["pixels"].as_f64().unwrap_or(0.0);
        if pixels < 0.002 * total {
            continue;
        }
        let share = i["dominant_share"].as_f64().unwrap_or(0.0);
        assert!(
            share >= 0.8 && i["dominant_label"].as_u64() == i["label"].as_u64(),
            "instance {i}"
        );
    }
    // labels.json: the global table with classes from the dataset and Gaussian counts.
    let labels: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("labels.json")).expect("labels"))
            .expect("json");
    let labels = labels.as_array().expect("array");
    assert!(labels.iter().any(|l| l["class"] == "table"), "{labels:?}");
    assert!(labels
        .iter()
        .any(|l| l["gaussians"].as_u64().unwrap_or(0) > 1000));
    // Label PNGs beside the renders, the segmenter's maps under segments/.
    let renders: Vec<_> = std::fs::read_dir(out.join("renders"))
        .expect("renders")
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("labels_"))
        .collect();
    assert!(!renders.is_empty());
    assert!(
        std::fs::read_dir(out.join("segments"))
            .expect("segments")
            .count()
            > 5
    );
}

#[test]
fn geometry_segments_make_a_map_of_objects() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let (metrics, semantics) = run("geometry", &dir.path().join("run"));
    let miou = metrics["miou"].as_f64().expect("miou");
    let acc = metrics["acc"].as_f64().expect("acc");
    let labels = metrics["labels"].as_u64().expect("labels");
    // Measured 72 / 74 with 48 global labels for the room's 23 objects
    // (classic: 45 / 31 with 436); the bounds leave room for a loaded machine.
    assert!(
        miou >= 55.0 && acc >= 55.0,
        "mIoU {miou}, acc {acc}\n{semantics:#}"
    );
    assert!(labels <= 3 * 23, "{labels} global labels");
    // Fresh ids every frame: one matching over the run cannot score the segmenter, a matching
    // per keyframe map can (`bench segment --quality` measured 89 on the room).
    let raw = metrics["miou_raw"].as_f64().expect("miou_raw");
    let per_frame = metrics["miou_raw_per_frame"]
        .as_f64()
        .expect("miou_raw_per_frame");
    assert!(
        per_frame >= 75.0 && raw < 20.0,
        "per frame {per_frame}, one matching {raw}"
    );
}

#[test]
fn classic_map_labels_beat_the_raw_segmenter() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let (metrics, semantics) = run("classic", &dir.path().join("run"));
    let miou = metrics["miou"].as_f64().expect("miou");
    let raw = metrics["miou_raw"].as_f64().expect("miou_raw");
    // Classic relabels arbitrarily per frame: the global matching punishes it, the map not.
    assert!(miou > raw + 10.0, "map {miou} vs raw {raw}\n{semantics:#}");
}

#[test]
fn killed_consensus_resumes_its_label_table() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("run");
    let run_id = format!("t{}-sem-kill", std::process::id());
    let run = command("prior", &out, &run_id).spawn().expect("run starts");
    // Once the consensus has saved its table, SIGKILL it.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    while !out.join("label_table.json").exists() {
        assert!(
            std::time::Instant::now() < deadline,
            "no label table written"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let pid = loop {
        assert!(std::time::Instant::now() < deadline, "no consensus pid");
        if let Some(p) = opengs_e2e::stage_pid(&run_id, "consensus") {
            break p;
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    };
    // SAFETY: signalling a process this test's run started.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGKILL) }, 0);
    let output = run.wait_with_output().expect("run ends");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("restarted consensus"), "{stderr}");
    let log = std::fs::read_to_string(out.join("logs/consensus.log")).expect("log");
    assert!(log.contains("resuming with"), "{log}");
    let read = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join(name)).expect(name)).expect(name)
    };
    let metrics = read("metrics.json");
    let miou = metrics["miou"].as_f64().expect("miou");
    // Keyframes segmented while it was down are lost, so a little below the uninterrupted run.
    assert!(miou >= 80.0, "mIoU {miou} after a consensus restart");
    // The restart did not set off a burst of fresh labels for objects the map already knows
    // (the log line above shows the table was resumed). Killed right after its first answer,
    // the consensus often took that answer with it unread; until it gave it again after the
    // restart, the labels came back as New ones (37-40 for 20 objects in 5 of 8 runs).
    let labels = read("labels.json");
    let labels = labels.as_array().expect("array");
    let instances = read("semantics.json")["map"]["instances"]
        .as_array()
        .map_or(0, |a| a.len());
    assert!(labels.len() <= instances + 5, "{} labels", labels.len());
}
