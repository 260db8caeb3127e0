//! `opengs refine RUN_DIR`: keep optimising a finished run's map offline on its keyframes,
//! and report render quality (PSNR / SSIM, docs/METHOD.md §9) before and after.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use opengs_datasets::open_dataset;
use opengs_eval::read_tum_trajectory;
use opengs_eval::RunDir;
use opengs_mapping::{refine, RefineConfig};
use opengs_pipeline::cli_values::{at_least_one, positive_f32};
use opengs_pipeline::{DatasetArgs, RunRecord};
use opengs_quality::{
    evaluate_dataset_quality, load_posed_frames, merge_metrics_json, write_quality_metrics,
    write_report_json, QualityReport,
};
use opengs_splat::write_ply_file;

use crate::cmd::map_input::load_map;

#[derive(Debug, clap::Args)]
pub struct RefineArgs {
    /// A run directory written by `opengs run` (map.ply, trajectory.txt, run.json).
    pub run_dir: PathBuf,
    /// Optimisation steps (≥ 1).
    #[arg(long, default_value_t = 1000, value_parser = at_least_one)]
    pub iters: usize,
    /// Train on every Nth trajectory frame, N ≥ 1 [default: 5].
    #[arg(long, value_name = "N", value_parser = at_least_one)]
    pub every: Option<usize>,
    /// Evaluate PSNR / SSIM on every Nth trajectory frame (N ≥ 1), counted from halfway
    /// between the first two training frames: with N a multiple of the training stride no
    /// evaluated frame was trained on.
    #[arg(long, value_name = "N", default_value_t = 5, value_parser = at_least_one)]
    pub eval_every: usize,
    /// Keep at most this many keyframes in memory (`--every` is raised to fit; ≥ 1).
    #[arg(long, default_value_t = 300, value_parser = at_least_one)]
    pub max_keyframes: usize,
    /// Optimise at half resolution (4× cheaper per step, as the online mapper does, but
    /// detail finer than two pixels stays blurred).
    #[arg(long)]
    pub half_resolution: bool,
    /// Seed of the keyframe order.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Smallest scene extent (m) for the position learning rate and size pruning; the
    /// extent is otherwise 1.1 × the radius of the keyframe camera centres.
    #[arg(long, default_value_t = 1.0, value_parser = positive_f32)]
    pub min_scene_extent: f32,
    /// Map to refine [default: RUN_DIR/map.ply].
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Dataset (`synthetic`, `tum:DIR`, `replica:DIR`, `rosbag2:PATH`) when run.json does not
    /// name it.
    #[arg(long)]
    pub dataset: Option<String>,
    /// Refuse a map with NaN or infinite values instead of leaving those Gaussians out.
    #[arg(long)]
    pub strict: bool,
    /// Times the keyframe poses are aligned photometrically to the map being refined,
    /// evenly spread over the steps (0: never; the mapper's final optimisation does 1).
    #[arg(long, default_value_t = 1)]
    pub pose_rounds: usize,
}

pub fn run(args: RefineArgs) -> anyhow::Result<()> {
    let dir = &args.run_dir;
    anyhow::ensure!(
        dir.is_dir(),
        "{}: not a run directory (expected the output directory of `opengs run`)",
        dir.display()
    );
    let dataset = dataset_args(dir, args.dataset.as_deref())?;
    let run = RunDir::new(dir);
    let map_path = args.map.clone().unwrap_or_else(|| run.map());
    let mut map = load_map(&map_path, args.strict)?;
    anyhow::ensure!(!map.is_empty(), "{}: the map is empty", map_path.display());
    let trajectory = read_tum_trajectory(&run.trajectory())?;
    anyhow::ensure!(
        !trajectory.is_empty(),
        "{}: no poses",
        run.trajectory().display()
    );
    let spec = dataset.spec()?;
    let mut source =
        open_dataset(&spec).with_context(|| format!("opening dataset '{}'", dataset.dataset))?;
    let intrinsics = source.intrinsics();

    println!(
        "map {} ({} Gaussians), {} poses, dataset {}",
        map_path.display(),
        map.len(),
        trajectory.len(),
        source.name()
    );
    let every = keyframe_stride(
        trajectory.len(),
        args.every.unwrap_or(5),
        args.max_keyframes,
    );
    let eval = HeldOut::new(trajectory.len(), every, args.eval_every);
    println!("{eval}");
    let eval_poses = &trajectory[eval.offset..];
    let before = evaluate_dataset_quality(
        &map,
        source.as_mut(),
        eval_poses,
        args.eval_every,
        Some(&run.renders_dir()),
    )
    .context("evaluating the map before refinement")?;
    print_quality("before", &before);

    let (mut keyframes, unmatched) =
        load_posed_frames(source.as_mut(), &trajectory, every).context("loading keyframes")?;
    if unmatched > 0 {
        eprintln!("{unmatched} trajectory poses match no dataset frame within 1 ms; skipped");
    }
    println!(
        "refining on {} keyframes (one pose in {every}), {} iterations at {} resolution",
        keyframes.len(),
        args.iters,
        if args.half_resolution { "half" } else { "full" }
    );
    let config = RefineConfig {
        iters: args.iters,
        downscale: args.half_resolution,
        seed: args.seed,
        min_scene_extent: args.min_scene_extent,
        pose_rounds: args.pose_rounds,
        ..RefineConfig::default()
    };
    let bar = progress_bar(args.iters)?;
    // Ctrl-C ends the refinement early; what it has done is evaluated and saved.
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop))?;
    }
    let stats = refine(&mut map, &mut keyframes, intrinsics, &config, |i, loss| {
        bar.set_position(i as u64);
        if i % 10 == 0 {
            bar.set_message(format!("loss {loss:.4}"));
        }
        if stop.load(Ordering::Relaxed) {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })
    .context("refining")?;
    bar.finish_and_clear();
    if stats.iterations < args.iters {
        println!(
            "interrupted after {} of {} iterations; saving what is done",
            stats.iterations, args.iters
        );
    }
    println!(
        "refined in {:.1} s: loss {:.4} → {:.4}, scene extent {:.2} m, {} → {} Gaussians",
        stats.seconds,
        stats.first_loss,
        stats.last_loss,
        stats.scene_extent,
        stats.gaussians_before,
        stats.gaussians_after
    );
    println!("  {}", stats.step_ms);
    if stats.poses.refined > 0 {
        println!("  {}", stats.poses);
    }
    drop(keyframes);

    let after = evaluate_dataset_quality(
        &map,
        source.as_mut(),
        eval_poses,
        args.eval_every,
        Some(&dir.join("renders_refined")),
    )
    .context("evaluating the refined map")?;
    print_quality("after", &after);

    let out = run.map_refined();
    write_ply_file(&map, &out).with_context(|| format!("writing {}", out.display()))?;
    write_report_json(&run.quality_refined(), &after)?;
    write_quality_metrics(dir, &after, "_refined")?;
    let mut extra = serde_json::Map::new();
    extra.insert("refine_iters".into(), stats.iterations.into());
    extra.insert("refine_keyframes".into(), stats.keyframes.into());
    // The unrefined map scored on the same frames, so before/after compare like for like.
    extra.insert("psnr_db_before_refine".into(), before.psnr_db.into());
    extra.insert("ssim_before_refine".into(), before.ssim.into());
    merge_metrics_json(&run.metrics(), extra)?;
    println!(
        "PSNR {:.2} → {:.2} dB, SSIM {:.4} → {:.4}",
        before.psnr_db, after.psnr_db, before.ssim, after.ssim
    );
    println!("wrote {}", out.display());
    println!("wrote {}", run.quality_refined().display());
    println!("wrote {}", run.metrics().display());
    for p in before.pngs.iter().chain(&after.pngs) {
        println!("wrote {}", p.display());
    }
    Ok(())
}

/// The run's dataset selection: run.json's `dataset_args`, or `--dataset` when given.
pub(crate) fn dataset_args(
    run_dir: &Path,
    dataset_override: Option<&str>,
) -> anyhow::Result<DatasetArgs> {
    let run = RunDir::new(run_dir);
    let saved = RunRecord::read(&run)?.map(|r| r.dataset_args);
    match (saved, dataset_override) {
        (Some(mut a), Some(d)) => {
            a.dataset = d.to_string();
            Ok(a)
        }
        (Some(a), None) => Ok(a),
        (None, Some(d)) => Ok(DatasetArgs {
            dataset: d.to_string(),
            ..DatasetArgs::default()
        }),
        (None, None) => anyhow::bail!(
            "{}: no run record; pass --dataset synthetic|tum:DIR|replica:DIR|rosbag2:PATH",
            run.run_record().display()
        ),
    }
}

/// The evaluated frames: every `eval_every`-th trajectory pose from `offset`, half a
/// training stride in, so a refinement is scored on views it did not train on (trained
/// on every fifth frame and scored on the same ones, scene 4's fr2_desk read 29.80 dB).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct HeldOut {
    offset: usize,
    eval_every: usize,
    frames: usize,
    /// Of those, the frames also trained on.
    trained: usize,
}

impl HeldOut {
    fn new(poses: usize, train_every: usize, eval_every: usize) -> Self {
        let (train_every, eval_every) = (train_every.max(1), eval_every.max(1));
        let offset = (train_every / 2).min(poses.saturating_sub(1));
        let evaluated = (offset..poses).step_by(eval_every);
        Self {
            offset,
            eval_every,
            frames: evaluated.clone().count(),
            trained: evaluated.filter(|i| i % train_every == 0).count(),
        }
    }
}

impl std::fmt::Display for HeldOut {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "scoring {} frames (one pose in {} from pose {})",
            self.frames, self.eval_every, self.offset
        )?;
        match self.trained {
            0 => write!(f, ", none of them trained on"),
            n => write!(
                f,
                ", {n} of them also trained on (an --eval-every that is a multiple of \
                 --every holds them all out)"
            ),
        }
    }
}

/// `every`, raised so that at most `max_keyframes` of `poses` are used.
fn keyframe_stride(poses: usize, every: usize, max_keyframes: usize) -> usize {
    every.max(1).max(poses.div_ceil(max_keyframes.max(1)))
}

fn progress_bar(iters: usize) -> anyhow::Result<ProgressBar> {
    let bar = ProgressBar::new(iters as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "refine [{bar:40}] {pos}/{len} its ({per_sec}, eta {eta}) {msg}",
        )
        .context("progress bar template")?
        .progress_chars("=> "),
    );
    Ok(bar)
}

fn print_quality(when: &str, r: &QualityReport) {
    println!(
        "{when}: PSNR {:.2} dB, SSIM {:.4} over {} frames (pixels without depth masked)",
        r.psnr_db, r.ssim, r.frames_evaluated
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evaluated_frames_sit_between_the_training_frames() {
        // Trained on 0, 5, 10, …; scored on 2, 7, 12, …: none trained on.
        let held = HeldOut::new(600, 5, 5);
        assert_eq!((held.offset, held.frames, held.trained), (2, 120, 0));
        // Trained on every 10th, scored on every 20th from 5: 30 frames.
        assert_eq!(HeldOut::new(600, 10, 20).frames, 30);
        assert_eq!(HeldOut::new(600, 10, 20).trained, 0);
        // Scored on every 7th from 2 (2, 9, 16, 23, 30, …): 30 and 65 are trained on too.
        let mixed = HeldOut::new(100, 5, 7);
        assert_eq!((mixed.frames, mixed.trained), (14, 2), "{mixed:?}");
        assert!(
            mixed.to_string().contains("2 of them also trained on"),
            "{mixed}"
        );
        // Training on every pose leaves nothing out, and says so.
        let all = HeldOut::new(10, 1, 1);
        assert_eq!((all.offset, all.frames, all.trained), (0, 10, 10));
        // A one-pose trajectory is still scored.
        assert_eq!(HeldOut::new(1, 5, 5).frames, 1);
    }

    #[test]
    fn stride_respects_the_keyframe_cap() {
        assert_eq!(keyframe_stride(600, 5, 300), 5);
        assert_eq!(keyframe_stride(2000, 5, 300), 7);
        assert_eq!(keyframe_stride(10, 0, 300), 1);
    }
}
