//! The run recorder: collects every pose the tracker publishes and writes the trajectory.

use std::collections::BTreeMap;
use std::path::Path;

use opengs_eval::{write_tum_trajectory, TimedPose, TrajectoryError};
use opengs_geometry::{pose_from_tum, Pose};
use opengs_ipc_schema::{PoseHeader, PoseStatus};

/// One tracked frame.
#[derive(Debug, Clone)]
pub struct TrackedFrame {
    pub timestamp: f64,
    pub pose: Pose,
    pub gt: Option<Pose>,
    pub status: PoseStatus,
    pub keyframe: bool,
}

/// Poses by frame seq (a restarted tracker may repeat a seq: the latest wins).
#[derive(Default)]
pub struct Recorder {
    frames: BTreeMap<u64, TrackedFrame>,
}

impl Recorder {
    /// Adds a validated pose message.
    pub fn record(&mut self, h: &PoseHeader, status: PoseStatus) {
        let Ok(pose) = pose_from_tum(&h.pose) else {
            tracing::warn!("pose #{} has an invalid rotation; skipped", h.stamp.seq);
            return;
        };
        let gt = if h.has_gt != 0 {
            pose_from_tum(&h.gt_pose).ok()
        } else {
            None
        };
        self.frames.insert(
            h.stamp.seq,
            TrackedFrame {
                timestamp: h.stamp.capture_ns as f64 / 1e9,
                pose,
                gt,
                status,
                keyframe: h.is_keyframe != 0,
            },
        );
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    pub fn keyframes(&self) -> usize {
        self.frames.values().filter(|f| f.keyframe).count()
    }

    pub fn failures(&self) -> usize {
        self.frames
            .values()
            .filter(|f| !matches!(f.status, PoseStatus::Tracked | PoseStatus::Initial))
            .count()
    }

    /// Writes `trajectory.txt` (and `groundtruth.txt` when known) in TUM format.
    pub fn write(&self, dir: &Path) -> Result<(), TrajectoryError> {
        let timed = |pose: &Pose, timestamp: f64| TimedPose {
            timestamp,
            pose: *pose,
        };
        let estimated: Vec<TimedPose> = self
            .frames
            .values()
            .map(|f| timed(&f.pose, f.timestamp))
            .collect();
        write_tum_trajectory(&dir.join("trajectory.txt"), &estimated)?;
        let gt: Vec<TimedPose> = self
            .frames
            .values()
            .filter_map(|f| f.gt.as_ref().map(|g| timed(g, f.timestamp)))
            .collect();
        if !gt.is_empty() {
            write_tum_trajectory(&dir.join("groundtruth.txt"), &gt)?;
        }
        Ok(())
    }
}
