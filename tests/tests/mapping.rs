//! End-to-end mapping: a killed mapper resumes from its checkpoint, and the run ends with a map.

use std::process::Command;
use std::time::{Duration, Instant};

use opengs_e2e::{binary, ctl_status, interrupt, opengs_run, serial, stage_pid, Guard};

#[test]
fn killed_mapper_resumes_from_its_checkpoint() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let deploy = mapping_deploy(
        dir.path(),
        "mapper checkpoints every second",
        r#"args = ["--checkpoint-every", "1"]"#,
    );
    let out = dir.path().join("run");
    let run_id = format!("t{}-mapper", std::process::id());
    let run = opengs_run(&run_id, &out)
        .args(["--frames", "240", "--max-rate", "15"])
        .arg("--deploy")
        .arg(&deploy)
        .spawn()
        .expect("run starts");
    // Wait for a checkpoint, then SIGKILL the mapper.
    let deadline = Instant::now() + Duration::from_secs(120);
    while !out.join("map_checkpoint.ply").exists() {
        assert!(Instant::now() < deadline, "no checkpoint written");
        std::thread::sleep(Duration::from_millis(100));
    }
    let pid = loop {
        assert!(Instant::now() < deadline, "no mapper pid");
        if let Some(p) = stage_pid(&run_id, "mapper") {
            break p;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    // SAFETY: signalling a process this test's run started.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGKILL) }, 0);
    let output = run.wait_with_output().expect("run ends");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("restarted mapper"), "{stderr}");
    let log = std::fs::read_to_string(out.join("logs/mapper.log")).expect("mapper log");
    assert!(log.contains("resuming from"), "{log}");
    let map = std::fs::read(out.join("map.ply")).expect("map.ply written at the end");
    assert!(map.starts_with(b"ply\n"));
    let stats: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("mapper.json")).expect("mapper.json"),
    )
    .expect("json");
    assert!(stats["gaussians"].as_u64().unwrap_or(0) > 1000, "{stats}");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).expect("metrics"))
            .expect("json");
    assert!(
        metrics["ate_rmse_cm"].as_f64().expect("ate") < 1.0,
        "{metrics}"
    );
    assert_eq!(
        opengs_runtime::leftover_files(&run_id),
        Vec::<std::path::PathBuf>::new()
    );
}

/// A deploy file of the mapper (with `mapper_line` in its stanza), the tracker and the
/// synthetic sensor.
fn mapping_deploy(dir: &std::path::Path, what: &str, mapper_line: &str) -> std::path::PathBuf {
    let deploy = dir.join("deploy.toml");
    std::fs::write(
        &deploy,
        format!(
            r#"description = "test: {what}"
terminal_stage = "tracker"
drain_timeout_s = 10
[[stages]]
name = "mapper"
binary = "opengs-mapper"
{mapper_line}
[[stages]]
name = "tracker"
binary = "opengs-tracker"
[[stages]]
name = "sensor"
binary = "opengs-sensor"
role = "source"
"#
        ),
    )
    .expect("deploy");
    deploy
}

fn finishing_run(
    deploy: &std::path::Path,
    out: &std::path::Path,
    run_id: &str,
    steps: usize,
) -> Command {
    let mut cmd = opengs_run(run_id, out);
    cmd.args(["--frames", "100", "--max-rate", "15"])
        .args(["--finish-steps", &steps.to_string()])
        .arg("--deploy")
        .arg(deploy);
    cmd
}

/// A run whose final optimisation (1,000,000 steps) is far too long to finish, returned once
/// the mapper has started it.
fn run_into_final_work(deploy: &std::path::Path, out: &std::path::Path, run_id: &str) -> Guard {
    let run = Guard(
        finishing_run(deploy, out, run_id, 1_000_000)
            .spawn()
            .expect("run starts"),
    );
    let deadline = Instant::now() + Duration::from_secs(120);
    let log = out.join("logs/mapper.log");
    while !std::fs::read_to_string(&log)
        .is_ok_and(|l| l.contains("end of data: final optimisation"))
    {
        assert!(
            Instant::now() < deadline,
            "final optimisation never started"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    run
}

fn mapper_stats(out: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("mapper.json")).expect("mapper.json"))
        .expect("json")
}

#[test]
fn final_optimisation_runs_after_the_data_and_ctrl_c_keeps_its_map() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let deploy = mapping_deploy(
        dir.path(),
        "mapper with a final optimisation",
        "finish_timeout_s = 300",
    );

    // To the end: the mapper gets the finish signal, runs its steps, then the run ends.
    let out = dir.path().join("full");
    let run_id = format!("t{}-finish", std::process::id());
    let output = finishing_run(&deploy, &out, &run_id, 30)
        .output()
        .expect("run");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(
        stderr.contains("mapper finished its final work"),
        "{stderr}"
    );
    let stats = mapper_stats(&out);
    let fin = &stats["final_optimisation"];
    assert_eq!(fin["iterations"], 30, "{stats}");
    assert!(
        fin["last_loss"].as_f64().expect("loss") < fin["first_loss"].as_f64().expect("loss"),
        "{stats}"
    );
    // The final map: the optimised one plus the Gaussians that filled what it left open.
    let filled = stats["holes_filled"].as_u64().expect("holes_filled");
    assert_eq!(
        fin["gaussians_after"].as_u64().expect("count") + filled,
        stats["gaussians"].as_u64().expect("count"),
        "{stats}"
    );
    let map = opengs_splat::read_ply_file(out.join("map.ply")).expect("map.ply");
    assert_eq!(
        map.len() as u64,
        stats["gaussians"].as_u64().expect("count")
    );
    // After the final optimisation every pose was aligned to the map; the tracker's poses
    // are kept, frame for frame, and metrics.json says what the alignment did.
    let stamps = |name: &str| -> Vec<String> {
        std::fs::read_to_string(out.join(name))
            .expect(name)
            .lines()
            .filter(|l| !l.starts_with('#'))
            .filter_map(|l| l.split_whitespace().next().map(str::to_string))
            .collect()
    };
    let (refined, tracker) = (stamps("trajectory.txt"), stamps("trajectory_tracker.txt"));
    assert_eq!(refined, tracker);
    let metrics: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("metrics.json")).expect("metrics.json"),
    )
    .expect("json");
    let aligned = &metrics["pose_refinement"];
    assert_eq!(
        aligned["poses"].as_u64(),
        Some(refined.len() as u64),
        "{metrics}"
    );
    assert!(
        aligned["accepted"].as_u64().is_some_and(|n| n > 0),
        "{metrics}"
    );
    assert!(metrics["ate_rmse_cm_tracker"].is_number(), "{metrics}");
    assert!(
        String::from_utf8_lossy(&output.stdout).contains("poses aligned to the final map"),
        "{}",
        String::from_utf8_lossy(&output.stdout)
    );

    // Ctrl-C during a final optimisation far too long to finish: the map so far is written.
    let out = dir.path().join("interrupted");
    let run_id = format!("t{}-finish-int", std::process::id());
    let mut run = run_into_final_work(&deploy, &out, &run_id);
    // The supervisor answers while the mapper finishes (it used to time out here).
    let status = ctl_status(&run_id).expect("ctl status answers during the final work");
    assert!(
        status["stages"].as_array().is_some_and(|s| !s.is_empty()),
        "{status}"
    );
    let status = interrupt(&mut run.0, Duration::from_secs(30));
    assert_eq!(status.code(), Some(130), "interrupted, outputs kept");
    // An interrupted run keeps the tracker's poses as they are.
    assert!(!out.join("trajectory_tracker.txt").exists());
    let stats = mapper_stats(&out);
    let done = stats["final_optimisation"]["iterations"]
        .as_u64()
        .expect("iterations");
    assert!(done > 0 && done < 1_000_000, "{stats}");
    let map = opengs_splat::read_ply_file(out.join("map.ply")).expect("map.ply kept");
    assert_eq!(
        map.len() as u64,
        stats["gaussians"].as_u64().expect("count")
    );
    assert_eq!(
        opengs_runtime::leftover_files(&run_id),
        Vec::<std::path::PathBuf>::new()
    );

    // `opengs ctl stop` during the final work: a requested end (exit 0), the map so far kept.
    let out = dir.path().join("stopped");
    let run_id = format!("t{}-finish-stop", std::process::id());
    let mut run = run_into_final_work(&deploy, &out, &run_id);
    let stop = Command::new(binary("opengs"))
        .args(["ctl", "--run", &run_id, "stop"])
        .output()
        .expect("ctl stop");
    assert!(
        stop.status.success(),
        "{}",
        String::from_utf8_lossy(&stop.stderr)
    );
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(s) = run.0.try_wait().expect("wait") {
            break s;
        }
        assert!(
            Instant::now() < deadline,
            "ctl stop was ignored during the final work"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(status.code(), Some(0), "a requested stop");
    let stats = mapper_stats(&out);
    let done = stats["final_optimisation"]["iterations"]
        .as_u64()
        .expect("iterations");
    assert!(done > 0 && done < 1_000_000, "{stats}");
    assert!(out.join("map.ply").exists(), "map.ply kept");
}

/// Every keyframe seq in `dir/index.txt`, the index of a run's keyframe journal.
fn journalled_keyframes(dir: &std::path::Path) -> Vec<u64> {
    std::fs::read_to_string(dir.join("index.txt"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| l.split_whitespace().next()?.parse().ok())
        .collect()
}

/// A mapper killed while a consensus result it applied is newer than its checkpoint (a
/// file in `mapper_consensus/`) applies that result again after its restart, and maps every
/// journalled keyframe its checkpoint lacked. Before: the consensus answers a keyframe once,
/// so those labels were lost, and journalled keyframes newer than the checkpoint came back as
/// training targets without Gaussians (killed at pose 30 by hand: mIoU 76.7 against 96.7
/// fault-free, with the checkpoint holding 2 of 3 journalled keyframes).
#[test]
fn a_killed_mapper_gets_back_what_its_checkpoint_lacks() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("run");
    let run_id = format!("t{}-relabel", std::process::id());
    let run = opengs_run(&run_id, &out)
        .args([
            "--frames",
            "120",
            "--finish-steps",
            "0",
            "--segmenter",
            "prior",
        ])
        .spawn()
        .expect("run starts");
    let mut run = Guard(run);
    let deadline = Instant::now() + Duration::from_secs(120);
    let results = out.join("mapper_consensus");
    let pending = loop {
        assert!(Instant::now() < deadline, "no consensus result journalled");
        let seqs: Vec<u64> = std::fs::read_dir(&results)
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|e| e.file_name().to_str()?.strip_suffix(".bin")?.parse().ok())
            .collect();
        if let (false, Some(pid)) = (seqs.is_empty(), stage_pid(&run_id, "mapper")) {
            // SAFETY: signalling a process this test's run started.
            assert_eq!(unsafe { libc::kill(pid, libc::SIGKILL) }, 0);
            break seqs;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let running = std::mem::replace(&mut run.0, Command::new("true").spawn().expect("true"));
    let output = running.wait_with_output().expect("run ends");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    let log = std::fs::read_to_string(out.join("logs/mapper.log")).expect("mapper log");
    let restart = log
        .lines()
        .find(|l| l.contains("journalled consensus results the map lacked applied again"))
        .unwrap_or_else(|| panic!("no restart summary: {log}"));
    eprintln!("killed with results {pending:?} journalled; {restart}");
    let held: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("map_checkpoint.json")).expect("map_checkpoint.json"),
    )
    .expect("json");
    let set = |key: &str| -> Vec<u64> {
        held[key]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_u64()).collect())
            .unwrap_or_default()
    };
    let (mapped, labelled) = (set("mapped"), set("labelled"));
    for seq in &pending {
        assert!(labelled.contains(seq), "consensus #{seq} lost: {held}");
    }
    for seq in journalled_keyframes(&out.join("mapper_keyframes")) {
        assert!(mapped.contains(&seq), "keyframe #{seq} not mapped: {held}");
    }
    assert_eq!(mapped.len() as u64, held["keyframes"].as_u64().unwrap_or(0));
}
