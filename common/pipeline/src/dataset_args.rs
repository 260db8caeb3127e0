//! Dataset selection on the command line, shared by `opengs run` and the sensor stage.

use std::path::PathBuf;

use opengs_datasets::{DatasetKind, DatasetSpec, DepthNoise};

/// Which dataset to stream and how.
#[derive(clap::Args, Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct DatasetArgs {
    /// `synthetic` (the embedded room), `tum:DIR` or `replica:DIR`.
    #[arg(long, default_value = "synthetic")]
    pub dataset: String,
    /// Use at most N frames.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Synthetic only: drive the camera along this TUM trajectory file.
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    /// Synthetic only: random seed (scene noise, generated path).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Synthetic only: add Kinect-like depth noise and missing depth.
    #[arg(long)]
    pub noise: bool,
}

impl DatasetArgs {
    pub fn spec(&self) -> anyhow::Result<DatasetSpec> {
        let kind: DatasetKind = self.dataset.parse()?;
        let mut spec = DatasetSpec::new(kind).with_max_frames(self.frames);
        spec.synthetic.frames = self.frames;
        spec.synthetic.seed = self.seed;
        spec.synthetic.trajectory = self.trajectory.clone();
        if self.noise {
            spec.synthetic.noise = Some(DepthNoise::default());
        }
        Ok(spec)
    }

    /// The same selection as command-line arguments, for a child process.
    pub fn to_args(&self) -> Vec<String> {
        let mut a = vec!["--dataset".to_string(), self.dataset.clone()];
        if let Some(n) = self.frames {
            a.extend(["--frames".to_string(), n.to_string()]);
        }
        if let Some(t) = &self.trajectory {
            a.extend(["--trajectory".to_string(), t.display().to_string()]);
        }
        a.extend(["--seed".to_string(), self.seed.to_string()]);
        if self.noise {
            a.push("--noise".to_string());
        }
        a
    }
}
