//! `opengs bench WHAT`: benchmarks that print figures (medians; machines are noisy).

use clap::{Args, Subcommand};

#[derive(Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    what: BenchWhat,
}

#[derive(Subcommand)]
enum BenchWhat {
    /// One-way shared-memory latency of RGB-D frames, publisher → woken subscriber process.
    Ipc(super::bench_ipc::BenchIpcArgs),
    /// Render speed of the GS Voting rasterizer (colour+depth vs +labels+top-K).
    Render(super::bench_render::BenchRenderArgs),
    /// G-ICP registration time and tracker throughput.
    Gicp(super::bench_gicp::BenchGicpArgs),
}

pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    match args.what {
        BenchWhat::Ipc(a) => super::bench_ipc::run(a),
        BenchWhat::Render(a) => super::bench_render::run(a),
        BenchWhat::Gicp(a) => super::bench_gicp::run(a),
    }
}
