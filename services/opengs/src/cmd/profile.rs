//! `opengs profile RUN_DIR`: the latency table of a finished run.

use std::path::PathBuf;

use opengs_eval::RunDir;
use opengs_telemetry::LatencyReport;

#[derive(clap::Args)]
pub struct ProfileArgs {
    /// A run directory written by `opengs run`.
    pub run_dir: PathBuf,
}

pub fn run(args: ProfileArgs) -> anyhow::Result<()> {
    let report = LatencyReport::read(&RunDir::new(&args.run_dir).latency())?;
    print!("{}", report.table());
    Ok(())
}
