//! Segmenter replicas: keyframes shared out between several segmenter processes (each
//! segmented once), `opengs ctl scale` up and down while the run goes on, and the requests the
//! supervisor refuses.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;
use std::time::{Duration, Instant};

use opengs_e2e::{binary, ctl_status, opengs_run, serial, Guard};

/// `opengs ctl --run ID ARGS...`: (exit ok, stdout, stderr).
fn ctl(run_id: &str, args: &[&str]) -> (bool, String, String) {
    let out = Command::new(binary("opengs"))
        .args(["ctl", "--run", run_id])
        .args(args)
        .output()
        .expect("ctl");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn wait_for_poses(run_id: &str, n: u64, deadline: Instant) {
    loop {
        let poses = ctl_status(run_id).and_then(|s| s["poses"].as_u64());
        if poses.is_some_and(|p| p >= n) {
            return;
        }
        assert!(Instant::now() < deadline, "the run never reached {n} poses");
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn replicas_share_the_keyframes_and_scale_while_the_run_goes_on() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("run");
    let run_id = format!("t{}-replicas", std::process::id());
    // 3 s per keyframe (sleeping, no CPU): the room at 10 Hz makes about a keyframe a second,
    // so two replicas cannot take them all and a third has work too.
    let mut run = Guard(
        opengs_run(&run_id, &out)
            .args([
                "--frames",
                "200",
                "--finish-steps",
                "0",
                "--quality-every",
                "0",
            ])
            .args([
                "--segmenter-replicas",
                "2",
                "--segmenter-min-call-ms",
                "3000",
            ])
            .spawn()
            .expect("run starts"),
    );
    let deadline = Instant::now() + Duration::from_secs(120);
    wait_for_poses(&run_id, 50, deadline);

    let (ok, stdout, stderr) = ctl(&run_id, &["scale", "segmenter", "--to", "3"]);
    assert!(ok, "scale up: {stderr}");
    assert!(
        stdout.contains("scaled segmenter from 2 to 3 replicas"),
        "{stdout}"
    );
    assert!(stdout.contains("started: segmenter#2 (pid "), "{stdout}");
    let status = ctl_status(&run_id).expect("status");
    let running: Vec<u64> = status["stages"]
        .as_array()
        .expect("stages")
        .iter()
        .filter(|s| s["name"] == "segmenter" && s["state"] == "ready")
        .map(|s| s["replica"].as_u64().expect("replica"))
        .collect();
    assert_eq!(running, [0, 1, 2]);
    // Replica 1 dies (mid-keyframe, most likely): it is restarted, and loses at most the
    // keyframe it had claimed; nobody segments that one again.
    let pid = status["stages"]
        .as_array()
        .and_then(|a| {
            a.iter()
                .find(|s| s["name"] == "segmenter" && s["replica"] == 1)
        })
        .and_then(|s| s["pid"].as_u64())
        .expect("replica 1's pid");
    // SAFETY: signalling a stage process of the run this test started.
    unsafe { libc::kill(pid as i32, libc::SIGKILL) };

    // Refused, with the reason, and nothing changes.
    let (ok, _, stderr) = ctl(&run_id, &["scale", "mapper", "--to", "2"]);
    assert!(
        !ok && stderr.contains("'mapper' cannot run replicas"),
        "{stderr}"
    );
    let (ok, _, stderr) = ctl(&run_id, &["scale", "segmenter", "--to", "3"]);
    assert!(
        !ok && stderr.contains("already runs 3 replicas"),
        "{stderr}"
    );
    let (ok, _, stderr) = ctl(&run_id, &["swap", "segmenter", "--to", "prior"]);
    assert!(
        !ok && stderr.contains("runs 3 replicas; scale it to 1 first"),
        "{stderr}"
    );

    wait_for_poses(&run_id, 140, deadline);
    let (ok, stdout, stderr) = ctl(&run_id, &["scale", "segmenter", "--to", "1"]);
    assert!(ok, "scale down: {stderr}");
    assert!(
        stdout.contains("scaled segmenter from 3 to 1 replicas"),
        "{stdout}"
    );
    assert!(
        stdout.contains("retired: segmenter#2 (pid") && stdout.contains("segmenter#1 (pid"),
        "{stdout}"
    );

    let output = run.wait_with_output();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );

    // Each replica did some of the work; the run record has one row per process.
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).expect("run.json"))
            .expect("json");
    let segmenters: Vec<(u64, u64, u64)> = record["stages"]
        .as_array()
        .expect("stages")
        .iter()
        .filter(|s| s["name"] == "segmenter")
        .map(|s| {
            let n = |k: &str| s[k].as_u64().unwrap_or(u64::MAX);
            (n("replica"), n("processed"), n("restarts"))
        })
        .collect();
    assert_eq!(segmenters.len(), 3, "{segmenters:?}");
    let restarts: Vec<u64> = segmenters.iter().map(|s| s.2).collect();
    assert_eq!(restarts, [0, 1, 0], "only the killed replica restarted");
    assert!(segmenters.iter().all(|s| s.1 >= 1), "{segmenters:?}");
    let segmented: u64 = segmenters.iter().map(|s| s.1).sum();

    // No keyframe segmented twice: every segmentation in the trace has its own seq.
    let trace: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("trace.json")).expect("trace"))
            .expect("json");
    let mut per_process: BTreeMap<String, u64> = BTreeMap::new();
    let mut seqs = Vec::new();
    for e in trace["traceEvents"].as_array().expect("events") {
        let cat = e["cat"].as_str().unwrap_or("");
        if e["ph"] == "X" && cat.starts_with("segmenter") {
            seqs.push(e["args"]["seq"].as_u64().expect("seq"));
            *per_process.entry(cat.to_string()).or_default() += 1;
        }
    }
    let distinct: BTreeSet<u64> = seqs.iter().copied().collect();
    assert_eq!(
        distinct.len(),
        seqs.len(),
        "a keyframe was segmented twice: {seqs:?}"
    );
    assert_eq!(seqs.len() as u64, segmented);
    assert_eq!(
        per_process.keys().collect::<Vec<_>>(),
        ["segmenter", "segmenter#1", "segmenter#2"]
    );
    // More keyframes segmented than one replica could have done in the run's time.
    let keyframes = std::fs::read_to_string(out.join("keyframes.txt"))
        .expect("keyframes")
        .lines()
        .count() as u64;
    // One replica alone: 20 s of data / 3 s = 6 at most.
    assert!(
        segmented >= 10 && segmented <= keyframes + 1,
        "{segmented} segmented of {keyframes} keyframes"
    );

    // Each claim names the process that took the keyframe: three pids, one file per keyframe.
    let claims: Vec<String> = std::fs::read_dir(out.join("segmenter_claims"))
        .expect("claims")
        .map(|e| std::fs::read_to_string(e.expect("entry").path()).expect("claim"))
        .collect();
    // One claim per keyframe taken: the segmented ones, and at most one the killed replica
    // had claimed when it died.
    assert!(
        claims.len() as u64 == segmented || claims.len() as u64 == segmented + 1,
        "{} claims, {segmented} segmented",
        claims.len()
    );
    let pids: BTreeSet<&str> = claims
        .iter()
        .filter_map(|c| c.split_whitespace().next())
        .collect();
    // Replicas 0, 1 (twice: before and after its restart) and 2.
    assert_eq!(pids.len(), 4, "{claims:?}");

    // The latency profile has the stage's row (all replicas) and one per replica.
    let latency: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("latency.json")).expect("lat"))
            .expect("json");
    let count = |k: &str| latency["stages"][k]["count"].as_u64().unwrap_or(0);
    assert_eq!(
        count("segmenter"),
        count("segmenter#0") + count("segmenter#1") + count("segmenter#2")
    );
    assert!(count("segmenter#2") >= 1);
    for log in ["segmenter.log", "segmenter#1.log", "segmenter#2.log"] {
        assert!(out.join("logs").join(log).exists(), "{log}");
    }
}
