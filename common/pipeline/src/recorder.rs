//! The run recorder: collects every pose the tracker publishes and writes the trajectory
//! (verified poses only) and the lost frames.

use std::collections::BTreeMap;
use std::path::Path;

use opengs_eval::RunDir;
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

    /// What a restarted tracker goes on from: the verified keyframe poses, then the last
    /// verified pose (empty before the first).
    pub fn resume_poses(&self) -> Vec<TimedPose> {
        let verified = || self.frames.values().filter(|f| f.status.has_pose());
        let mut poses: Vec<TimedPose> = verified()
            .filter(|f| f.keyframe)
            .map(|f| TimedPose {
                timestamp: f.timestamp,
                pose: f.pose,
            })
            .collect();
        if let Some(last) = verified().next_back() {
            poses.push(TimedPose {
                timestamp: last.timestamp,
                pose: last.pose,
            });
        }
        poses
    }

    pub fn keyframes(&self) -> usize {
        self.frames.values().filter(|f| f.keyframe).count()
    }

    /// Frames whose pose was not verified (the tracker was lost, or had no depth).
    pub fn lost(&self) -> usize {
        self.frames
            .values()
            .filter(|f| !f.status.has_pose())
            .count()
    }

    /// Frames where tracking resumed after lost frames.
    pub fn relocalised(&self) -> usize {
        self.frames
            .values()
            .filter(|f| f.status == PoseStatus::Relocalised)
            .count()
    }

    /// Writes `trajectory.txt` (verified poses) and `groundtruth.txt` (every frame, when
    /// known) in TUM format, and `lost.txt` (the frames without a verified pose).
    pub fn write(&self, dir: &Path) -> Result<(), TrajectoryError> {
        let timed = |pose: &Pose, timestamp: f64| TimedPose {
            timestamp,
            pose: *pose,
        };
        let estimated: Vec<TimedPose> = self
            .frames
            .values()
            .filter(|f| f.status.has_pose())
            .map(|f| timed(&f.pose, f.timestamp))
            .collect();
        let run = RunDir::new(dir);
        write_tum_trajectory(&run.trajectory(), &estimated)?;
        let lost_path = run.lost();
        let mut lost = String::from("# frames without a verified pose: timestamp seq status\n");
        for (seq, f) in self.frames.iter().filter(|(_, f)| !f.status.has_pose()) {
            lost.push_str(&format!("{:.6} {seq} {:?}\n", f.timestamp, f.status));
        }
        opengs_eval::write_atomically(&lost_path, lost.as_bytes()).map_err(|error| {
            TrajectoryError::Io {
                path: lost_path,
                error,
            }
        })?;
        let gt: Vec<TimedPose> = self
            .frames
            .values()
            .filter_map(|f| f.gt.as_ref().map(|g| timed(g, f.timestamp)))
            .collect();
        if !gt.is_empty() {
            write_tum_trajectory(&run.groundtruth(), &gt)?;
        }
        Ok(())
    }
}
