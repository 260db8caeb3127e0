//! Mapper stage: densify and optimise the Gaussian map; feed the tracker.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_pipeline::mapper_stage::{run_mapper, MapperArgs};
use opengs_pipeline::stage_main::stage_main;

#[derive(Parser)]
#[command(about = "opengs mapper stage (started by `opengs run`)")]
struct Args {
    /// Run id that namespaces this run's shared-memory services.
    #[arg(long)]
    run_id: String,
    /// Run directory: checkpoints, map.ply and mapper.json go here.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    mapper: MapperArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    stage_main("mapper", &args.run_id, |ctx| {
        run_mapper(ctx, &args.out, &args.mapper)
    })
}
