//! `opengs profile RUN_DIR`: the latency table of a finished run.

use std::path::PathBuf;

use opengs_telemetry::LatencyReport;

#[derive(clap::Args)]
pub struct ProfileArgs {
    /// A run directory written by `opengs run`.
    pub run_dir: PathBuf,
}

pub fn run(args: ProfileArgs) -> anyhow::Result<()> {
    let report = LatencyReport::read(&args.run_dir.join("latency.json"))?;
    print!("{}", report.table());
    Ok(())
}
