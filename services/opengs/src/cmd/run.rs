//! `opengs run`: the main job.

use std::path::{Path, PathBuf};

use opengs_pipeline::cli_values;
use opengs_pipeline::consensus_stage::{Ablation, ConsensusRunFlags};
use opengs_pipeline::deploy::stage_names;
use opengs_pipeline::mapper_stage::MapperRunFlags;
use opengs_pipeline::segmenter_stage::SegmenterRunFlags;
use opengs_pipeline::tracker_stage::TrackerRunFlags;
use opengs_pipeline::{DatasetArgs, DeployFile, RunOptions, RunSummary, StageFlags};

/// Default replay rate of the synthetic room (frames/s).
const SYNTHETIC_REPLAY_HZ: f64 = 10.0;

/// Final full-resolution mapper steps of `opengs run` (synthetic room, 600 frames: 600 take
/// the map from 25.4 to 28.4 dB PSNR in about a minute on 2 idle cores).
pub const DEFAULT_FINISH_STEPS: usize = 600;

/// Without `--finish-steps`, a run with more keyframes than 600 steps cover at this rate gets
/// this many per keyframe: 600 steps on the 225 keyframes of scene 4's whole fr2_desk loop left
/// it at 26.8 dB; 4 per keyframe (900) reached 28.2, 6 (1350) 29.3, in 1.4× and 2× the time.
pub const DEFAULT_FINISH_STEPS_PER_KEYFRAME: usize = 6;

#[derive(clap::Args, Clone)]
pub struct RunArgs {
    #[command(flatten)]
    pub dataset: DatasetArgs,
    /// Deploy file: a path, or `desktop` / `edge` for the built-in ones.
    #[arg(long, default_value = "desktop")]
    pub deploy: PathBuf,
    /// Run directory (default: runs/<timestamp>/).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Sensor rate cap in frames/s (0 = as fast as possible). Default: as recorded (each
    /// frame its timestamp's step after the previous one, so dropped frames keep their gap);
    /// for the synthetic room 10 Hz, because ray-casting it at 30 Hz takes most of a 2-core
    /// machine and would starve the mapper (a slower replay, like `rosbag play -r`).
    #[arg(long, value_name = "HZ", value_parser = cli_values::rate, allow_hyphen_values = true)]
    pub max_rate: Option<f64>,
    /// Segmenter to start with: geometry (depth-first, no weights), classic (graph-based, no
    /// weights), prior (ground truth), simulated (ground truth with SAM's failure modes: a
    /// reference to measure the consensus), sam, mobilesamv2.
    #[arg(long, value_parser = segmenter_kinds())]
    pub segmenter: Option<String>,
    /// Segmenter processes sharing the keyframes (1-6; default: the deploy file's `replicas`);
    /// `opengs ctl scale segmenter --to N` changes it while the run goes on.
    #[arg(long, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=opengs_pipeline::deploy::MAX_REPLICAS as i64))]
    pub segmenter_replicas: Option<u32>,
    /// Stand-in for a slow segmentation model (to try replicas on a small machine): each
    /// keyframe takes the segmenter at least this many milliseconds, sleeping, whatever its kind.
    #[arg(long, value_name = "MS", default_value_t = 0)]
    pub segmenter_min_call_ms: u64,
    /// Switch a consensus module off (repeatable), as in the paper's ablation table.
    #[arg(long, value_enum)]
    pub ablation: Vec<Ablation>,
    /// Start tracking at the ground-truth first pose instead of the identity.
    #[arg(long)]
    pub gt_first_pose: bool,
    /// Full-resolution optimisation steps (with splitting) the mapper runs on its keyframes
    /// after the end of the data, before it writes map.ply: online it only affords
    /// half-resolution steps. About 0.1 s each at 640×480 on 2 idle cores; 0 skips them; Ctrl-C
    /// during them keeps the map as it is. A number given is the count; the default grows
    /// with long runs. [default: 600, or 6 per kept keyframe past 100 keyframes; 0 in `opengs
    /// ablation`, which scores labels only]
    #[arg(long)]
    pub finish_steps: Option<usize>,
    /// Score rendered views (PSNR/SSIM) against every Nth frame at the end; 0 skips it.
    #[arg(long, default_value_t = 20)]
    pub quality_every: usize,
    /// Keep the tracker's poses. By default, after the final optimisation every pose is
    /// aligned photometrically to the final map (about 0.1 s per frame on 2 cores, reading
    /// the dataset again) and the tracker's poses are kept in trajectory_tracker.txt.
    #[arg(long)]
    pub no_pose_refinement: bool,
    /// No progress bar or progress lines.
    #[arg(long)]
    pub quiet: bool,
    /// Run id namespacing the shared-memory services (default: timestamp and pid).
    #[arg(long)]
    pub run_id: Option<String>,
    /// No end of data (for a service): after the last frame, wait for the frames a recorder
    /// appends to a TUM folder (images first, then their rgb.txt/depth.txt lines) until
    /// `opengs ctl stop` (exit 0) or SIGTERM (exit 130); outputs are rewritten every 5 s.
    /// No final optimisation.
    #[arg(long)]
    pub live: bool,
    #[command(flatten)]
    pub viewer: opengs_pipeline::viewer_args::ViewerArgs,
}

/// The segmenter kinds, for `--help` and for refusing a typo before any process starts.
pub fn segmenter_kinds() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(
        opengs_perception::SegmenterKind::ALL.map(|k| k.as_str()),
    )
}

pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let summary = execute(&args)?;
    print_summary(&summary);
    if summary.interrupted {
        // Outputs are written; the exit status says the run did not reach its end.
        return Err(crate::exit::Interrupted.into());
    }
    Ok(())
}

/// Starts the pipeline as `args` say and waits for it to finish.
pub fn execute(args: &RunArgs) -> anyhow::Result<RunSummary> {
    // --rerun without the viewer stage built: refused before anything else happens.
    args.viewer.check_ready()?;
    // A SIGKILLed supervisor leaves its run's shared memory; no one else would remove it.
    crate::cmd::clean::dead_runs_at_start();
    let mut deploy = DeployFile::load(&args.deploy)?;
    let segmenter_flags = [
        (args.segmenter.is_some(), "--segmenter"),
        (args.segmenter_replicas.is_some(), "--segmenter-replicas"),
        (args.segmenter_min_call_ms > 0, "--segmenter-min-call-ms"),
    ];
    if let Some((_, flag)) = segmenter_flags.iter().find(|(given, _)| *given) {
        let stage = deploy
            .stages
            .iter_mut()
            .find(|s| s.name == stage_names::SEGMENTER)
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "{flag}: deploy file {} has no segmenter stage",
                    args.deploy.display()
                )
            })?;
        if let Some(kind) = &args.segmenter {
            stage.kind = Some(kind.clone());
        }
        if let Some(n) = args.segmenter_replicas {
            stage.replicas = n;
        }
    }
    // Validate the dataset here so a typo fails before any process starts.
    let spec = args.dataset.spec()?;
    opengs_datasets::open_dataset(&spec)?;
    if args.live && !matches!(spec.kind, opengs_datasets::DatasetKind::Tum(_)) {
        eprintln!(
            "--live: {} does not grow; after its last frame the run waits until stopped",
            args.dataset.dataset
        );
    }
    let max_rate = match args.max_rate {
        None if spec.kind == opengs_datasets::DatasetKind::Synthetic => {
            eprintln!(
                "synthetic room replayed at {SYNTHETIC_REPLAY_HZ} Hz (its ray-caster would take \
                 the CPU the mapper needs; --max-rate 30 for real time)"
            );
            Some(SYNTHETIC_REPLAY_HZ)
        }
        other => other,
    };
    let now = chrono::Local::now();
    let run_id = args
        .run_id
        .clone()
        .unwrap_or_else(|| format!("{}-{}", now.format("%Y%m%d-%H%M%S"), std::process::id()));
    let out_dir = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("runs").join(now.format("%Y%m%d-%H%M%S").to_string()));
    let has_stage = |name: &str| deploy.stages.iter().any(|s| s.name == name);
    if !args.ablation.is_empty() && !has_stage(stage_names::CONSENSUS) {
        anyhow::bail!(
            "--ablation: deploy file {} has no consensus stage",
            args.deploy.display()
        );
    }
    let finish_steps = args.finish_steps.unwrap_or(DEFAULT_FINISH_STEPS);
    let mapper = deploy.stages.iter().find(|s| s.name == stage_names::MAPPER);
    // With 0 steps the mapper still gets its finish: it takes the last keyframe's labels.
    let finish_after_data = match mapper {
        Some(m) if m.finish_timeout_s > 0.0 => true,
        Some(_) if finish_steps > 0 => {
            eprintln!(
                "--finish-steps: the mapper in {} has no finish_timeout_s; no final optimisation",
                args.deploy.display()
            );
            false
        }
        _ => false,
    };
    let stage_flags = StageFlags {
        tracker: TrackerRunFlags {
            gt_first_pose: args.gt_first_pose,
        },
        mapper: mapper_flags(args.finish_steps, finish_after_data),
        consensus: ConsensusRunFlags {
            ablation: args.ablation.clone(),
        },
        segmenter: SegmenterRunFlags {
            min_call_ms: args.segmenter_min_call_ms,
        },
        viewer: args.viewer.clone(),
    };
    eprintln!(
        "opengs run {run_id}: dataset {}, deploy {} ({}), output {}",
        args.dataset.dataset,
        args.deploy.display(),
        deploy.description,
        out_dir.display()
    );
    let run_id_for_link = run_id.clone();
    for host in deploy.hosts() {
        eprintln!(
            "stages on host {host}: start them there with `opengs node --deploy {} --host {host} \
             --run-id {run_id}`",
            args.deploy.display()
        );
    }
    opengs_pipeline::run(RunOptions {
        deploy,
        dataset: args.dataset.clone(),
        out_dir: out_dir.clone(),
        run_id,
        max_rate,
        stage_flags,
        progress: !args.quiet,
        quality_every: args.quality_every,
        pose_refinement: !args.no_pose_refinement,
        finish_after_data: finish_after_data && !args.live,
        live: args.live,
        host: None,
        link: run_id_for_link,
    })
}

fn print_summary(s: &RunSummary) {
    // Tracking rate while the data streamed (the mapper's final work and scoring excluded).
    let fps = s.poses as f64 / s.streaming_s.max(1e-9);
    println!(
        "\n{} in {:.1} s ({:.1} s of data): {} frames published, {} poses ({:.1} fps), {} keyframes, {} lost frames",
        if s.interrupted { "interrupted" } else { "finished" },
        s.elapsed_s,
        s.streaming_s,
        s.frames_published,
        s.poses,
        fps,
        s.keyframes,
        s.lost_frames
    );
    if s.lost_frames > 0 {
        println!(
            "tracking was lost on {} frames ({} relocalisations); they are in lost.txt, not in \
             trajectory.txt",
            s.lost_frames, s.relocalisations
        );
        if s.withdrawn > 0 {
            println!(
                "tracking started again soon after its start: {} of them had a pose, given up \
                 with that start and left out of the map (the tracker's log says where)",
                s.withdrawn
            );
        }
    }
    let skipped = s.frames_published.saturating_sub(s.poses as u64);
    if skipped > 0 {
        println!(
            "{skipped} published frames got no pose: the tracker was down, or more than {} \
             frames behind and dropped the oldest (its log names those)",
            opengs_pipeline::frame_backlog::BACKLOG_FRAMES
        );
    }
    let restarts: Vec<String> = s
        .restarts
        .iter()
        .filter(|(_, &r)| r > 0)
        .map(|(n, r)| format!("{n} ×{r}"))
        .collect();
    if !restarts.is_empty() {
        println!("restarts: {}", restarts.join(", "));
    }
    if let Some(r) = &s.pose_refinement {
        println!(
            "poses aligned to the final map: {} of {} accepted, mean correction {:.2} mm {:.3}°, \
             {:.1} s (the tracker's poses are in trajectory_tracker.txt)",
            r.accepted, r.poses, r.mean_translation_mm, r.mean_rotation_deg, r.seconds
        );
    }
    if let Some(m) = &s.scores.metrics {
        if let (Some(rmse), Some(mean)) = (m.ate_rmse_cm, m.ate_mean_cm) {
            print!(
                "ATE (Umeyama, no scale): RMSE {rmse:.3} cm, mean {mean:.3} cm over {} frames",
                m.frames
            );
            match m.ate_rmse_cm_tracker {
                Some(t) => println!(" (the tracker's poses: RMSE {t:.3} cm)"),
                None => println!(),
            }
        }
    }
    if let Some(q) = &s.scores.quality {
        println!(
            "render quality: PSNR {:.2} dB, SSIM {:.3}, holes {:.2} % over {} frames (valid depth only)",
            q.psnr_db, q.ssim, q.holes_pct, q.frames_evaluated
        );
    }
    if let Some(sem) = &s.scores.semantics {
        if let Some(m) = &sem.map {
            print!(
                "labels: mIoU {:.2}, acc {:.2} over {} held-out frames",
                m.miou, m.acc, m.frames
            );
            if let Some(r) = &sem.raw {
                // The per-frame score is the segmenter's own quality; the run-wide matching
                // only scores a segmenter that keeps its ids across frames (as the map does).
                match sem.raw_per_frame_miou {
                    Some(pf) => print!(
                        " (segmenter alone over {} keyframes: mIoU {pf:.2} matched per frame; \
                         {:.2} / acc {:.2} with one matching over the run, as the map)",
                        r.frames, r.miou, r.acc
                    ),
                    None => print!(
                        " (segmenter alone: mIoU {:.2}, acc {:.2} over {} keyframes)",
                        r.miou, r.acc, r.frames
                    ),
                }
            }
            println!(
                "; {} global labels, {} in the map",
                sem.labels, sem.map_labels
            );
        }
    }
    println!("\nper-stage latency:\n{}", s.latency.table());
    if !s.leftover_files.is_empty() {
        println!(
            "warning: {} shared-memory files remain: {:?}",
            s.leftover_files.len(),
            s.leftover_files
        );
    }
    println!("outputs: {}", s.out_dir.display());
}

/// The mapper's final steps: a count given is kept as given; without one, 600 or
/// [`DEFAULT_FINISH_STEPS_PER_KEYFRAME`] per kept keyframe, whichever is more.
fn mapper_flags(finish_steps: Option<usize>, finish_after_data: bool) -> MapperRunFlags {
    if !finish_after_data {
        return MapperRunFlags::default();
    }
    MapperRunFlags {
        finish_steps: finish_steps.unwrap_or(DEFAULT_FINISH_STEPS),
        finish_steps_per_keyframe: match finish_steps {
            None => DEFAULT_FINISH_STEPS_PER_KEYFRAME,
            Some(_) => 0,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_default_final_steps_grow_with_the_keyframes() {
        let default = mapper_flags(None, true);
        assert_eq!(
            default.to_args(),
            ["--finish-steps", "600", "--finish-steps-per-keyframe", "6"]
        );
        assert_eq!(
            mapper_flags(Some(600), true).to_args(),
            ["--finish-steps", "600"]
        );
        assert!(mapper_flags(Some(0), true).to_args().is_empty());
        assert!(mapper_flags(None, false).to_args().is_empty());
    }
}
