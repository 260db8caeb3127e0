//! `opengs eval RUN_DIR`: recompute a run's metrics from its files.

use std::path::PathBuf;

use opengs_eval::RunDir;

#[derive(clap::Args)]
pub struct EvalArgs {
    /// A run directory written by `opengs run` (trajectory.txt, groundtruth.txt).
    pub run_dir: PathBuf,
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
    println!("wrote {}", RunDir::new(&args.run_dir).metrics().display());
    Ok(())
}
