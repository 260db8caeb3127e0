//! `opengs-viewer`: the Rerun viewer stage, started by `opengs run --rerun FILE.rrd` or
//! `--rerun-connect ADDR` (built only with `--features opengs-viewer/rerun`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_pipeline::stage_main::stage_main;
use opengs_pipeline::viewer_args::ViewerArgs;
use opengs_viewer::rerun_sink::RerunSink;
use opengs_viewer::stage::{run_viewer, STAGE};

#[derive(Parser)]
#[command(
    about = "opengs Rerun viewer stage (started by `opengs run --rerun` / `--rerun-connect`)"
)]
struct Args {
    /// Run id that namespaces this run's shared-memory services (also the recording id).
    #[arg(long)]
    run_id: String,
    /// Run directory (unused by the viewer; every stage accepts it).
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    viewer: ViewerArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    stage_main(STAGE, &args.run_id, |ctx| {
        let sink = RerunSink::new(&args.run_id, &args.viewer)?;
        run_viewer(ctx, sink)
    })
}
