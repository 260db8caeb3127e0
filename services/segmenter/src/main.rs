//! Segmenter stage: label maps with confidences and classes for the newest keyframe.

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
    /// Run directory (unused by the segmenter; every stage accepts it).
    #[arg(long)]
    out: Option<PathBuf>,
    /// sam (and mobilesamv2 without --proposals): decoder prompts on an N×N point grid per
    /// keyframe (default 16, i.e. 256 decoder runs; SAM's own default is 32).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    points_per_side: Option<u32>,
    #[command(flatten)]
    segmenter: SegmenterArgs,
}

/// Read by opengs-perception's `AmgParams::default()` (the pipeline builds the segmenter from
/// options that carry no AMG settings), so the flag reaches it through the environment.
const POINTS_PER_SIDE_ENV: &str = "OPENGS_SAM_POINTS_PER_SIDE";

fn main() -> ExitCode {
    let args = Args::parse();
    if let Some(n) = args.points_per_side {
        std::env::set_var(POINTS_PER_SIDE_ENV, n.to_string());
    }
    stage_main("segmenter", &args.run_id, |ctx| {
        run_segmenter(ctx, &args.segmenter)
    })
}
