//! Consensus stage: one consistent object label per Gaussian from per-frame segmentations.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_pipeline::consensus_stage::{run_consensus, ConsensusArgs};
use opengs_pipeline::stage_main::stage_main;

#[derive(Parser)]
#[command(about = "opengs consensus stage (started by `opengs run`)")]
struct Args {
    /// Run id that namespaces this run's shared-memory services.
    #[arg(long)]
    run_id: String,
    /// Run directory: label_table.json and segments/*.png go here.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    consensus: ConsensusArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    stage_main("consensus", &args.run_id, |ctx| {
        run_consensus(ctx, &args.out, &args.consensus)
    })
}
