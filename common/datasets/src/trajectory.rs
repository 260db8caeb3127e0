//! TUM trajectory files: `timestamp tx ty tz qx qy qz qw`, camera-to-world.

use std::io::Write;
use std::path::Path;

use opengs_geometry::{format_tum_pose, pose_from_tum, Pose};

use crate::text::{data_lines, parse_numbers};
use crate::DatasetError;

/// A timestamped camera-to-world pose.
pub type StampedPose = (f64, Pose);

/// Reads a TUM trajectory, sorted by time; errors name the file and line.
pub fn read_tum_trajectory(path: &Path) -> Result<Vec<StampedPose>, DatasetError> {
    let mut poses = Vec::new();
    for (line_no, line) in data_lines(path)? {
        let v = parse_numbers(path, line_no, &line)?;
        if v.len() != 8 {
            return Err(DatasetError::parse(
                path,
                line_no,
                format!(
                    "expected 8 numbers (timestamp tx ty tz qx qy qz qw), found {}",
                    v.len()
                ),
            ));
        }
        let pose = pose_from_tum(&[v[1], v[2], v[3], v[4], v[5], v[6], v[7]])
            .map_err(|e| DatasetError::parse(path, line_no, e.to_string()))?;
        poses.push((v[0], pose));
    }
    poses.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(poses)
}

/// Formats a pose line with enough digits to round-trip within 1e-9.
pub fn format_tum_line(timestamp: f64, pose: &Pose) -> String {
    format!("{timestamp:.6} {}", format_tum_pose(pose))
}

/// Writes a TUM trajectory file.
pub fn write_tum_trajectory(path: &Path, poses: &[StampedPose]) -> Result<(), DatasetError> {
    let mut text = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for (t, p) in poses {
        text.push_str(&format_tum_line(*t, p));
        text.push('\n');
    }
    let mut f = std::fs::File::create(path).map_err(|e| DatasetError::io(path, e))?;
    f.write_all(text.as_bytes())
        .map_err(|e| DatasetError::io(path, e))
}
