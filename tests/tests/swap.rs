//! Swapping the segmenter while the pipeline runs: classic → prior → classic, and sam →
//! mobilesamv2 → sam with their own model files (and a broken set that changes nothing).

use std::process::Command;
use std::time::{Duration, Instant};

use opengs_e2e::{binary, opengs_run, serial};

fn swap(run_id: &str, to: &str) {
    let out = Command::new(binary("opengs"))
        .args(["ctl", "--run", run_id, "swap", "segmenter", "--to", to])
        .output()
        .expect("ctl swap");
    assert!(
        out.status.success(),
        "swap to {to}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn segmenter_swaps_mid_run_without_a_gap() {
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let deploy = dir.path().join("deploy.toml");
    std::fs::write(
        &deploy,
        format!(
            r#"description = "test: segments watched by the probe"
terminal_stage = "tracker"
[[stages]]
name = "probe"
binary = "{}"
args = ["--segments"]
[[stages]]
name = "segmenter"
binary = "opengs-segmenter"
kind = "classic"
dataset = true
[[stages]]
name = "tracker"
binary = "opengs-tracker"
[[stages]]
name = "sensor"
binary = "opengs-sensor"
role = "source"
"#,
            binary("opengs-frame-probe").display()
        ),
    )
    .expect("deploy");
    let out = dir.path().join("run");
    let run_id = format!("t{}-swap", std::process::id());
    let run = opengs_run(&run_id, &out)
        .args(["--frames", "360", "--max-rate", "30"])
        .arg("--deploy")
        .arg(&deploy)
        .spawn()
        .expect("run starts");
    let log = out.join("logs/probe.log");
    let deadline = Instant::now() + Duration::from_secs(120);
    for (after, to) in [(3, "prior"), (6, "classic")] {
        while segment_rows(&log).len() < after {
            assert!(
                Instant::now() < deadline,
                "segments stopped arriving before the swap to {to}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        swap(&run_id, to);
    }
    let output = run.wait_with_output().expect("run ends");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );

    // seq, arrival, segmenter kind (0 classic, 1 prior), label count.
    let rows = segment_rows(&log);
    let kinds: Vec<u32> = rows.iter().map(|r| r.2).collect();
    let first_prior = kinds
        .iter()
        .position(|&k| k == 1)
        .expect("prior segments arrived");
    let back = kinds[first_prior..]
        .iter()
        .position(|&k| k == 0)
        .expect("classic segments after the second swap");
    assert!(kinds[..first_prior].iter().all(|&k| k == 0));
    assert!(
        back > 0 && rows.len() > first_prior + back + 1,
        "segments kept arriving after the last swap: {kinds:?}"
    );
    // The gap across each swap is at most one segmentation period longer than the usual gap.
    let gaps: Vec<u64> = rows.windows(2).map(|w| w[1].1 - w[0].1).collect();
    let mut sorted = gaps.clone();
    sorted.sort_unstable();
    let usual = sorted[sorted.len() / 2];
    let period = usual; // one keyframe → one segmentation
    eprintln!(
        "{} segmentations; usual gap {} ms; gaps at the swaps {} ms and {} ms",
        rows.len(),
        usual / 1_000_000,
        gaps[first_prior - 1] / 1_000_000,
        gaps[first_prior + back - 1] / 1_000_000
    );
    // 200 ms of slack for scheduling on a loaded 2-core machine.
    for i in [first_prior - 1, first_prior + back - 1] {
        assert!(
            gaps[i] <= usual + period + 200_000_000,
            "gap at swap {} ms vs usual {} ms",
            gaps[i] / 1_000_000,
            usual / 1_000_000
        );
    }
    let status: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).expect("run.json"))
            .expect("json");
    assert_eq!(status["stages"][1]["restarts"], 0);
}

/// `(seq, arrival ns, kind id)` of every segmentation the probe saw.
fn segment_rows(log: &std::path::Path) -> Vec<(u64, u64, u32)> {
    std::fs::read_to_string(log)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| {
            let v: Vec<&str> = l.split_whitespace().collect();
            if v.len() != 4 {
                return None;
            }
            Some((v[0].parse().ok()?, v[1].parse().ok()?, v[2].parse().ok()?))
        })
        .collect()
}

/// `opengs ctl swap segmenter --to KIND`: (exit ok, stdout, stderr).
fn try_swap(run_id: &str, to: &str) -> (bool, String, String) {
    let out = Command::new(binary("opengs"))
        .args(["ctl", "--run", run_id, "swap", "segmenter", "--to", to])
        .output()
        .expect("ctl swap");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const SAM: u32 = 2;
const MOBILESAMV2: u32 = 3;

#[test]
fn sam_and_mobilesamv2_swap_each_with_its_own_models() {
    if std::env::var_os("ORT_DYLIB_PATH").is_none() {
        assert!(
            std::env::var_os("OPENGS_REQUIRE_ORT").is_none(),
            "OPENGS_REQUIRE_ORT is set but ORT_DYLIB_PATH is not (run scripts/setup-ort.sh)"
        );
        eprintln!("skipped: ORT_DYLIB_PATH is not set (scripts/setup-ort.sh)");
        return;
    }
    let _serial = serial();
    let dir = tempfile::tempdir().expect("tmp");
    let fixtures = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../common/perception/tests/fixtures");
    // MobileSAMv2's set is a copy, so the test can break it for the failing swap.
    let mobile = dir.path().join("mobile");
    std::fs::create_dir_all(&mobile).expect("dir");
    for f in [
        "tiny_sam_encoder.onnx",
        "tiny_sam_decoder.onnx",
        "tiny_proposals.onnx",
    ] {
        std::fs::copy(fixtures.join(f), mobile.join(f)).expect("copy fixture");
    }
    let path = |p: std::path::PathBuf| p.display().to_string();
    let deploy = dir.path().join("deploy.toml");
    std::fs::write(
        &deploy,
        format!(
            r#"description = "test: SAM and MobileSAMv2, each with its own model files"
terminal_stage = "tracker"
[[stages]]
name = "probe"
binary = "{probe}"
args = ["--segments"]
[[stages]]
name = "segmenter"
binary = "opengs-segmenter"
kind = "sam"
dataset = true
[stages.kinds.sam]
args = ["--encoder", "{sam_enc}", "--decoder", "{sam_dec}", "--points-per-side", "8"]
[stages.kinds.mobilesamv2]
args = ["--encoder", "{m_enc}", "--decoder", "{m_dec}", "--proposals", "{m_prop}"]
[[stages]]
name = "tracker"
binary = "opengs-tracker"
[[stages]]
name = "sensor"
binary = "opengs-sensor"
role = "source"
"#,
            probe = path(binary("opengs-frame-probe")),
            sam_enc = path(fixtures.join("tiny_sam_encoder.onnx")),
            sam_dec = path(fixtures.join("tiny_sam_decoder.onnx")),
            m_enc = path(mobile.join("tiny_sam_encoder.onnx")),
            m_dec = path(mobile.join("tiny_sam_decoder.onnx")),
            m_prop = path(mobile.join("tiny_proposals.onnx")),
        ),
    )
    .expect("deploy");
    let out = dir.path().join("run");
    let run_id = format!("t{}-samswap", std::process::id());
    let run = opengs_run(&run_id, &out)
        .args(["--frames", "900", "--max-rate", "30"])
        .arg("--deploy")
        .arg(&deploy)
        .spawn()
        .expect("run starts");
    let log = out.join("logs/probe.log");
    let deadline = Instant::now() + Duration::from_secs(150);
    // Waits until `n` more segmentations of `kind` arrived.
    let wait_for = |kind: u32, n: usize| {
        let before = segment_rows(&log).iter().filter(|r| r.2 == kind).count();
        while segment_rows(&log).iter().filter(|r| r.2 == kind).count() < before + n {
            assert!(
                Instant::now() < deadline,
                "no {n} more segmentations of kind {kind}: {:?}",
                segment_rows(&log)
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    wait_for(SAM, 2);
    for (to, kind) in [("mobilesamv2", MOBILESAMV2), ("sam", SAM)] {
        let (ok, stdout, stderr) = try_swap(&run_id, to);
        assert!(ok, "swap to {to}: {stdout}{stderr}");
        assert!(stdout.contains(&format!("to {to} (pid ")), "{stdout}");
        assert!(stdout.contains("first output after"), "{stdout}");
        wait_for(kind, 2);
    }
    // A broken model set: the swap fails, names the file, and SAM keeps segmenting.
    std::fs::write(mobile.join("tiny_proposals.onnx"), b"not an onnx file").expect("break");
    let (ok, stdout, stderr) = try_swap(&run_id, "mobilesamv2");
    assert!(!ok, "a broken model set must fail the swap: {stdout}");
    assert!(stderr.contains("tiny_proposals.onnx"), "{stderr}");
    assert!(stderr.contains("sam keeps running"), "{stderr}");
    wait_for(SAM, 2);
    let stop = Command::new(binary("opengs"))
        .args(["ctl", "--run", &run_id, "stop"])
        .output()
        .expect("ctl stop");
    assert!(stop.status.success());
    let output = run.wait_with_output().expect("run ends");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );

    let rows = segment_rows(&log);
    let kinds: Vec<u32> = rows.iter().map(|r| r.2).collect();
    // sam, then mobilesamv2, then sam to the end: the failed swap changed nothing. While both
    // processes run (make-before-break: the old one finishes the keyframe it is on) both
    // kinds may arrive, at most two strays per swap; the consensus takes one per keyframe.
    assert_eq!(kinds.first(), Some(&SAM), "{kinds:?}");
    assert!(kinds.contains(&MOBILESAMV2), "{kinds:?}");
    let last_mobile = kinds.iter().rposition(|&k| k == MOBILESAMV2).unwrap_or(0);
    assert!(
        kinds.len() - last_mobile > 4,
        "sam alone after the last swap, through the failed one: {kinds:?}"
    );
    let changes = kinds.windows(2).filter(|w| w[0] != w[1]).count();
    assert!(changes <= 2 + 2 * 2, "{changes} kind changes: {kinds:?}");
    // Around each swap the gap is at most one segmentation period of the new kind longer
    // than the usual gap of the old one (the kinds' periods differ: the grid costs more).
    let gaps: Vec<u64> = rows.windows(2).map(|w| w[1].1 - w[0].1).collect();
    let median_gap = |kind: u32| {
        let mut g: Vec<u64> = rows
            .windows(2)
            .filter(|w| w[0].2 == kind && w[1].2 == kind)
            .map(|w| w[1].1 - w[0].1)
            .collect();
        g.sort_unstable();
        g.get(g.len() / 2).copied().unwrap_or(0)
    };
    for i in (0..gaps.len()).filter(|&i| kinds[i] != kinds[i + 1]) {
        let (old, new) = (median_gap(kinds[i]), median_gap(kinds[i + 1]));
        eprintln!(
            "gap at swap {} ms; usual {} ms before, {} ms after",
            gaps[i] / 1_000_000,
            old / 1_000_000,
            new / 1_000_000
        );
        // The new kind waits for a keyframe (at most the old kind's usual gap) and runs its
        // first (warmed up, but beside the old process's exit: up to a quarter slower than
        // its median), with 200 ms of slack for scheduling on a loaded 2-core machine.
        assert!(
            gaps[i] <= old + new + new / 4 + 200_000_000,
            "gap at swap {} ms vs usual {} ms and period {} ms",
            gaps[i] / 1_000_000,
            old / 1_000_000,
            new / 1_000_000
        );
    }
    let status: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).expect("run.json"))
            .expect("json");
    assert_eq!(status["stages"][1]["restarts"], 0);
}
