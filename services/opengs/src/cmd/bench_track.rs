//! `opengs bench track`: the tracker alone over a dataset, frame by frame, on one thread
//! (as the tracker stage runs): per-frame time percentiles, the frames that ran the wide
//! search (after a gap, or when the fast registration failed or slid) and what they cost,
//! lost frames and the error against the ground truth. The pipeline's tracker p99 includes
//! queueing behind a slow frame; this is the work itself.

use std::time::Instant;

use anyhow::Context;
use hdrhistogram::Histogram;
use opengs_datasets::open_dataset;
use opengs_pipeline::DatasetArgs;
use opengs_tracking::{DepthFrame, FrameTracker, TrackerConfig};

#[derive(clap::Args)]
pub struct BenchTrackArgs {
    #[command(flatten)]
    dataset: DatasetArgs,
    /// Threads of the tracker's pool (the tracker stage runs one).
    #[arg(long, default_value_t = 1, value_parser = opengs_pipeline::cli_values::at_least_one)]
    threads: usize,
    /// Print every frame slower than this (ms), with its status, the iterations of its fine
    /// registration, why the wide search ran and why a frame got no pose (0: every frame).
    #[arg(long, default_value_t = 50.0)]
    slow_ms: f64,
    /// Write one line per frame to this file (tab-separated: frame, timestamp, status, ms,
    /// fine iterations, position error in cm against the ground truth, why the wide search ran).
    #[arg(long)]
    frames_out: Option<std::path::PathBuf>,
}

struct Frame {
    timestamp: f64,
    depth: Vec<u16>,
    depth_scale: f64,
    gt: Option<opengs_geometry::Pose>,
}

pub fn run(args: BenchTrackArgs) -> anyhow::Result<()> {
    let spec = args.dataset.spec()?;
    let mut source = open_dataset(&spec).context("opening the dataset")?;
    let k = source.intrinsics();
    let n = source.len();
    // Decoded up front: only tracking is timed.
    let mut frames = Vec::with_capacity(n);
    for i in 0..n {
        let f = source.frame(i).with_context(|| format!("frame {i}"))?;
        frames.push(Frame {
            timestamp: f.timestamp,
            depth: f.depth,
            depth_scale: f64::from(f.depth_scale),
            gt: f.gt_pose,
        });
    }
    println!("{}: {n} frames, {}×{}", source.name(), k.width, k.height);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()?;
    // As the tracker stage: models are built and relocalisation guesses tried on threads
    // of their own.
    let mut tracker = FrameTracker::threaded(TrackerConfig::for_width(k.width))?;
    let mut all = Histogram::<u64>::new_with_bounds(1, 600_000_000, 3)?;
    let mut wide = Histogram::<u64>::new_with_bounds(1, 600_000_000, 3)?;
    // Each frame's pose, if it has one, and its squared position error (`None` without
    // ground truth).
    let mut posed: Vec<Option<Option<f64>>> = Vec::with_capacity(n);
    let mut starts_again = 0usize;
    // Iterations of each registered frame's last (fine) registration: what a frame's time
    // is made of, between the fine search's cost per iteration and the count.
    let mut iterations: Vec<usize> = Vec::with_capacity(n);
    let mut lines =
        String::from("frame\ttimestamp\tstatus\tms\titerations\terror_cm\twide_search\n");
    for (i, f) in frames.iter().enumerate() {
        // A start (and a start again) is at the truth: the error needs no alignment.
        if let Some(gt) = f.gt {
            tracker.set_first_pose(gt);
        }
        let frame = DepthFrame {
            depth: &f.depth,
            depth_scale: f.depth_scale,
            intrinsics: &k,
            timestamp: f.timestamp,
        };
        let start = Instant::now();
        let out = pool.install(|| tracker.track(&frame));
        let us = start.elapsed().as_micros() as u64;
        all.saturating_record(us);
        if out.wide_search.is_some() {
            wide.saturating_record(us);
        }
        let ms = us as f64 / 1e3;
        if out.iterations > 0 {
            iterations.push(out.iterations);
        }
        if ms > args.slow_ms && out.started_again.is_none() {
            println!(
                "  frame {i:5} ({:.3} s): {ms:6.1} ms  {:?}, {} iterations{}{}",
                f.timestamp,
                out.status,
                out.iterations,
                out.wide_search
                    .as_deref()
                    .map_or(String::new(), |w| format!(", wide search: {w}")),
                out.failure
                    .as_deref()
                    .map_or(String::new(), |why| format!(": {why}"))
            );
        }
        if let Some(again) = &out.started_again {
            // The frames since the start given up have no pose any more (frame indices are the
            // tracker's count).
            starts_again += 1;
            let from = usize::try_from(again.given_up).unwrap_or(usize::MAX);
            for p in posed.iter_mut().skip(from) {
                *p = None;
            }
            println!(
                "  frame {i:5} ({:.3} s): {ms:6.1} ms  tracking starts again ({}); frames {}–{} have no pose",
                f.timestamp,
                again.why,
                again.given_up,
                i.saturating_sub(1)
            );
        }
        let error_cm =
            f.gt.map(|gt| (out.pose.translation.vector - gt.translation.vector).norm() * 100.0);
        lines.push_str(&format!(
            "{i}\t{:.6}\t{:?}\t{ms:.2}\t{}\t{}\t{}\n",
            f.timestamp,
            out.status,
            out.iterations,
            error_cm.map_or("".into(), |e| format!("{e:.4}")),
            out.wide_search.as_deref().unwrap_or("")
        ));
        posed.push(
            out.status
                .has_pose()
                .then(|| error_cm.map(|e| (e / 100.0).powi(2))),
        );
    }
    let lost = posed.iter().filter(|p| p.is_none()).count();
    let sq_errors: Vec<f64> = posed.iter().flatten().flatten().copied().collect();
    let scored = sq_errors.len();
    let sq_err: f64 = sq_errors.iter().sum();
    let q = |h: &Histogram<u64>, p: f64| h.value_at_quantile(p) as f64 / 1e3;
    println!(
        "per frame: p50 {:.1} ms, p90 {:.1} ms, p99 {:.1} ms, max {:.1} ms ({} frames, {} thread(s))",
        q(&all, 0.5),
        q(&all, 0.9),
        q(&all, 0.99),
        all.max() as f64 / 1e3,
        all.len(),
        args.threads
    );
    if !wide.is_empty() {
        println!(
            "wide search: {} frames, median {:.1} ms, max {:.1} ms",
            wide.len(),
            q(&wide, 0.5),
            wide.max() as f64 / 1e3
        );
    }
    iterations.sort_unstable();
    if let Some(&max) = iterations.last() {
        let at = |p: f64| iterations[((iterations.len() - 1) as f64 * p).round() as usize];
        println!(
            "fine iterations per registered frame: median {}, p90 {}, max {} ({} frames)",
            at(0.5),
            at(0.9),
            max,
            iterations.len()
        );
    }
    if let Some(path) = &args.frames_out {
        std::fs::write(path, &lines).with_context(|| format!("writing {}", path.display()))?;
    }
    let rmse = (scored > 0).then(|| (sq_err / scored as f64).sqrt() * 100.0);
    println!(
        "lost {lost} of {n}{}; position error RMSE {} (no alignment: a start's pose is the truth)",
        match starts_again {
            0 => String::new(),
            r => format!(" (tracking started again {r} time(s))"),
        },
        rmse.map_or("n/a (no ground truth)".into(), |e| format!("{e:.3} cm"))
    );
    Ok(())
}
