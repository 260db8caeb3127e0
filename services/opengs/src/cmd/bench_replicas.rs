//! `opengs bench replicas`: segmenter replicas through the real pipeline on the built-in room,
//! with the segmenter held to a fixed time per keyframe (`--segmenter-min-call-ms`, a stand-in
//! for SAM on a CPU that costs no CPU, so the scaling shows on 2 cores). One run per replica
//! count: keyframes, keyframes segmented (and how many twice, from the telemetry: must be 0),
//! the ratio to one replica, keyframes the consensus answered, mIoU. Then one run
//! that starts with one replica and is scaled up and down with `opengs ctl scale` while it
//! goes: the longest gap between two segmentations around each change, against the period.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::Context;
use serde::Serialize;

use super::bench_faults::{read_json, start_run, wait_for_poses, wait_timeout};

#[derive(clap::Args)]
pub struct BenchReplicasArgs {
    /// Small: 150 frames, 1 and 2 replicas, the scale run.
    #[arg(long)]
    quick: bool,
    /// Frames of the built-in room per run (default 600, the default run; 150 with --quick).
    #[arg(long, value_parser = clap::value_parser!(u64).range(30..))]
    frames: Option<u64>,
    /// Milliseconds each keyframe takes the segmenter.
    #[arg(long, default_value_t = 2000, value_parser = clap::value_parser!(u64).range(1..))]
    min_call_ms: u64,
    /// Replica counts to run, comma-separated (default 1,2,4; 1,2 with --quick).
    #[arg(long, value_delimiter = ',',
          value_parser = clap::value_parser!(u32).range(1..=opengs_pipeline::deploy::MAX_REPLICAS as i64))]
    replicas: Vec<u32>,
    /// Sensor rate in frames/s (default: the default run's 10). Faster replay makes keyframes
    /// come faster than one replica can take them.
    #[arg(long)]
    max_rate: Option<f64>,
    /// Where the runs and bench_replicas.json go.
    #[arg(long, default_value = "bench_replicas")]
    out_root: PathBuf,
}

#[derive(Debug, Default, Serialize)]
struct Row {
    case: String,
    replicas: String,
    exit: Option<i32>,
    keyframes: u64,
    segmented: u64,
    /// Segmentations of a keyframe segmented before (must be 0).
    segmented_twice: u64,
    /// Segmented, against the one-replica run.
    ratio: Option<f64>,
    /// Keyframes the consensus answered.
    answered: u64,
    /// Segmented per replica, in replica order.
    per_replica: Vec<u64>,
    miou: Option<f64>,
    /// Longest time between two segmentations while the data streamed (s).
    longest_gap_s: Option<f64>,
    /// The scale run: each `ctl scale` with the longest gap around it (s).
    scale_events: Vec<ScaleEvent>,
    note: String,
}

#[derive(Debug, Default, Serialize)]
struct ScaleEvent {
    to: u32,
    reply: String,
    /// Longest gap between segmentations from one period before the request to one after
    /// its reply (s).
    gap_s: Option<f64>,
}

pub fn run(args: BenchReplicasArgs) -> anyhow::Result<()> {
    let frames = args
        .frames
        .map_or(if args.quick { 150 } else { 600 }, |f| f as usize);
    let period_ms = args.min_call_ms;
    let counts = match (args.replicas.is_empty(), args.quick) {
        (false, _) => args.replicas.clone(),
        (true, true) => vec![1, 2],
        (true, false) => vec![1, 2, 4],
    };
    let opengs = std::env::current_exe().context("locating opengs")?;
    std::fs::create_dir_all(&args.out_root)
        .with_context(|| format!("creating {}", args.out_root.display()))?;
    println!(
        "segmenter replicas: {frames} frames of the built-in room, {period_ms} ms per keyframe, \
         {} Hz, no final optimisation; runs in {}",
        args.max_rate.unwrap_or(10.0),
        args.out_root.display()
    );
    let period = Duration::from_millis(period_ms);
    let setup = Setup {
        opengs: &opengs,
        frames,
        period,
        max_rate: args.max_rate,
    };
    let mut rows: Vec<Row> = Vec::new();
    for (i, &n) in counts.iter().enumerate() {
        let dir = args.out_root.join(format!("replicas_{n}"));
        let row = setup.run_case(&dir, i, n, &[]).unwrap_or_else(|e| Row {
            note: format!("{e:#}"),
            ..Row::default()
        });
        rows.push(Row {
            case: format!("{n} replica{}", if n == 1 { "" } else { "s" }),
            ..row
        });
    }
    // Up to 2 a third of the way, back to 1 at two thirds.
    let plan = [(frames / 3, 2), (frames * 2 / 3, 1)];
    let dir = args.out_root.join("scaled");
    let row = setup
        .run_case(&dir, counts.len(), 1, &plan)
        .unwrap_or_else(|e| Row {
            note: format!("{e:#}"),
            ..Row::default()
        });
    rows.push(Row {
        case: "1 → 2 → 1 (ctl scale)".into(),
        ..row
    });
    let single = rows
        .iter()
        .find(|r| r.replicas == "1" && r.exit == Some(0))
        .map(|r| r.segmented);
    for r in &mut rows {
        r.ratio = single
            .filter(|&s| s > 0)
            .map(|s| r.segmented as f64 / s as f64);
    }
    println!(
        "{:<24} {:>9} {:>9} {:>6} {:>6} {:>8} {:>6} {:>8}  per replica",
        "case", "keyframes", "segmented", "twice", "ratio", "answered", "mIoU", "gap s"
    );
    for r in &rows {
        println!(
            "{:<24} {:>9} {:>9} {:>6} {:>6} {:>8} {:>6} {:>8}  {:?}{}",
            r.case,
            r.keyframes,
            r.segmented,
            r.segmented_twice,
            r.ratio.map_or("-".into(), |v| format!("{v:.2}")),
            r.answered,
            r.miou.map_or("-".into(), |v| format!("{v:.1}")),
            r.longest_gap_s.map_or("-".into(), |v| format!("{v:.2}")),
            r.per_replica,
            if r.note.is_empty() {
                String::new()
            } else {
                format!("  [{}]", r.note)
            }
        );
        for e in &r.scale_events {
            println!(
                "    scale to {}: longest gap around it {} s (period {:.2} s); {}",
                e.to,
                e.gap_s.map_or("-".into(), |v| format!("{v:.2}")),
                period.as_secs_f64(),
                e.reply
            );
        }
    }
    let json = args.out_root.join("bench_replicas.json");
    std::fs::write(&json, serde_json::to_string_pretty(&rows)?)
        .with_context(|| format!("writing {}", json.display()))?;
    println!("rows: {}", json.display());
    Ok(())
}

struct Setup<'a> {
    opengs: &'a Path,
    frames: usize,
    period: Duration,
    max_rate: Option<f64>,
}

impl Setup<'_> {
    /// One run with `replicas` segmenters, scaled to `to` at each `(poses, to)` of `plan`.
    fn run_case(
        &self,
        dir: &Path,
        index: usize,
        replicas: u32,
        plan: &[(usize, u32)],
    ) -> anyhow::Result<Row> {
        let run_id = format!("replicas{}-{index}", std::process::id());
        let mut args: Vec<String> = [
            "--finish-steps",
            "0",
            "--frames",
            &self.frames.to_string(),
            "--segmenter-replicas",
            &replicas.to_string(),
            "--segmenter-min-call-ms",
            &self.period.as_millis().to_string(),
        ]
        .map(String::from)
        .to_vec();
        if let Some(rate) = self.max_rate {
            args.extend(["--max-rate".into(), rate.to_string()]);
        }
        let started = Instant::now();
        let mut child = start_run(self.opengs, dir, &run_id, &args)?;
        let mut events = Vec::new();
        for &(at, to) in plan {
            if !wait_for_poses(self.opengs, &run_id, &mut child, at)? {
                break;
            }
            let asked = opengs_ipc_schema::now_ns();
            let out = Command::new(self.opengs)
                .args(["ctl", "--run", &run_id, "scale", "segmenter", "--to"])
                .arg(to.to_string())
                .output()?;
            let answered = opengs_ipc_schema::now_ns();
            let text = String::from_utf8_lossy(if out.status.success() {
                &out.stdout
            } else {
                &out.stderr
            })
            .trim()
            .replace('\n', "; ");
            events.push((to, text, asked, answered));
        }
        let exit = wait_timeout(&mut child, Duration::from_secs(900))?;
        let mut row = Row {
            replicas: replicas.to_string(),
            exit,
            ..Row::default()
        };
        let record = read_json(&dir.join("run.json"))?;
        let stages = record["stages"].as_array().cloned().unwrap_or_default();
        let count = |name: &str| {
            stages
                .iter()
                .filter(|s| s["name"] == name)
                .filter_map(|s| s["processed"].as_u64())
                .sum::<u64>()
        };
        row.segmented = count("segmenter");
        row.answered = count("consensus");
        row.per_replica = stages
            .iter()
            .filter(|s| s["name"] == "segmenter")
            .filter_map(|s| s["processed"].as_u64())
            .collect();
        // The tracker's keyframes, from the run's summary line ("..., 63 keyframes, ...").
        let summary = std::fs::read_to_string(dir.with_extension("log")).unwrap_or_default();
        row.keyframes = summary
            .split(", ")
            .find_map(|part| part.strip_suffix(" keyframes")?.parse().ok())
            .unwrap_or(0);
        if let Ok(m) = read_json(&dir.join("metrics.json")) {
            row.miou = m["miou"].as_f64();
        }
        let (origin, segmentations) = segmentations(&dir.join("trace.json"))?;
        // From the telemetry, not the claims: a keyframe two processes segmented shows twice.
        let distinct: std::collections::BTreeSet<u64> =
            segmentations.iter().map(|&(_, seq)| seq).collect();
        row.segmented_twice = (segmentations.len() - distinct.len()) as u64;
        let ends: Vec<u64> = segmentations.iter().map(|&(end, _)| end).collect();
        row.longest_gap_s = longest_gap(&ends, 0, u64::MAX);
        for (to, reply, asked, answered) in events {
            let p = self.period.as_nanos() as u64;
            let from = asked.saturating_sub(origin).saturating_sub(p);
            let until = answered.saturating_sub(origin) + p;
            row.scale_events.push(ScaleEvent {
                to,
                reply,
                gap_s: longest_gap(&ends, from, until),
            });
        }
        row.note = format!("{:.0} s", started.elapsed().as_secs_f64());
        Ok(row)
    }
}

/// The trace's origin (ns) and every segmentation: (end, ns after the origin; keyframe seq),
/// by end.
fn segmentations(trace: &Path) -> anyhow::Result<(u64, Vec<(u64, u64)>)> {
    let v = read_json(trace)?;
    let origin: u64 = v["otherData"]["origin_ns"]
        .as_str()
        .and_then(|s| s.parse().ok())
        .with_context(|| format!("{}: no otherData.origin_ns", trace.display()))?;
    let mut spans: Vec<(u64, u64)> = v["traceEvents"]
        .as_array()
        .map(|a| a.as_slice())
        .unwrap_or_default()
        .iter()
        .filter(|e| {
            e["ph"] == "X"
                && e["cat"]
                    .as_str()
                    .is_some_and(|c| c.starts_with("segmenter"))
        })
        .filter_map(|e| {
            let end = (e["ts"].as_f64()? + e["dur"].as_f64()?) * 1e3;
            Some((end as u64, e["args"]["seq"].as_u64()?))
        })
        .collect();
    spans.sort_unstable();
    Ok((origin, spans))
}

/// The longest time (s) between consecutive segmentations whose interval overlaps
/// [`from`, `until`] (ns after the origin).
fn longest_gap(ends: &[u64], from: u64, until: u64) -> Option<f64> {
    ends.windows(2)
        .filter(|w| w[1] >= from && w[0] <= until)
        .map(|w| (w[1] - w[0]) as f64 / 1e9)
        .max_by(f64::total_cmp)
}

#[cfg(test)]
mod tests {
    use super::longest_gap;

    #[test]
    fn the_gap_around_a_moment_is_the_longest_interval_touching_it() {
        let s = 1_000_000_000;
        let ends = [0, 2 * s, 4 * s, 5 * s, 9 * s, 10 * s];
        assert_eq!(longest_gap(&ends, 0, u64::MAX), Some(4.0));
        // [3 s, 4.5 s] touches 2→4 and 4→5.
        assert_eq!(longest_gap(&ends, 3 * s, 4 * s + s / 2), Some(2.0));
        assert_eq!(longest_gap(&ends[..1], 0, u64::MAX), None);
    }
}
