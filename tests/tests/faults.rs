//! A stage that dies or hangs costs seconds, never the run: the quick fault campaign on the
//! built-in room (120 frames, no final optimisation). One fault-free run; one in which the
//! mapper and then the consensus are SIGKILLed; one in which the tracker is SIGKILLed and
//! then SIGSTOPped (only the watchdog can tell). Each faulted run must finish with its
//! trajectory, map and labels close to the fault-free run's.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use opengs_e2e::{ctl_status, opengs_run, serial, stage_pid, Guard};

fn metrics(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).expect("metrics"))
        .expect("json")
}

fn poses(run_id: &str) -> u64 {
    ctl_status(run_id)
        .and_then(|s| s["poses"].as_u64())
        .unwrap_or(0)
}

/// Waits until the run has published `n` poses.
fn wait_poses(run_id: &str, n: u64, deadline: Instant) {
    while poses(run_id) < n {
        assert!(Instant::now() < deadline, "the run never reached {n} poses");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn signal(run_id: &str, stage: &str, sig: i32) {
    let pid = stage_pid(run_id, stage).expect("stage pid");
    // SAFETY: signalling a process this test's run started.
    assert_eq!(unsafe { libc::kill(pid, sig) }, 0, "kill {stage}");
}

/// One fault-injected run with `args`: `faults` (poses to wait for, stage, signal) in order.
/// Returns the run's directory once it ended (exit 0 and its stderr checked by the caller).
fn faulted_run_with(
    dir: &Path,
    tag: &str,
    args: &[&str],
    faults: &[(u64, &str, i32)],
) -> (PathBuf, String) {
    let out = dir.join(tag);
    let run_id = format!("t{}-{tag}", std::process::id());
    let child = opengs_run(&run_id, &out)
        .args(args)
        .spawn()
        .expect("run starts");
    let mut guard = Guard(child);
    let deadline = Instant::now() + Duration::from_secs(120);
    for (i, &(at, stage, sig)) in faults.iter().enumerate() {
        wait_poses(&run_id, at, deadline);
        if stage == "mapper" {
            // A mapper faulted before its first checkpoint starts again from an empty map and
            // its journals (killed at pose 2–3 by hand, twice: mIoU 96.5 and 96.8 against 96.7
            // fault-free; before the consensus journal, 84.5 against 89.3). On a slow machine
            // pose 30 can come first; these tests measure a checkpointed one.
            while !out.join("map_checkpoint.ply").exists() {
                assert!(Instant::now() < deadline, "{tag}: no mapper checkpoint");
                std::thread::sleep(Duration::from_millis(20));
            }
        } else {
            // One fault at a time: a restarted mapper is back (its map, keyframes and labels
            // made again, and a consensus applied since) before the next stage dies. A
            // consensus killed while the mapper restarts loses the segmentations both had
            // queued (beside a busy loop: mIoU 69.8–76.0 against 96.4–96.5 fault-free,
            // keyframes 0–20, half the map, never answered).
            let back = |log: String| {
                log.split_once("consensus results the map lacked applied again")
                    .is_some_and(|(_, after)| after.contains("consensus #"))
            };
            // Not past pose 100 of 120 all the same: the stage must still be running.
            while faults[..i].iter().any(|f| f.1 == "mapper")
                && !std::fs::read_to_string(out.join("logs/mapper.log")).is_ok_and(back)
                && poses(&run_id) < 100
            {
                assert!(
                    Instant::now() < deadline,
                    "{tag}: the mapper never came back"
                );
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        signal(&run_id, stage, sig);
    }
    let running = std::mem::replace(&mut guard.0, Command::new("true").spawn().expect("true"));
    let output = running.wait_with_output().expect("run ends");
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "{tag}: {stderr}");
    (out, stderr)
}

/// The synthetic room's first `frames` frames written as a TUM folder at `data`.
fn synth_tum(data: &Path, frames: usize) {
    let synth = Command::new(opengs_e2e::binary("opengs"))
        .args([
            "synth",
            "--format",
            "tum",
            "--frames",
            &frames.to_string(),
            "--out",
        ])
        .arg(data)
        .output()
        .expect("synth");
    assert!(
        synth.status.success(),
        "{}",
        String::from_utf8_lossy(&synth.stderr)
    );
}

fn stage_record(out: &Path, name: &str) -> serde_json::Value {
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).expect("run.json"))
            .expect("json");
    record["stages"]
        .as_array()
        .and_then(|a| a.iter().find(|s| s["name"] == name))
        .cloned()
        .expect(name)
}

/// Trajectory, map and labels within the bounds of the fault-free run: ATE 2x (or
/// +0.1 cm: sub-millimetre baselines make a bare 2x meaningless), PSNR 2 dB, mIoU 5 points.
fn close_to(base: &serde_json::Value, got: &serde_json::Value, tag: &str) {
    let num = |m: &serde_json::Value, k: &str| m[k].as_f64().unwrap_or(f64::NAN);
    eprintln!(
        "{tag}: ATE {:.3} cm, PSNR {:.2} dB, mIoU {:.1}, {} verified poses, {} lost; fault-free: ATE \
         {:.3} cm, PSNR {:.2} dB, mIoU {:.1}",
        num(got, "ate_rmse_cm"),
        num(got, "psnr_db"),
        num(got, "miou"),
        got["frames"],
        got["frames_lost"],
        num(base, "ate_rmse_cm"),
        num(base, "psnr_db"),
        num(base, "miou"),
    );
    let ate_limit = (2.0 * num(base, "ate_rmse_cm")).max(num(base, "ate_rmse_cm") + 0.1);
    assert!(num(got, "ate_rmse_cm") <= ate_limit, "{tag}: ATE {got}");
    assert!(
        num(got, "psnr_db") >= num(base, "psnr_db") - 2.0,
        "{tag}: PSNR {got}"
    );
    assert!(
        num(got, "miou") >= num(base, "miou") - 5.0,
        "{tag}: mIoU {got}"
    );
    // A hang costs the watchdog's second and the restart, and the camera moves on meanwhile:
    // where it moved too far to be found from the last pose or a keyframe's, the tracker
    // stays lost until it comes back (global relocalisation is not built). At least half of
    // the frames keep a verified pose.
    // (metrics.json: `frames` are the verified poses, `frames_lost` the frames without one.)
    let verified = got["frames"].as_u64().unwrap_or(0);
    assert!(verified >= 60, "{tag}: {verified} verified poses: {got}");
}

/// Killed and hung stages are compared with the fault-free run under the ground-truth
/// segmenter: a fault shifts which frames become keyframes, and with `geometry`, which cuts
/// every frame anew, that alone can leave a box its segmenter once merged with the table in
/// the table's label for good (mIoU 79.4 against 88.0 in some runs of one build, within 1 in
/// others). The faults' cost is what this test measures, not that chaos. PSNR over every
/// fifth pose: over every twentieth (4–5 frames) one frame at the edge of what the hung
/// tracker let be mapped (16 dB against 24–25) moved a run's mean by 1.7 dB (a script
/// faulting runs as this test does: 23.0–23.5 dB in 11 of 12 runs against 25.1 fault-free,
/// the limit 23.1; every fifth pose: 24.2–24.9 in 8 of 8 against 24.6). 100 final steps:
/// without them PSNR followed the online iterations a restart costs and a loaded machine
/// withholds (20.61 against 23.40 fault-free in a full test run; beside a busy loop, gaps of
/// 0.12–0.76 dB before, −0.29 to +0.30 dB after, over 2 and 3 runs).
const FAULT_ARGS: [&str; 8] = [
    "--frames",
    "120",
    "--finish-steps",
    "100",
    "--segmenter",
    "prior",
    "--quality-every",
    "5",
];

#[test]
fn killed_and_hung_stages_cost_seconds_not_the_run() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let clean = dir.path().join("clean");
    let run = opengs_run(&format!("t{}-clean", std::process::id()), &clean)
        .args(FAULT_ARGS)
        .output()
        .expect("run");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let base = metrics(&clean);

    // The map's side: the mapper (checkpointed at its first keyframe and within a second of
    // each keyframe and consensus since), then the consensus. Before: a mapper killed before
    // its first checkpoint came back empty (PSNR 12.7 dB); a restarted consensus skipped
    // keyframes without a word.
    let (out, _) = faulted_run_with(
        dir.path(),
        "map",
        &FAULT_ARGS,
        &[
            (30, "mapper", libc::SIGKILL),
            (60, "consensus", libc::SIGKILL),
        ],
    );
    assert_eq!(stage_record(&out, "mapper")["restarts"], 1);
    assert_eq!(stage_record(&out, "consensus")["restarts"], 1);
    // No keyframe answered twice: service history hands the restarted consensus what its
    // predecessor answered, and it skips those.
    assert!(
        stage_record(&out, "consensus")["processed"].as_u64()
            <= stage_record(&out, "segmenter")["processed"].as_u64()
    );
    // The restarted mapper counts the keyframes mapped before its death.
    let mapper: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("mapper.json")).expect("mapper.json"),
    )
    .expect("json");
    assert_eq!(mapper["restarts"], 1, "{mapper}");
    assert!(mapper["keyframes"].as_u64().unwrap_or(0) >= 8, "{mapper}");
    close_to(&base, &metrics(&out), "mapper and consensus killed");

    // The tracker: killed (before: it restarted at the identity, ATE 45.9 cm), then hung,
    // which only the watchdog can tell.
    let (out, stderr) = faulted_run_with(
        dir.path(),
        "track",
        &FAULT_ARGS,
        &[
            (40, "tracker", libc::SIGKILL),
            (80, "tracker", libc::SIGSTOP),
        ],
    );
    assert!(stderr.contains("hung or stopped; killing it"), "{stderr}");
    let tracker = stage_record(&out, "tracker");
    assert_eq!(tracker["restarts"], 2, "{tracker}");
    assert_eq!(tracker["hangs"], 1, "{tracker}");
    close_to(&base, &metrics(&out), "tracker killed and hung");
}

/// The segmenter stopped: its heartbeats go on during a segmentation (a SAM keyframe takes
/// tens of seconds on a CPU), not while the process is stopped, so its 10 s watchdog finds
/// it within the run (before: 120 s, longer than most runs) and the labels come back.
#[test]
fn a_stopped_segmenter_is_found_in_seconds() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let (out, stderr) = faulted_run_with(
        dir.path(),
        "segment",
        &["--frames", "250", "--finish-steps", "0"],
        &[(20, "segmenter", libc::SIGSTOP)],
    );
    assert!(stderr.contains("stage segmenter"), "{stderr}");
    let segmenter = stage_record(&out, "segmenter");
    assert_eq!(segmenter["hangs"], 1, "{segmenter}");
    assert_eq!(segmenter["restarts"], 1, "{segmenter}");
    // 25 s of data, 10 s of them without a segmenter: the later keyframes are labelled.
    let m = metrics(&out);
    let miou = m["miou"].as_f64().unwrap_or(0.0);
    eprintln!("segmenter stopped at 2 s of 25: mIoU {miou:.1}");
    assert!(miou > 60.0, "{m}");
}

/// The idle-scheduled mapper stopped: the watchdog does not count time it waits for a CPU,
/// so its 10 s watchdog finds a stopped one (before: 60 s, after the end of most runs), and
/// the restarted mapper takes the keyframes sent meanwhile from the service's history
/// (before: lost, PSNR -7 dB in `opengs bench faults`).
#[test]
fn a_stopped_mapper_is_found_in_seconds_and_misses_no_keyframe() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let (out, stderr) = faulted_run_with(
        dir.path(),
        "mapstop",
        &["--frames", "250", "--finish-steps", "0"],
        &[(60, "mapper", libc::SIGSTOP)],
    );
    assert!(stderr.contains("stage mapper"), "{stderr}");
    let mapper = stage_record(&out, "mapper");
    assert_eq!(mapper["hangs"], 1, "{mapper}");
    assert_eq!(mapper["restarts"], 1, "{mapper}");
    let log = std::fs::read_to_string(out.join("logs/mapper.log")).expect("mapper.log");
    let taken = log
        .lines()
        .find_map(|l| {
            let (_, rest) = l.split_once("restarted: ")?;
            rest.split_once(" keyframes it had missed")?
                .0
                .parse::<u64>()
                .ok()
        })
        .expect("the restarted mapper says what it took from the history");
    assert!(taken > 0, "the keyframes of 10 s of data came back: {log}");
    // Every keyframe the segmenter saw was mapped, once.
    let seqs: Vec<u64> = std::fs::read_to_string(out.join("keyframes.txt"))
        .expect("keyframes.txt")
        .lines()
        .filter_map(|l| l.trim().parse().ok())
        .collect();
    let distinct: std::collections::BTreeSet<u64> = seqs.iter().copied().collect();
    assert_eq!(
        distinct.len(),
        seqs.len(),
        "a keyframe mapped twice: {seqs:?}"
    );
    let segmented = stage_record(&out, "segmenter")["processed"]
        .as_u64()
        .unwrap_or(0);
    eprintln!(
        "mapper stopped at 6 s of 25: {taken} keyframes from the history, {} mapped, {segmented} segmented",
        seqs.len()
    );
    assert!(seqs.len() as u64 >= segmented, "{seqs:?}");
}

/// The supervisor itself SIGKILLed mid-run (before: no trajectory.txt, run.json or latency,
/// 77 poses lost): its snapshots leave a directory `opengs eval` scores.
#[test]
fn a_killed_supervisor_leaves_a_usable_run_directory() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("run");
    let run_id = format!("t{}-supkill", std::process::id());
    let child = opengs_run(&run_id, &out)
        .args(["--frames", "300", "--finish-steps", "0"])
        .spawn()
        .expect("run starts");
    let mut guard = Guard(child);
    let deadline = Instant::now() + Duration::from_secs(60);
    wait_poses(&run_id, 80, deadline);
    // A snapshot is at most 5 s old; wait for one that has poses in it.
    while !std::fs::read_to_string(out.join("trajectory.txt")).is_ok_and(|t| t.lines().count() > 20)
    {
        assert!(Instant::now() < deadline, "no snapshot of the trajectory");
        std::thread::sleep(Duration::from_millis(100));
    }
    let _ = guard.0.kill();
    let _ = guard.0.wait();
    let trajectory = std::fs::read_to_string(out.join("trajectory.txt")).expect("trajectory");
    let poses = trajectory.lines().filter(|l| !l.starts_with('#')).count();
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).expect("run.json"))
            .expect("run.json parses");
    assert_eq!(record["run_id"], run_id.as_str());
    let latency: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("latency.json")).expect("latency.json"),
    )
    .expect("latency.json parses");
    assert!(latency["stages"]["tracker"]["count"].as_u64().unwrap_or(0) > 0);
    let eval = Command::new(opengs_e2e::binary("opengs"))
        .arg("eval")
        .arg(&out)
        .output()
        .expect("opengs eval");
    assert!(
        eval.status.success(),
        "{}",
        String::from_utf8_lossy(&eval.stderr)
    );
    let scored = metrics(&out);
    eprintln!(
        "killed supervisor: {poses} poses kept, ATE {:.3} cm",
        scored["ate_rmse_cm"].as_f64().unwrap_or(f64::NAN)
    );
    assert!(poses > 20);
    assert!(
        scored["ate_rmse_cm"].as_f64().is_some_and(|a| a < 1.0),
        "{scored}"
    );
}

/// A corrupt frame is bad input, not a crash: the sensor stops on it (exit 65) and is not
/// restarted (before: three restarts that read the same file, then exit 3); the run ends with
/// exit 4 naming the file, and what came before it is kept.
#[test]
fn a_corrupt_frame_stops_the_run_naming_it() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let data = dir.path().join("tum");
    synth_tum(&data, 40);
    let mut depth: Vec<PathBuf> = std::fs::read_dir(data.join("depth"))
        .expect("depth dir")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    depth.sort();
    let broken = &depth[25];
    std::fs::write(broken, b"\x89PNG\r\n\x1a\n but not really").expect("break a frame");
    let out = dir.path().join("run");
    let run = opengs_run(&format!("t{}-corrupt", std::process::id()), &out)
        .arg("--dataset")
        .arg(format!("tum:{}", data.display()))
        .args(["--finish-steps", "0"])
        .output()
        .expect("run");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(4), "{stderr}");
    let name = broken.file_name().and_then(|n| n.to_str()).unwrap_or("?");
    assert!(
        stderr.contains("stopped on input it cannot use"),
        "{stderr}"
    );
    assert!(stderr.contains(name), "names {name}: {stderr}");
    assert!(!stderr.contains("restarted sensor"), "{stderr}");
    let trajectory = std::fs::read_to_string(out.join("trajectory.txt")).expect("kept");
    assert!(
        trajectory.lines().filter(|l| !l.starts_with('#')).count() >= 20,
        "{trajectory}"
    );
}

/// A recording's gap is replayed as a gap, and a gap longer than the sensor's watchdog is
/// not a hang: the waiting sensor keeps sending heartbeats (before: silent for the whole
/// gap, so a 12 s gap under the 10 s watchdog killed and restarted it). Here a 2.5 s gap
/// under a 1 s watchdog.
#[test]
fn a_gap_in_the_recording_is_waited_out_not_taken_for_a_hang() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let data = dir.path().join("tum");
    synth_tum(&data, 20);
    // Frames 10 and after come 2.5 s later than recorded.
    for list in ["rgb.txt", "depth.txt", "groundtruth.txt"] {
        let path = data.join(list);
        let text = std::fs::read_to_string(&path).expect(list);
        let mut frame = 0;
        let shifted: Vec<String> = text
            .lines()
            .map(|line| {
                let Some((stamp, rest)) = line.split_once(' ') else {
                    return line.to_string();
                };
                match stamp.parse::<f64>() {
                    Ok(t) if !line.starts_with('#') => {
                        frame += 1;
                        let t = if frame > 10 { t + 2.5 } else { t };
                        format!("{t:.6} {rest}")
                    }
                    _ => line.to_string(),
                }
            })
            .collect();
        std::fs::write(&path, shifted.join("\n") + "\n").expect(list);
    }
    let desktop = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/desktop.toml"),
    )
    .expect("desktop.toml");
    let deploy = dir.path().join("impatient.toml");
    std::fs::write(&deploy, format!("{desktop}watchdog_s = 1\n")).expect("deploy");
    assert!(
        desktop.trim_end().ends_with("role = \"source\""),
        "the sensor is last"
    );
    let out = dir.path().join("run");
    let started = Instant::now();
    let run = opengs_run(&format!("t{}-gap", std::process::id()), &out)
        .arg("--dataset")
        .arg(format!("tum:{}", data.display()))
        .arg("--deploy")
        .arg(&deploy)
        .args(["--finish-steps", "0"])
        .output()
        .expect("run");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(
        started.elapsed() >= Duration::from_millis(2500),
        "the gap was replayed"
    );
    assert_eq!(stage_record(&out, "sensor")["restarts"], 0, "{stderr}");
    let trajectory = std::fs::read_to_string(out.join("trajectory.txt")).expect("trajectory");
    assert_eq!(
        trajectory.lines().filter(|l| !l.starts_with('#')).count(),
        20,
        "{trajectory}"
    );
}
