//! Tracker stage: G-ICP of every frame against the model; poses and keyframes out.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_pipeline::stage_main::stage_main;
use opengs_pipeline::tracker_stage::{run_tracker, TrackerArgs};

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
    let args = Args::parse();
    stage_main("tracker", &args.run_id, |ctx| {
        run_tracker(ctx, &args.tracker)
    })
}
