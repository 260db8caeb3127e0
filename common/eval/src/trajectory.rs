//! Trajectories in TUM format: `timestamp tx ty tz qx qy qz qw` per line,
//! `#` comments, poses camera-to-world.

use opengs_geometry::{format_tum_pose, pose_from_tum, Pose};
use std::path::{Path, PathBuf};

/// One pose of a trajectory with its capture time (seconds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedPose {
    pub timestamp: f64,
    pub pose: Pose,
}

/// A trajectory file that could not be read or written; names the file and line.
#[derive(Debug, thiserror::Error)]
pub enum TrajectoryError {
    // The I/O error is part of the message (not a `source`) so it prints once.
    #[error("{path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },
}

/// Parses TUM trajectory text; `path` only names the source in errors.
pub fn parse_tum_trajectory(text: &str, path: &Path) -> Result<Vec<TimedPose>, TrajectoryError> {
    let error = |line: usize, message: String| TrajectoryError::Parse {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut poses = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let content = line.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let fields: Vec<&str> = content.split_whitespace().collect();
        if fields.len() != 8 {
            return Err(error(
                i + 1,
                format!(
                    "expected 8 numbers (timestamp tx ty tz qx qy qz qw), found {}",
                    fields.len()
                ),
            ));
        }
        let mut values = [0.0; 8];
        for (v, field) in values.iter_mut().zip(&fields) {
            *v = field
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| error(i + 1, format!("'{field}' is not a finite number")))?;
        }
        let mut tum = [0.0; 7];
        tum.copy_from_slice(&values[1..]);
        let pose = pose_from_tum(&tum).map_err(|e| error(i + 1, e.to_string()))?;
        poses.push(TimedPose {
            timestamp: values[0],
            pose,
        });
    }
    Ok(poses)
}

pub fn read_tum_trajectory(path: &Path) -> Result<Vec<TimedPose>, TrajectoryError> {
    let text = std::fs::read_to_string(path).map_err(|error| TrajectoryError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    parse_tum_trajectory(&text, path)
}

/// TUM text with a header comment, one pose per line.
pub fn format_tum_trajectory(poses: &[TimedPose]) -> String {
    let mut text = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for p in poses {
        text.push_str(&format!(
            "{:.6} {}\n",
            p.timestamp,
            format_tum_pose(&p.pose)
        ));
    }
    text
}

pub fn write_tum_trajectory(path: &Path, poses: &[TimedPose]) -> Result<(), TrajectoryError> {
    crate::write_atomically(path, format_tum_trajectory(poses).as_bytes()).map_err(|error| {
        TrajectoryError::Io {
            path: path.to_path_buf(),
            error,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn round_trip_through_text() {
        let text = "# comment\n1.5 1 2 3 0 0 0 1\n\n2.0 0 0 1 0 0 0.7071068 0.7071068 # turned\n";
        let poses = parse_tum_trajectory(text, Path::new("t.txt")).expect("valid");
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].timestamp, 1.5);
        let back = parse_tum_trajectory(&format_tum_trajectory(&poses), Path::new("t.txt"))
            .expect("valid");
        for (a, b) in poses.iter().zip(&back) {
            assert_relative_eq!(
                a.pose.to_homogeneous(),
                b.pose.to_homogeneous(),
                epsilon = 1e-6
            );
        }
    }

    #[test]
    fn errors_name_file_and_line() {
        let e = parse_tum_trajectory("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n", Path::new("gt.txt"))
            .expect_err("7 numbers")
            .to_string();
        assert_eq!(
            e,
            "gt.txt:2: expected 8 numbers (timestamp tx ty tz qx qy qz qw), found 7"
        );
        let e = parse_tum_trajectory("# x\n1 0 0 zero 0 0 0 1\n", Path::new("gt.txt"))
            .expect_err("bad number")
            .to_string();
        assert_eq!(e, "gt.txt:2: 'zero' is not a finite number");
        let e = parse_tum_trajectory("1 0 0 0 0 0 0 0\n", Path::new("gt.txt"))
            .expect_err("zero quaternion");
        assert!(e.to_string().starts_with("gt.txt:1: "), "{e}");
    }
}
