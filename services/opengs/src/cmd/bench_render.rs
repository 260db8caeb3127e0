//! `opengs bench render`: the renderer benchmark (median ms per frame) on synthetic scenes.

use anyhow::Context;
use opengs_pipeline::cli_values::at_least_one;
use opengs_splat::args;
use opengs_splat::bench::{run_render_bench, BenchConfig};

#[derive(Debug, clap::Args)]
pub struct BenchRenderArgs {
    /// Scene sizes (number of Gaussians), comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = [100_000usize, 500_000], value_parser = at_least_one)]
    pub gaussians: Vec<usize>,
    /// Image sizes, comma-separated WxH (focal 525 at 640 wide, scaled; centred principal point).
    #[arg(long, value_parser = args::parse_size, value_delimiter = ',', default_values = ["640x480", "1200x680"])]
    pub sizes: Vec<(u32, u32)>,
    /// Timed frames per case (median reported). The four requests (colour+depth, +labels+top-K,
    /// +labels only, +top-K only) render each frame in turn, so the overhead column is the
    /// median of per-frame ratios and a busy machine slows all columns alike.
    #[arg(long, default_value_t = 9, value_parser = at_least_one)]
    pub frames: usize,
    /// Renders of each frame per request, the fastest kept: steadier figures on a shared
    /// machine (slow spells only ever add time). Try 5 when comparing two builds.
    #[arg(long, default_value_t = 1, value_parser = at_least_one)]
    pub repeat: usize,
    /// Worker threads (default: all cores). 1 shows the per-core cost without scheduling.
    #[arg(long, value_parser = at_least_one)]
    pub threads: Option<usize>,
    /// K of the per-pixel top-K.
    #[arg(long, default_value_t = 50, value_parser = at_least_one)]
    pub top_k: usize,
    /// Also print project / bin+sort / rasterize times of one (b) frame per case.
    #[arg(long)]
    pub breakdown: bool,
}

pub fn run(args: BenchRenderArgs) -> anyhow::Result<()> {
    for &(w, h) in &args.sizes {
        args::check_render_size(w, h, Some(args.top_k))
            .map_err(anyhow::Error::msg)
            .context("--sizes")?;
    }
    let cfg = BenchConfig {
        gaussian_counts: args.gaussians,
        intrinsics: args
            .sizes
            .iter()
            .map(|&(w, h)| opengs_splat::bench::intrinsics_for_size(w, h))
            .collect(),
        frames: args.frames,
        repeat: args.repeat,
        top_k: args.top_k,
        breakdown: args.breakdown,
    };
    let report = match args.threads {
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .context("cannot start the worker threads")?
            .install(|| run_render_bench(&cfg)),
        None => run_render_bench(&cfg),
    };
    print!("{report}");
    Ok(())
}
