//! End-to-end: real processes over real shared memory.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use opengs_datasets::{open_dataset, DatasetSpec};
use opengs_e2e::{binary, ctl_status, frame_checksum, interrupt, opengs_run, serial, Guard};

fn unique_run_id(tag: &str) -> String {
    format!("t{}-{tag}", std::process::id())
}

fn expected_checksums(frames: usize) -> Vec<u64> {
    let spec: DatasetSpec = "synthetic".parse().expect("spec");
    let mut source = open_dataset(&spec.with_max_frames(Some(frames))).expect("dataset");
    (0..frames)
        .map(|i| {
            let f = source.frame(i).expect("frame");
            frame_checksum(&f.depth, &f.rgb)
        })
        .collect()
}

#[test]
fn every_frame_arrives_intact_and_in_order() {
    let _serial = serial();
    const N: usize = 45;
    let run_id = unique_run_id("intact");
    let mut probe = Guard(
        Command::new(binary("opengs-frame-probe"))
            .args(["--run-id", &run_id, "--count", &N.to_string()])
            .stdout(Stdio::piped())
            .spawn()
            .expect("probe starts"),
    );
    let mut lines = BufReader::new(probe.0.stdout.take().expect("stdout")).lines();
    assert_eq!(lines.next().expect("a line").expect("text"), "ready");
    let sensor = Command::new(binary("opengs-sensor"))
        .args([
            "--run-id",
            &run_id,
            "--dataset",
            "synthetic",
            "--frames",
            &N.to_string(),
        ])
        .stderr(Stdio::null())
        .spawn()
        .expect("sensor starts");
    let mut sensor = Guard(sensor);
    let received: Vec<(u64, u64)> = lines
        .map(|l| {
            let l = l.expect("text");
            let mut it = l.split_whitespace();
            let seq = it
                .next()
                .and_then(|s| s.parse().ok())
                .unwrap_or_else(|| panic!("bad line {l}"));
            let sum = it
                .next()
                .and_then(|s| s.parse().ok())
                .unwrap_or_else(|| panic!("bad line {l}"));
            (seq, sum)
        })
        .collect();
    assert!(sensor.0.wait().expect("sensor exits").success());
    assert!(probe.0.wait().expect("probe exits").success());
    let expected = expected_checksums(N);
    assert_eq!(received.len(), N, "every frame arrives");
    for (i, (seq, sum)) in received.iter().enumerate() {
        assert_eq!(*seq, i as u64, "frames arrive in order");
        assert_eq!(*sum, expected[i], "frame {i} arrives intact");
    }
    assert!(opengs_runtime::leftover_files(&run_id)
        .iter()
        .all(|p| p.to_string_lossy().ends_with(".global_mgmt")));
}

fn write_deploy(dir: &Path) -> std::path::PathBuf {
    let probe = binary("opengs-frame-probe");
    let text = format!(
        r#"description = "test: probe + sensor"
terminal_stage = "probe"
drain_timeout_s = 5
[[stages]]
name = "probe"
binary = "{}"
[[stages]]
name = "sensor"
binary = "opengs-sensor"
role = "source"
restart_limit = 2
"#,
        probe.display()
    );
    let path = dir.join("deploy.toml");
    std::fs::write(&path, text).expect("write deploy");
    path
}

#[test]
fn supervisor_restarts_a_killed_stage_and_the_run_finishes_clean() {
    let _serial = serial();
    const N: usize = 120;
    let dir = tempfile::tempdir().expect("tmp");
    let deploy = write_deploy(dir.path());
    let run_id = unique_run_id("restart");
    let out = dir.path().join("run");
    let run = opengs_run(&run_id, &out)
        .args(["--frames", &N.to_string(), "--max-rate", "30"])
        .arg("--deploy")
        .arg(&deploy)
        .spawn()
        .expect("opengs run starts");
    let mut run = Guard(run);

    // Wait until the sensor is publishing, then SIGKILL it (ctl status gives its pid).
    let deadline = Instant::now() + Duration::from_secs(60);
    let sensor_pid = loop {
        assert!(Instant::now() < deadline, "the run never reached mid-way");
        if let Some(st) = ctl_status(&run_id) {
            let sensor = st["stages"]
                .as_array()
                .and_then(|a| a.iter().find(|s| s["name"] == "sensor"))
                .cloned();
            if let Some(s) = sensor {
                if s["processed"].as_u64().unwrap_or(0) >= 30 {
                    break s["pid"].as_u64().expect("sensor pid") as i32;
                }
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    // SAFETY: signalling a process this test's run started.
    assert_eq!(unsafe { libc::kill(sensor_pid, libc::SIGKILL) }, 0);

    let output = std::mem::replace(&mut run.0, Command::new("true").spawn().expect("true"))
        .wait_with_output()
        .expect("run ends");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "run failed:\n{stdout}\n{stderr}");
    assert!(stderr.contains("restarted sensor"), "{stderr}");

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).expect("run.json"))
            .expect("json");
    let stage = |name: &str| {
        summary["stages"]
            .as_array()
            .and_then(|a| a.iter().find(|s| s["name"] == name))
            .cloned()
            .expect(name)
    };
    assert_eq!(stage("sensor")["restarts"], 1);
    // The restarted sensor resumed: the last frame was published, and the probe saw it.
    assert_eq!(stage("sensor")["last_seq"], (N - 1) as u64);
    assert_eq!(stage("probe")["last_seq"], (N - 1) as u64);
    // Latency outputs exist and parse.
    let latency: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("latency.json")).expect("latency.json"),
    )
    .expect("json");
    assert!(latency["stages"]["probe"]["count"].as_u64().unwrap_or(0) >= (N as u64) / 2);
    let trace: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("trace.json")).expect("trace.json"))
            .expect("json");
    let events = trace["traceEvents"].as_array().expect("events");
    assert!(!events.is_empty());
    // Perfetto keeps it whole: no two complete events on one track overlap.
    assert_eq!(
        opengs_telemetry::overlapping_complete_events(events),
        Vec::<(usize, usize)>::new()
    );
    // Nothing of this run is left in /dev/shm or the iceoryx2 root.
    assert_eq!(
        opengs_runtime::leftover_files(&run_id),
        Vec::<std::path::PathBuf>::new()
    );
}

#[test]
fn ctrl_c_stops_the_run_and_keeps_outputs() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let deploy = write_deploy(dir.path());
    let run_id = unique_run_id("sigint");
    let out = dir.path().join("run");
    let mut run = Guard(
        opengs_run(&run_id, &out)
            .args(["--frames", "100000", "--max-rate", "30"])
            .arg("--deploy")
            .arg(&deploy)
            .spawn()
            .expect("opengs run starts"),
    );
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        assert!(Instant::now() < deadline, "run never got going");
        let st = ctl_status(&run_id);
        if st.is_some_and(|s| s["stages"][0]["processed"].as_u64().unwrap_or(0) >= 10) {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let status = interrupt(&mut run.0, Duration::from_secs(20));
    // Interrupted: the conventional 130, with every output written.
    assert_eq!(status.code(), Some(130));
    for f in ["latency.json", "trace.json", "run.json"] {
        assert!(out.join(f).exists(), "{f} kept after Ctrl-C");
    }
    assert_eq!(
        opengs_runtime::leftover_files(&run_id),
        Vec::<std::path::PathBuf>::new()
    );
    // No stage process of this run survives.
    let ps = Command::new("pgrep")
        .args(["-f", &run_id])
        .output()
        .expect("pgrep");
    assert!(
        String::from_utf8_lossy(&ps.stdout).trim().is_empty(),
        "stages left running"
    );
}

/// `(cpus allowed, nice)` of a live process, from /proc.
fn affinity_and_nice(pid: u64) -> (String, i64) {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("status");
    let cpus = status
        .lines()
        .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))
        .map(|s| s.trim().to_string())
        .expect("Cpus_allowed_list");
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).expect("stat");
    // Fields after the parenthesised command name; nice is field 19 overall.
    let after = &stat[stat.rfind(')').expect("comm") + 2..];
    let nice = after
        .split_whitespace()
        .nth(16)
        .and_then(|v| v.parse().ok())
        .expect("nice");
    (cpus, nice)
}

#[test]
fn edge_deploy_pins_and_nices_stages() {
    let _serial = serial();
    if std::thread::available_parallelism().map_or(1, |n| n.get()) < 2 {
        eprintln!("skipped: the edge deploy pins to cpus 0 and 1");
        return;
    }
    let dir = tempfile::tempdir().expect("tmp");
    let run_id = unique_run_id("edge");
    let out = dir.path().join("run");
    let mut run = Guard(
        opengs_run(&run_id, &out)
            // 10 Hz: at 30 Hz the synthetic sensor's ray-caster fills cpu 0, where the edge
            // mapper only gets idle time, and on a 2-core machine the consensus may get its
            // first render after the deadline (this test is about pinning and nice values).
            .args(["--deploy", "edge", "--frames", "100000", "--max-rate", "10"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("opengs run starts"),
    );
    let deadline = Instant::now() + Duration::from_secs(60);
    let stages = loop {
        assert!(Instant::now() < deadline, "run never got going");
        if let Some(st) = ctl_status(&run_id) {
            let stages = st["stages"].as_array().cloned().unwrap_or_default();
            if stages
                .iter()
                .all(|s| s["pid"].is_u64() && s["processed"].as_u64().unwrap_or(0) > 0)
            {
                break stages;
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let pid = |name: &str| {
        stages
            .iter()
            .find(|s| s["name"] == name)
            .and_then(|s| s["pid"].as_u64())
            .expect(name)
    };
    assert_eq!(affinity_and_nice(pid("tracker")), ("1".to_string(), 0));
    assert_eq!(affinity_and_nice(pid("sensor")), ("0".to_string(), 5));
    // `opengs ctl stop` ends the run cleanly.
    let stop = Command::new(binary("opengs"))
        .args(["ctl", "--run", &run_id, "stop"])
        .output()
        .expect("ctl stop");
    assert!(
        stop.status.success(),
        "{}",
        String::from_utf8_lossy(&stop.stderr)
    );
    let started = Instant::now();
    while run.0.try_wait().expect("wait").is_none() {
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "run did not stop on `ctl stop`"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(out.join("trajectory.txt").exists());
    assert_eq!(
        opengs_runtime::leftover_files(&run_id),
        Vec::<std::path::PathBuf>::new()
    );
}
