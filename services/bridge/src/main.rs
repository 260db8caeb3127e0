//! Bridge stage: services of this host's run to and from other hosts, over Zenoh.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_bridge::link::{Link, LinkArgs};
use opengs_pipeline::stage_main::stage_main;

#[derive(Parser)]
#[command(about = "opengs bridge stage: carries services between hosts over Zenoh")]
struct Args {
    /// Run id that namespaces this host's shared-memory services.
    #[arg(long)]
    run_id: String,
    /// Run directory (unused by the bridge; every stage accepts it).
    #[arg(long)]
    out: Option<PathBuf>,
    /// The stage's name in the deploy file (its telemetry says it): each host's bridge has
    /// its own.
    #[arg(long, default_value = "bridge")]
    name: String,
    #[command(flatten)]
    link: LinkArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    stage_main(&args.name, &args.run_id, |ctx| {
        let link = Link::plan(&args.run_id, &args.link).map_err(anyhow::Error::msg)?;
        opengs_bridge::zenoh_link::run_bridge(ctx, &link, &args.name)
    })
}
