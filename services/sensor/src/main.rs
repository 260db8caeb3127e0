//! Sensor stage: streams a dataset's RGB-D frames into shared memory.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_pipeline::sensor::{run_sensor, SensorArgs};
use opengs_pipeline::stage_main::stage_main;

#[derive(Parser)]
#[command(about = "opengs sensor stage (started by `opengs run`)")]
struct Args {
    /// Run id that namespaces this run's shared-memory services.
    #[arg(long)]
    run_id: String,
    /// Run directory (unused by the sensor; every stage accepts it).
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    sensor: SensorArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    stage_main("sensor", &args.run_id, |ctx| run_sensor(ctx, &args.sensor))
}
