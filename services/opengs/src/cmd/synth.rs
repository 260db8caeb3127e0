//! `opengs synth`: write the synthetic room as a TUM or Replica dataset, or a ROS 2 bag.

use std::path::PathBuf;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use opengs_datasets::replica::REPLICA_DEPTH_SCALE;
use opengs_datasets::rosbag2::MM_DEPTH_SCALE;
use opengs_datasets::tum::TUM_DEPTH_SCALE;
use opengs_datasets::{
    write_dataset, DatasetFormat, DepthNoise, RgbdSource, SyntheticOptions, SyntheticSource,
};
use opengs_pipeline::dataset_args::{parse_at_least_one, parse_drop_rate, parse_start};

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SynthFormat {
    /// rgb/, depth/, labels/ + rgb.txt, depth.txt, groundtruth.txt (depth scale 5000)
    Tum,
    /// results/frame%06d.jpg, depth%06d.png, label%06d.png + traj.txt (depth scale 6553.5)
    Replica,
    /// ROS 2 bag directory: metadata.yaml + DIR_0.mcap (zstd chunks) with rgb8 Image,
    /// 16UC1 depth (mm), CameraInfo and PoseStamped ground truth (no labels)
    Rosbag2,
}

#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Dataset layout to write.
    #[arg(long, value_enum, default_value_t = SynthFormat::Tum)]
    pub format: SynthFormat,
    /// Number of frames, N ≥ 1 (default: one 20 s loop, or the whole trajectory).
    #[arg(long, value_name = "N", value_parser = parse_at_least_one, allow_hyphen_values = true)]
    pub frames: Option<usize>,
    /// Drive the camera along this TUM trajectory (re-centred into the fixed
    /// room; a generated room is fitted around it).
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    /// Seed of the camera path jitter and the depth noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Add Kinect-like depth noise and dropouts.
    #[arg(long)]
    pub noise: bool,
    /// Room of the scene suite: 0 is the fixed 5×4 m room; any other seed
    /// generates a furnished room around the camera path.
    #[arg(long, value_name = "SEED", default_value_t = 0)]
    pub scene: u64,
    /// Drop this fraction of frames at random (0 ≤ RATE < 1); dropped frames
    /// leave a jump in the timestamps.
    #[arg(long = "drop-frames", value_name = "RATE", default_value_t = 0.0,
          value_parser = parse_drop_rate, allow_hyphen_values = true)]
    pub drop_frames: f64,
    /// Random drops come in bursts of N consecutive frames (N ≥ 1).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = parse_at_least_one)]
    pub drop_burst: usize,
    /// Keep every K-th frame of the 30 Hz clock, so the camera moves K times
    /// faster per frame (K ≥ 1).
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = parse_at_least_one)]
    pub speed: usize,
    /// Skip the first SECONDS of the camera path (the room is the same as
    /// for the whole path).
    #[arg(long, value_name = "SECONDS", default_value_t = 0.0, value_parser = parse_start, allow_hyphen_values = true)]
    pub start: f64,
}

pub fn run(args: SynthArgs) -> anyhow::Result<()> {
    let (format, depth_scale) = match args.format {
        SynthFormat::Tum => (DatasetFormat::Tum, TUM_DEPTH_SCALE),
        SynthFormat::Replica => (DatasetFormat::Replica, REPLICA_DEPTH_SCALE),
        SynthFormat::Rosbag2 => (DatasetFormat::Rosbag2, MM_DEPTH_SCALE),
    };
    let options = SyntheticOptions {
        frames: args.frames,
        seed: args.seed,
        noise: args.noise.then(DepthNoise::default),
        trajectory: args.trajectory.clone(),
        // Render in the target format's units so depth is written unchanged.
        depth_scale,
        scene: args.scene,
        drop_rate: args.drop_frames,
        drop_burst: args.drop_burst,
        speed: args.speed,
        start_s: args.start,
        ..SyntheticOptions::default()
    };
    let mut source = SyntheticSource::new(options).context("setting up the synthetic room")?;
    print_summary(&source);
    let bar = ProgressBar::new(source.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} frames ({per_sec}, eta {eta})")
            .context("progress bar template")?
            .progress_chars("=> "),
    );
    bar.set_message(format!("writing {format} dataset"));
    write_dataset(&mut source, &args.out, format, &mut |done, _total| {
        bar.set_position(done as u64)
    })
    .with_context(|| format!("writing {}", args.out.display()))?;
    bar.finish_with_message(format!(
        "wrote {} frames to {}",
        source.len(),
        args.out.display()
    ));
    Ok(())
}

/// Room size, object count, and for a path with drops the dropped frames and the long gaps.
fn print_summary(source: &SyntheticSource) {
    let scene = source.scene();
    let size = scene.room_size();
    println!(
        "scene {}: room {:.2} × {:.2} × {:.2} m, {} objects, {} frames",
        source.options().scene,
        size.x,
        size.y,
        size.z,
        scene.object_count(),
        source.len()
    );
    let dropped = source.dropped_frames();
    if source.options().trajectory.is_none() && dropped == 0 {
        return;
    }
    let long: Vec<String> = source
        .gaps()
        .iter()
        .filter(|g| g.missing_s > 1.0)
        .map(|g| {
            format!(
                "{:.1} s before frame {} (t = {:.1} s)",
                g.missing_s, g.frame, g.time_s
            )
        })
        .collect();
    println!(
        "{dropped} dropped frames; gaps over 1 s: {}",
        if long.is_empty() {
            "none".to_string()
        } else {
            long.join(", ")
        }
    );
}
