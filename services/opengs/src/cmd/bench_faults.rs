//! `opengs bench faults`: the fault campaign through the real pipeline on the built-in room.
//! A fault-free run, then every stage SIGKILLed early (after its first keyframe) and mid-run,
//! every stage SIGSTOPped once mid-run (only the watchdog can tell), the mapper SIGKILLed
//! during the final optimisation, and the supervisor SIGKILLed once (its run directory must
//! still be scored by `opengs eval`, which scores its trajectory). One row per case: exit status, the stage's restarts and
//! hangs, poses, lost frames, ATE, PSNR, mIoU, and whether the run stays within 2× ATE (or
//! +0.1 cm: sub-millimetre baselines), 2 dB and 5 mIoU points of the fault-free run.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use serde::Serialize;

const STAGES: [&str; 5] = ["sensor", "tracker", "mapper", "segmenter", "consensus"];

#[derive(clap::Args)]
pub struct BenchFaultsArgs {
    /// The small campaign: 120 frames, each stage killed mid-run, the tracker stopped, the
    /// supervisor killed; no final optimisation.
    #[arg(long)]
    quick: bool,
    /// Frames of the built-in room per run (default 300; 120 with --quick).
    #[arg(long, value_parser = clap::value_parser!(u64).range(20..))]
    frames: Option<u64>,
    /// Final optimisation steps (default 200; 0 with --quick: no mapper-during-finish case).
    #[arg(long)]
    finish_steps: Option<usize>,
    /// Only the cases whose name contains this (e.g. "stop mapper"); the fault-free run,
    /// which the others are compared with, always runs first.
    #[arg(long)]
    only: Option<String>,
    /// Where the runs and bench_faults.json go.
    #[arg(long, default_value = "bench_faults")]
    out_root: PathBuf,
}

#[derive(Debug, Clone, Copy)]
enum Fault {
    None,
    /// SIGKILL or SIGSTOP to `stage` once the run has `at` poses.
    Signal {
        stage: &'static str,
        signal: i32,
        at: usize,
    },
    /// SIGKILL to the mapper a few seconds into its final optimisation.
    KillDuringFinish,
    /// SIGKILL to the supervisor (`opengs run` itself) at `at` poses.
    KillSupervisor {
        at: usize,
    },
}

#[derive(Debug, Default, Serialize)]
struct Row {
    case: String,
    exit: Option<i32>,
    restarts: u64,
    hangs: u64,
    /// Frames with a verified pose, and frames the tracker reported lost.
    poses: Option<u64>,
    lost: Option<u64>,
    ate_rmse_cm: Option<f64>,
    psnr_db: Option<f64>,
    miou: Option<f64>,
    within: bool,
    note: String,
}

pub fn run(args: BenchFaultsArgs) -> anyhow::Result<()> {
    let frames = args
        .frames
        .map_or(if args.quick { 120 } else { 300 }, |f| f as usize);
    let finish = args
        .finish_steps
        .unwrap_or(if args.quick { 0 } else { 200 });
    let opengs = std::env::current_exe().context("locating opengs")?;
    std::fs::create_dir_all(&args.out_root)
        .with_context(|| format!("creating {}", args.out_root.display()))?;
    let (early, mid) = (frames * 15 / 100, frames / 2);
    let mut cases: Vec<(String, Fault)> = vec![("fault-free".into(), Fault::None)];
    for stage in STAGES {
        let kill = |at| Fault::Signal {
            stage,
            signal: libc::SIGKILL,
            at,
        };
        if !args.quick {
            cases.push((format!("kill {stage} early"), kill(early)));
        }
        cases.push((format!("kill {stage} mid-run"), kill(mid)));
        if !args.quick || stage == "tracker" {
            cases.push((
                format!("stop {stage} mid-run"),
                Fault::Signal {
                    stage,
                    signal: libc::SIGSTOP,
                    at: mid,
                },
            ));
        }
    }
    if finish > 0 {
        cases.push((
            "kill mapper in final optimisation".into(),
            Fault::KillDuringFinish,
        ));
    }
    cases.push((
        "kill supervisor mid-run".into(),
        Fault::KillSupervisor { at: mid },
    ));
    if let Some(only) = &args.only {
        cases.retain(|(name, fault)| matches!(fault, Fault::None) || name.contains(only.as_str()));
        if cases.len() == 1 {
            anyhow::bail!("--only '{only}': no fault case has that in its name");
        }
    }
    println!(
        "fault campaign: {} runs of {frames} frames of the built-in room, final optimisation \
         {finish} steps; runs in {}",
        cases.len(),
        args.out_root.display()
    );
    let mut rows: Vec<Row> = Vec::new();
    for (i, (name, fault)) in cases.iter().enumerate() {
        let started = Instant::now();
        let dir = args.out_root.join(name.replace(' ', "_"));
        let mut row = run_case(&opengs, &dir, i, frames, finish, *fault).unwrap_or_else(|e| Row {
            note: format!("{e:#}"),
            ..Row::default()
        });
        row.case = name.clone();
        if let Some(base) = rows.first() {
            row.within = match fault {
                // `opengs eval` scores a dead supervisor's trajectory; render and label
                // scores need the end of the run.
                Fault::KillSupervisor { .. } => ate_within(base, &row),
                _ => within(base, &row),
            };
        } else {
            row.within = row.exit == Some(0);
        }
        println!(
            "  {:<36} exit {:>4}  restarts {} hangs {}  verified {:>4} lost {:>3}  ATE {:>7} cm  \
             PSNR {:>6} dB  mIoU {:>5}  {}  ({:.0} s){}",
            row.case,
            row.exit.map_or("-".into(), |c| c.to_string()),
            row.restarts,
            row.hangs,
            row.poses.map_or("-".into(), |p| p.to_string()),
            row.lost.map_or("-".into(), |p| p.to_string()),
            fmt(row.ate_rmse_cm, 3),
            fmt(row.psnr_db, 2),
            fmt(row.miou, 1),
            if row.within { "ok" } else { "OUTSIDE" },
            started.elapsed().as_secs_f64(),
            if row.note.is_empty() {
                String::new()
            } else {
                format!("  [{}]", row.note)
            }
        );
        rows.push(row);
    }
    let outside = rows.iter().filter(|r| !r.within).count();
    println!(
        "{} of {} runs within 2x ATE (or +0.1 cm), 2 dB PSNR and 5 mIoU points of the fault-free run",
        rows.len() - outside,
        rows.len()
    );
    let json = args.out_root.join("bench_faults.json");
    std::fs::write(&json, serde_json::to_string_pretty(&rows)?)
        .with_context(|| format!("writing {}", json.display()))?;
    println!("rows: {}", json.display());
    Ok(())
}

fn fmt(v: Option<f64>, decimals: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.decimals$}"))
}

fn ate_within(base: &Row, row: &Row) -> bool {
    match (base.ate_rmse_cm, row.ate_rmse_cm) {
        (Some(a0), Some(a)) => a <= (2.0 * a0).max(a0 + 0.1),
        _ => false,
    }
}

/// Within the campaign's bounds of the fault-free row `base`.
fn within(base: &Row, row: &Row) -> bool {
    let (Some(p0), Some(m0), Some(p), Some(m)) = (base.psnr_db, base.miou, row.psnr_db, row.miou)
    else {
        return false;
    };
    ate_within(base, row) && p >= p0 - 2.0 && m >= m0 - 5.0
}

fn run_case(
    opengs: &Path,
    dir: &Path,
    index: usize,
    frames: usize,
    finish: usize,
    fault: Fault,
) -> anyhow::Result<Row> {
    let run_id = format!("faults{}-{index}", std::process::id());
    let mut child = start_run(
        opengs,
        dir,
        &run_id,
        &[
            "--frames".into(),
            frames.to_string(),
            "--finish-steps".into(),
            finish.to_string(),
        ],
    )?;
    let mut note = String::new();
    let faulted_stage = match fault {
        Fault::None => None,
        Fault::Signal { stage, signal, at } => {
            if wait_for_poses(opengs, &run_id, &mut child, at)? {
                let pid = stage_pid(opengs, &run_id, stage)?;
                // SAFETY: signalling a stage of the run this bench started.
                unsafe { libc::kill(pid, signal) };
            } else {
                note = format!("the run ended before {at} poses");
            }
            Some(stage)
        }
        Fault::KillDuringFinish => {
            if wait_for_poses(opengs, &run_id, &mut child, frames)? {
                std::thread::sleep(Duration::from_secs(3));
                let pid = stage_pid(opengs, &run_id, "mapper")?;
                // SAFETY: as above.
                unsafe { libc::kill(pid, libc::SIGKILL) };
            }
            Some("mapper")
        }
        Fault::KillSupervisor { at } => {
            if wait_for_poses(opengs, &run_id, &mut child, at)? {
                let _ = child.kill();
            }
            None
        }
    };
    let status = wait_timeout(&mut child, Duration::from_secs(600))?;
    let mut row = Row {
        exit: status,
        note,
        ..Row::default()
    };
    if matches!(fault, Fault::KillSupervisor { .. }) {
        // What a user does after a dead supervisor: score what it left, remove its memory.
        let eval = Command::new(opengs).arg("eval").arg(dir).output()?;
        if !eval.status.success() {
            row.note = format!(
                "opengs eval failed: {}",
                String::from_utf8_lossy(&eval.stderr).trim()
            );
        }
        row.exit = Some(0);
    }
    let record = read_json(&dir.join("run.json")).ok();
    if let (Some(r), Some(stage)) = (&record, faulted_stage) {
        let s = r["stages"]
            .as_array()
            .and_then(|a| a.iter().find(|s| s["name"] == stage));
        row.restarts = s.and_then(|s| s["restarts"].as_u64()).unwrap_or(0);
        row.hangs = s.and_then(|s| s["hangs"].as_u64()).unwrap_or(0);
    }
    if let Ok(m) = read_json(&dir.join("metrics.json")) {
        row.poses = m["frames"].as_u64();
        row.lost = m["frames_lost"].as_u64();
        row.ate_rmse_cm = m["ate_rmse_cm"].as_f64();
        row.psnr_db = m["psnr_db"].as_f64();
        row.miou = m["miou"].as_f64();
    }
    Ok(row)
}

/// `opengs run --quiet --run-id RUN_ID --out DIR ARGS...` into a fresh `dir`, its output
/// in `DIR.log`.
pub(super) fn start_run(
    opengs: &Path,
    dir: &Path,
    run_id: &str,
    args: &[String],
) -> anyhow::Result<Child> {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let log_path = dir.with_extension("log");
    let log = std::fs::File::create(&log_path)
        .with_context(|| format!("creating {}", log_path.display()))?;
    Command::new(opengs)
        .args(["run", "--quiet", "--run-id", run_id])
        .args(args)
        .arg("--out")
        .arg(dir)
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .with_context(|| format!("starting {}", opengs.display()))
}

pub(super) fn read_json(path: &Path) -> anyhow::Result<serde_json::Value> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: invalid JSON", path.display()))
}

/// `opengs ctl --run ID status --json`, parsed; None while the run does not answer.
pub(super) fn status(opengs: &Path, run_id: &str) -> Option<serde_json::Value> {
    let out = Command::new(opengs)
        .args(["ctl", "--run", run_id, "status", "--json"])
        .stderr(Stdio::null())
        .output()
        .ok()?;
    serde_json::from_slice(&out.stdout).ok()
}

/// Waits until the run has `n` poses; false when it ended first.
pub(super) fn wait_for_poses(
    opengs: &Path,
    run_id: &str,
    child: &mut Child,
    n: usize,
) -> anyhow::Result<bool> {
    loop {
        if child.try_wait()?.is_some() {
            return Ok(false);
        }
        if status(opengs, run_id)
            .and_then(|s| s["poses"].as_u64())
            .is_some_and(|p| p as usize >= n)
        {
            return Ok(true);
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn stage_pid(opengs: &Path, run_id: &str, stage: &str) -> anyhow::Result<i32> {
    status(opengs, run_id)
        .and_then(|s| {
            s["stages"]
                .as_array()?
                .iter()
                .find(|s| s["name"] == stage)?["pid"]
                .as_u64()
        })
        .map(|p| p as i32)
        .ok_or_else(|| anyhow::anyhow!("no running {stage} in run {run_id}"))
}

/// The exit code (None: killed by a signal), or an error after `limit`.
pub(super) fn wait_timeout(child: &mut Child, limit: Duration) -> anyhow::Result<Option<i32>> {
    let started = Instant::now();
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(status.code());
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            anyhow::bail!("the run did not end within {} s", limit.as_secs());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}
