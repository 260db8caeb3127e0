//! TUM trajectory files (`timestamp tx ty tz qx qy qz qw`, camera-to-world) as the dataset
//! readers want them: sorted by time, errors as [`DatasetError`]. The parsing and formatting
//! live in `opengs_eval::trajectory`, once.

use std::path::Path;

use opengs_eval::{TimedPose, TrajectoryError};
use opengs_geometry::{format_tum_pose, Pose};

use crate::DatasetError;

/// A timestamped camera-to-world pose.
pub type StampedPose = (f64, Pose);

/// Reads a TUM trajectory, sorted by time; errors name the file and line.
pub fn read_tum_trajectory(path: &Path) -> Result<Vec<StampedPose>, DatasetError> {
    sorted(opengs_eval::read_tum_trajectory(path))
}

/// Parses the text of a TUM trajectory read from `path` (`groundtruth.txt`), sorted by time.
pub fn parse_tum_trajectory(text: &str, path: &Path) -> Result<Vec<StampedPose>, DatasetError> {
    sorted(opengs_eval::parse_tum_trajectory(text, path))
}

/// The eval crate's result as the readers want it: errors as [`DatasetError`], poses sorted.
fn sorted(
    poses: Result<Vec<TimedPose>, TrajectoryError>,
) -> Result<Vec<StampedPose>, DatasetError> {
    let poses = poses.map_err(|e| match e {
        TrajectoryError::Io { path, error } => DatasetError::io(&path, error),
        TrajectoryError::Parse {
            path,
            line,
            message,
        } => DatasetError::parse(&path, line, message),
    })?;
    let mut poses: Vec<StampedPose> = poses.into_iter().map(|p| (p.timestamp, p.pose)).collect();
    poses.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(poses)
}

/// One TUM line, the same formatting as `opengs_eval::format_tum_trajectory`.
pub fn format_tum_line(timestamp: f64, pose: &Pose) -> String {
    format!("{timestamp:.6} {}", format_tum_pose(pose))
}
