//! `opengs eval RUN_DIR`: recompute a run's metrics from its files.

use std::path::PathBuf;

use opengs_eval::RunDir;

#[derive(clap::Args)]
pub struct EvalArgs {
    /// A run directory written by `opengs run` (trajectory.txt, groundtruth.txt).
    pub run_dir: PathBuf,
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
        _ => println!("{} frames; no groundtruth.txt, so no ATE", m.frames),
    }
    println!("wrote {}", RunDir::new(&args.run_dir).metrics().display());
    Ok(())
}
