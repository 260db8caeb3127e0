//! `opengs synth`: write the synthetic room as a TUM or Replica dataset.

use std::path::PathBuf;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use opengs_datasets::replica::REPLICA_DEPTH_SCALE;
use opengs_datasets::tum::TUM_DEPTH_SCALE;
use opengs_datasets::{
    write_dataset, DatasetFormat, DepthNoise, RgbdSource, SyntheticOptions, SyntheticSource,
};

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SynthFormat {
    /// rgb/, depth/, labels/ + rgb.txt, depth.txt, groundtruth.txt (depth scale 5000)
    Tum,
    /// results/frame%06d.jpg, depth%06d.png, label%06d.png + traj.txt (depth scale 6553.5)
    Replica,
}

#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Dataset layout to write.
    #[arg(long, value_enum, default_value_t = SynthFormat::Tum)]
    pub format: SynthFormat,
    /// Number of frames (default: one 20 s loop, or the whole trajectory).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Drive the camera along this TUM trajectory (re-centred into the room).
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    /// Seed of the camera path jitter and the depth noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Add Kinect-like depth noise and dropouts.
    #[arg(long)]
    pub noise: bool,
}

pub fn run(args: SynthArgs) -> anyhow::Result<()> {
    let (format, depth_scale) = match args.format {
        SynthFormat::Tum => (DatasetFormat::Tum, TUM_DEPTH_SCALE),
        SynthFormat::Replica => (DatasetFormat::Replica, REPLICA_DEPTH_SCALE),
    };
    let options = SyntheticOptions {
        frames: args.frames,
        seed: args.seed,
        noise: args.noise.then(DepthNoise::default),
        trajectory: args.trajectory.clone(),
        // Render in the target format's units so depth is written unchanged.
        depth_scale,
        ..SyntheticOptions::default()
    };
    let mut source = SyntheticSource::new(options).context("setting up the synthetic room")?;
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
