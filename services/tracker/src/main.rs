//! Tracker stage: G-ICP of every frame against the model; poses and keyframes out.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_pipeline::tracker_stage::{run_tracker, TrackerArgs};
use opengs_runtime::RunContext;

#[derive(Parser)]
#[command(about = "opengs tracker stage (started by `opengs run`)")]
struct Args {
    /// Run id that namespaces this run's shared-memory services.
    #[arg(long)]
    run_id: String,
    /// Run directory (unused by the tracker; every stage accepts it).
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    tracker: TrackerArgs,
}

fn main() -> ExitCode {
    opengs_pipeline::logging::init("info");
    let args = Args::parse();
    let result = RunContext::new(&args.run_id)
        .map_err(anyhow::Error::from)
        .and_then(|ctx| run_tracker(&ctx, &args.tracker));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("tracker: {e:#}");
            ExitCode::FAILURE
        }
    }
}
