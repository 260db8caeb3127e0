//! The run recorder: collects every pose the tracker publishes and writes the trajectory.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

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

    pub fn frames(&self) -> impl Iterator<Item = (&u64, &TrackedFrame)> {
        self.frames.iter()
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
    pub fn write(&self, dir: &Path) -> std::io::Result<()> {
        write_tum(
            &dir.join("trajectory.txt"),
            self.frames.values().map(|f| (f.timestamp, &f.pose)),
        )?;
        if self.frames.values().any(|f| f.gt.is_some()) {
            write_tum(
                &dir.join("groundtruth.txt"),
                self.frames
                    .values()
                    .filter_map(|f| f.gt.as_ref().map(|g| (f.timestamp, g))),
            )?;
        }
        Ok(())
    }
}

fn write_tum<'a>(path: &Path, poses: impl Iterator<Item = (f64, &'a Pose)>) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(out, "# timestamp tx ty tz qx qy qz qw")?;
    for (t, p) in poses {
        let v = p.translation.vector;
        let q = p.rotation.quaternion();
        writeln!(
            out,
            "{t:.6} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}",
            v.x, v.y, v.z, q.i, q.j, q.k, q.w
        )?;
    }
    out.flush()
}
