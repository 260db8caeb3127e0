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
    /// The SLAM scene suite through the real pipeline: generated rooms × camera paths ×
    /// noise; ATE, PSNR, holes, mIoU, lost frames, tracker p99 per case and the worst row.
    Slam(super::bench_slam::BenchSlamArgs),
    /// The fault campaign: each stage SIGKILLed (early, mid-run, the mapper in its final
    /// optimisation) and SIGSTOPped, the supervisor SIGKILLed; every run against the
    /// fault-free one (ATE, PSNR, mIoU, poses, restarts, hangs).
    Faults(super::bench_faults::BenchFaultsArgs),
    /// Segmenter replicas with a segmenter held to a fixed time per keyframe: keyframes
    /// segmented with 1, 2, 4 replicas, mIoU, and `ctl scale` during a run (the gap it leaves).
    Replicas(super::bench_replicas::BenchReplicasArgs),
    /// What a Zenoh link between hosts adds to one-way latency (640×480 RGB-D frame, label
    /// map), against iceoryx2 alone, in one run (needs `opengs-bridge`: feature
    /// opengs-bridge/zenoh).
    Bridge(super::bench_bridge::BenchBridgeArgs),
    /// G-ICP registration time and tracker throughput.
    Gicp(super::bench_gicp::BenchGicpArgs),
    /// The tracker alone over a dataset, one frame at a time: per-frame time percentiles,
    /// the wide-search frames and their cost, lost frames, position error.
    Track(super::bench_track::BenchTrackArgs),
    /// One mapping step (forward + backward + Adam) with 100k Gaussians at 640×480 and
    /// 320×240; with `--run DIR`, the rates the mapper sustained in that run.
    Map(super::bench_map::BenchMapArgs),
    /// Label consensus per 640×480 keyframe with ~100 input and ~100 rendered labels (one core).
    Consensus {
        /// Timed keyframes.
        #[arg(long, default_value_t = 50)]
        runs: usize,
    },
    /// Segmenters per 640×480 synthetic frame: geometry, classic, prior, and with `onnx` both
    /// SAM paths (grid points, proposed boxes; without and with the tagger/detector) on the tiny
    /// fixture models, split into model time and our own.
    Segment {
        /// Frames to segment.
        #[arg(long, default_value_t = 8)]
        frames: usize,
        /// Repeats per frame.
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        /// SAM grid path: prompts on an N×N point grid (default: the segmenter's default).
        #[arg(long)]
        points_per_side: Option<u32>,
        /// Instead of timing alone: per-frame quality against the ground-truth instances
        /// (Hungarian mIoU, split and merge shares, ms per frame) of geometry, classic, prior and
        /// simulated.
        #[arg(long)]
        quality: bool,
        /// With --quality: room of the scene suite (0 = the fixed room).
        #[arg(long, default_value_t = 0)]
        scene: u64,
        /// With --quality: the frames to score, `synthetic` or any dataset with instance
        /// labels (`tum:DIR` with a labels/ folder, as `opengs bench slam` writes them).
        #[arg(long, default_value = "synthetic")]
        dataset: String,
        /// With --quality, synthetic only: Kinect-like depth noise and missing depth, as a
        /// real sensor gives.
        #[arg(long)]
        noise: bool,
    },
}

pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    match args.what {
        BenchWhat::Ipc(a) => super::bench_ipc::run(a),
        BenchWhat::Render(a) => super::bench_render::run(a),
        BenchWhat::Gicp(a) => super::bench_gicp::run(a),
        BenchWhat::Track(a) => super::bench_track::run(a),
        BenchWhat::Slam(a) => super::bench_slam::run(a),
        BenchWhat::Faults(a) => super::bench_faults::run(a),
        BenchWhat::Replicas(a) => super::bench_replicas::run(a),
        BenchWhat::Bridge(a) => super::bench_bridge::run(a),
        BenchWhat::Map(a) => super::bench_map::run(a),
        BenchWhat::Consensus { runs } => {
            opengs_semantics::bench::print_consensus_bench(runs);
            Ok(())
        }
        BenchWhat::Segment {
            frames,
            repeats,
            points_per_side,
            quality: false,
            ..
        } => Ok(opengs_perception::bench::print_segment_bench_with(
            frames,
            repeats,
            points_per_side,
        )?),
        BenchWhat::Segment {
            frames,
            quality: true,
            scene,
            dataset,
            noise,
            ..
        } => {
            let spec = opengs_pipeline::DatasetArgs {
                dataset,
                scene,
                noise,
                ..Default::default()
            }
            .spec()?;
            Ok(opengs_perception::bench::print_segment_quality(
                frames, &spec,
            )?)
        }
    }
}
