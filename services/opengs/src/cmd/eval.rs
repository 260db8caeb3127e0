//! `opengs eval RUN_DIR`: recompute a run's metrics from its files.

use std::path::PathBuf;

use anyhow::Context;
use opengs_eval::RunDir;

#[derive(clap::Args)]
pub struct EvalArgs {
    /// A run directory written by `opengs run` (trajectory.txt, groundtruth.txt).
    pub run_dir: PathBuf,
    /// Also score the map again: rendered views (PSNR, SSIM, holes) and labels (mIoU, acc)
    /// against the run's dataset (run.json's, or --dataset), as `opengs run` does at its end.
    #[arg(long)]
    pub scores: bool,
    /// With --scores: score every Nth frame.
    #[arg(long, default_value_t = 20, value_parser = opengs_pipeline::cli_values::at_least_one)]
    pub every: usize,
    /// With --scores: the dataset to score against, instead of run.json's
    /// (`synthetic`, `tum:DIR`, `replica:DIR`, `rosbag2:PATH`).
    #[arg(long)]
    pub dataset: Option<String>,
}

/// `ate_rmse_cm` of the run's metrics.json, if it holds a number.
fn kept_ate_rmse(run: &RunDir) -> Option<f64> {
    let text = std::fs::read_to_string(run.metrics()).ok()?;
    let json: serde_json::Value = serde_json::from_str(&text).ok()?;
    json.get("ate_rmse_cm")?.as_f64()
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let m = opengs_quality::evaluate_run_trajectory(&args.run_dir)?;
    match (m.ate_rmse_cm, m.ate_mean_cm, m.ate_max_cm) {
        (Some(rmse), Some(mean), Some(max)) => {
            println!("frames        {}", m.frames);
            println!("ate_rmse_cm   {rmse:.4}");
            println!("ate_mean_cm   {mean:.4}");
            println!("ate_max_cm    {max:.4}");
        }
        _ => {
            let run = RunDir::new(&args.run_dir);
            println!(
                "{} frames; no {}, so no ATE computed",
                m.frames,
                run.groundtruth().display()
            );
            if let Some(rmse) = kept_ate_rmse(&run) {
                println!("metrics.json keeps its earlier ate_rmse_cm {rmse:.4}");
            }
        }
    }
    if args.scores {
        rescore(&args)?;
    }
    println!("wrote {}", RunDir::new(&args.run_dir).metrics().display());
    Ok(())
}

/// Render quality and labels of the run's map against its dataset.
fn rescore(args: &EvalArgs) -> anyhow::Result<()> {
    let dataset = super::refine::dataset_args(&args.run_dir, args.dataset.as_deref())?;
    let spec = dataset.spec()?;
    let mut source = opengs_datasets::open_dataset(&spec)
        .with_context(|| format!("opening the dataset {}", dataset.dataset))?;
    let q = opengs_quality::evaluate_run_quality(&args.run_dir, source.as_mut(), args.every)?;
    println!(
        "render quality: PSNR {:.2} dB, SSIM {:.3}, holes {:.2} % over {} frames (valid depth only)",
        q.psnr_db, q.ssim, q.holes_pct, q.frames_evaluated
    );
    let s = opengs_quality::evaluate_run_semantics(&args.run_dir, source.as_mut(), args.every)?;
    match &s.map {
        Some(m) => println!(
            "labels: mIoU {:.2}, acc {:.2} over {} held-out frames; {} global labels, {} in the map",
            m.miou, m.acc, m.frames, s.labels, s.map_labels
        ),
        None => println!("labels: the dataset has no instance labels"),
    }
    Ok(())
}
