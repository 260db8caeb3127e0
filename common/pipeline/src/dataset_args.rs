//! Dataset selection on the command line, shared by `opengs run` and the sensor stage.

use std::path::PathBuf;

use opengs_datasets::{DatasetKind, DatasetSpec, DepthNoise};

/// Which dataset to stream and how.
#[derive(clap::Args, Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DatasetArgs {
    /// `synthetic` (the embedded room), `tum:DIR`, `replica:DIR` or `rosbag2:PATH` (a ROS 2
    /// bag directory or .mcap file; MCAP storage).
    #[arg(long, default_value = "synthetic")]
    pub dataset: String,
    /// Use at most N frames (N ≥ 1).
    #[arg(long, value_name = "N", value_parser = parse_at_least_one, allow_hyphen_values = true)]
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
    /// Synthetic only: room of the scene suite. 0 is the fixed 5×4 m room;
    /// any other seed generates a furnished room around the camera path.
    #[arg(long, value_name = "SEED", default_value_t = 0)]
    #[serde(default)]
    pub scene: u64,
    /// Synthetic only: drop this fraction of frames at random (0 ≤ RATE < 1);
    /// dropped frames leave a jump in the timestamps.
    #[arg(long = "drop-frames", value_name = "RATE", default_value_t = 0.0,
          value_parser = parse_drop_rate, allow_hyphen_values = true)]
    #[serde(default)]
    pub drop_frames: f64,
    /// Synthetic only: random drops come in bursts of N consecutive frames (N ≥ 1).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = parse_at_least_one)]
    #[serde(default = "one")]
    pub drop_burst: usize,
    /// Synthetic only: keep every K-th frame of the 30 Hz clock, so the
    /// camera moves K times faster per frame (K ≥ 1).
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = parse_at_least_one)]
    #[serde(default = "one")]
    pub speed: usize,
    /// Synthetic only: skip the first SECONDS of the camera path (the room
    /// is the same as for the whole path).
    #[arg(long, value_name = "SECONDS", default_value_t = 0.0,
          value_parser = parse_start, allow_hyphen_values = true)]
    #[serde(default)]
    pub start: f64,
    /// rosbag2 only: colour topic (sensor_msgs/msg/Image or CompressedImage; default: the
    /// bag's only colour image topic).
    #[arg(long = "rgb-topic", value_name = "TOPIC")]
    #[serde(default)]
    pub rgb_topic: Option<String>,
    /// rosbag2 only: depth topic (sensor_msgs/msg/Image 16UC1 in mm or 32FC1 in m; default:
    /// the bag's only depth image topic).
    #[arg(long = "depth-topic", value_name = "TOPIC")]
    #[serde(default)]
    pub depth_topic: Option<String>,
    /// rosbag2 only: sensor_msgs/msg/CameraInfo topic (default: the only one, or the one
    /// beside the colour topic).
    #[arg(long = "camera-info-topic", value_name = "TOPIC")]
    #[serde(default)]
    pub camera_info_topic: Option<String>,
    /// rosbag2 only: ground-truth camera pose topic (geometry_msgs/msg/PoseStamped or
    /// nav_msgs/msg/Odometry; default: the only one, if any; `none`: no ground truth).
    #[arg(long = "pose-topic", value_name = "TOPIC")]
    #[serde(default)]
    pub pose_topic: Option<String>,
}

fn one() -> usize {
    1
}

/// `--drop-frames`: a fraction in [0, 1).
pub fn parse_drop_rate(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(r) if r.is_finite() && (0.0..1.0).contains(&r) => Ok(r),
        _ => Err(format!(
            "'{s}' is not a drop rate: give a fraction in [0, 1), e.g. 0.1"
        )),
    }
}

/// `--drop-burst`, `--speed`: a whole number ≥ 1.
pub fn parse_at_least_one(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("'{s}' is not a whole number of at least 1")),
    }
}

/// `--start`: seconds ≥ 0.
pub fn parse_start(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(t) if t.is_finite() && t >= 0.0 => Ok(t),
        _ => Err(format!("'{s}' is not a start time: give 0 or more seconds")),
    }
}

impl Default for DatasetArgs {
    fn default() -> Self {
        Self {
            dataset: "synthetic".to_string(),
            frames: None,
            trajectory: None,
            seed: 0,
            noise: false,
            scene: 0,
            drop_frames: 0.0,
            drop_burst: 1,
            speed: 1,
            start: 0.0,
            rgb_topic: None,
            depth_topic: None,
            camera_info_topic: None,
            pose_topic: None,
        }
    }
}

impl DatasetArgs {
    pub fn spec(&self) -> anyhow::Result<DatasetSpec> {
        let kind: DatasetKind = self.dataset.parse()?;
        // run.json's values bypass the flag parsers.
        anyhow::ensure!(self.frames != Some(0), "--frames must be at least 1");
        let mut spec = DatasetSpec::new(kind).with_max_frames(self.frames);
        let synthetic = &mut spec.synthetic;
        synthetic.frames = self.frames;
        synthetic.seed = self.seed;
        synthetic.trajectory = self.trajectory.clone();
        if self.noise {
            synthetic.noise = Some(DepthNoise::default());
        }
        synthetic.scene = self.scene;
        synthetic.drop_rate = self.drop_frames;
        synthetic.drop_burst = self.drop_burst;
        synthetic.speed = self.speed;
        synthetic.start_s = self.start;
        // Values from run.json bypass the flag parsers: check them here too.
        synthetic.validate()?;
        let rosbag2 = &mut spec.rosbag2;
        rosbag2.rgb_topic = self.rgb_topic.clone();
        rosbag2.depth_topic = self.depth_topic.clone();
        rosbag2.camera_info_topic = self.camera_info_topic.clone();
        rosbag2.pose_topic = self.pose_topic.clone();
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
        a.extend(["--scene".to_string(), self.scene.to_string()]);
        // f64 Display is the shortest text that parses back to the same value.
        a.extend(["--drop-frames".to_string(), self.drop_frames.to_string()]);
        a.extend(["--drop-burst".to_string(), self.drop_burst.to_string()]);
        a.extend(["--speed".to_string(), self.speed.to_string()]);
        a.extend(["--start".to_string(), self.start.to_string()]);
        for (flag, topic) in [
            ("--rgb-topic", &self.rgb_topic),
            ("--depth-topic", &self.depth_topic),
            ("--camera-info-topic", &self.camera_info_topic),
            ("--pose-topic", &self.pose_topic),
        ] {
            if let Some(t) = topic {
                // `--flag=VALUE`: a topic is never taken for a flag.
                a.push(format!("{flag}={t}"));
            }
        }
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser, Debug)]
    struct Cli {
        #[command(flatten)]
        dataset: DatasetArgs,
    }

    fn parse(args: &[&str]) -> Result<DatasetArgs, String> {
        Cli::try_parse_from(std::iter::once("opengs").chain(args.iter().copied()))
            .map(|c| c.dataset)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn dataset_args_defaults_match_default() {
        assert_eq!(parse(&[]), Ok(DatasetArgs::default()));
        let spec = DatasetArgs::default().spec().expect("spec");
        assert_eq!(spec.synthetic, opengs_datasets::SyntheticOptions::default());
    }

    #[test]
    fn dataset_args_round_trip_through_to_args() {
        let args = parse(&[
            "--trajectory",
            "fr2_desk.txt",
            "--frames",
            "40",
            "--scene",
            "7",
            "--drop-frames",
            "0.125",
            "--drop-burst",
            "3",
            "--speed",
            "2",
            "--start",
            "31.5",
            "--noise",
            "--rgb-topic",
            "/camera/color/image_raw",
            "--depth-topic",
            "/camera/aligned_depth_to_color/image_raw",
            "--camera-info-topic",
            "/camera/color/camera_info",
            "--pose-topic",
            "none",
        ])
        .expect("valid arguments");
        assert_eq!(
            (
                args.scene,
                args.drop_frames,
                args.drop_burst,
                args.speed,
                args.start
            ),
            (7, 0.125, 3, 2, 31.5)
        );
        let again: Vec<String> = args.to_args();
        let again: Vec<&str> = again.iter().map(String::as_str).collect();
        assert_eq!(parse(&again), Ok(args.clone()));
        let spec = args.spec().expect("spec");
        let s = spec.synthetic;
        assert_eq!(
            (s.scene, s.drop_rate, s.drop_burst, s.speed, s.start_s),
            (7, 0.125, 3, 2, 31.5)
        );
        let b = spec.rosbag2;
        assert_eq!(
            (
                b.rgb_topic.as_deref(),
                b.depth_topic.as_deref(),
                b.camera_info_topic.as_deref(),
                b.pose_topic.as_deref()
            ),
            (
                Some("/camera/color/image_raw"),
                Some("/camera/aligned_depth_to_color/image_raw"),
                Some("/camera/color/camera_info"),
                Some("none")
            )
        );
        // Older run.json files without the new fields still load.
        let json = r#"{"dataset": "synthetic", "frames": null, "trajectory": null, "seed": 3, "noise": false}"#;
        let old: DatasetArgs = serde_json::from_str(json).expect("old run.json");
        assert_eq!(old.seed, 3);
        assert_eq!((old.scene, old.drop_burst, old.speed), (0, 1, 1));
        assert_eq!((old.rgb_topic, old.pose_topic), (None, None));
        let json = serde_json::to_string(&args).expect("json");
        assert_eq!(serde_json::from_str::<DatasetArgs>(&json).ok(), Some(args));
    }

    #[test]
    fn dataset_args_refuse_bad_values_naming_the_flag() {
        for (flag, value) in [
            ("--drop-frames", "1"),
            ("--drop-frames", "-0.1"),
            ("--drop-frames", "lots"),
            ("--drop-burst", "0"),
            ("--speed", "0"),
            ("--start", "-2"),
            ("--start", "NaN"),
        ] {
            let e = parse(&[flag, value]).expect_err("refused");
            assert!(e.contains(flag), "{flag} {value}: {e}");
        }
        let mut args = DatasetArgs {
            speed: 0,
            ..DatasetArgs::default()
        };
        let e = args.spec().expect_err("refused").to_string();
        assert!(e.contains("--speed"), "{e}");
        args.speed = 1;
        args.drop_frames = 2.0;
        let e = args.spec().expect_err("refused").to_string();
        assert!(e.contains("--drop-frames"), "{e}");
    }
}
