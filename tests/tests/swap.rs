//! Swapping the segmenter while the pipeline runs: classic → prior → classic.

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

fn segments_seen(log: &std::path::Path) -> usize {
    std::fs::read_to_string(log)
        .map(|t| {
            t.lines()
                .filter(|l| l.split_whitespace().count() == 4)
                .count()
        })
        .unwrap_or(0)
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
        while segments_seen(&log) < after {
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
    let rows: Vec<(u64, u64, u32)> = std::fs::read_to_string(&log)
        .expect("probe log")
        .lines()
        .filter_map(|l| {
            let v: Vec<&str> = l.split_whitespace().collect();
            (v.len() == 4).then(|| (v[0].parse().ok(), v[1].parse().ok(), v[2].parse().ok()))
        })
        .filter_map(|(a, b, c)| Some((a?, b?, c?)))
        .collect();
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
