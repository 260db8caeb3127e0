//! Mapper stage: densify and optimise the Gaussian map; feed the tracker.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_pipeline::mapper_stage::{run_mapper, MapperArgs};
use opengs_runtime::RunContext;

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
    opengs_pipeline::logging::init("info");
    let args = Args::parse();
    let result = RunContext::new(&args.run_id)
        .map_err(anyhow::Error::from)
        .and_then(|ctx| run_mapper(&ctx, &args.out, &args.mapper));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("mapper: {e:#}");
            ExitCode::FAILURE
        }
    }
}
