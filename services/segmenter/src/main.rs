//! Segmenter stage: label maps with confidences and classes for the newest keyframe (no other
//! replica has taken).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_pipeline::segmenter_stage::{run_segmenter, SegmenterArgs};
use opengs_pipeline::stage_main::stage_main;

#[derive(Parser)]
#[command(about = "opengs segmenter stage (started by `opengs run`; swapped by `opengs ctl swap`)")]
struct Args {
    /// Run id that namespaces this run's shared-memory services.
    #[arg(long)]
    run_id: String,
    /// Run directory: replicas of the stage claim keyframes there, so each is segmented once.
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    segmenter: SegmenterArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    stage_main("segmenter", &args.run_id, |ctx| {
        run_segmenter(ctx, args.out.as_deref(), &args.segmenter)
    })
}
