//! The run recorder: collects every pose the tracker publishes and appends the trajectory
//! (verified poses only), the ground truth and the lost frames to the run directory.
//!
//! A run may last days (`opengs run --live`), so neither memory nor a snapshot's cost may
//! grow with its length: only the newest [`SETTLE_AFTER`] seqs are held (a restarted or
//! swapped-in tracker may repeat one of them: the latest wins); older ones are settled,
//! appended to the files and fsynced at each snapshot, and counted. What a restarted tracker
//! needs (the verified keyframe poses) is kept apart, one pose per keyframe.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use opengs_eval::RunDir;
use opengs_eval::{TimedPose, TrajectoryError};
use opengs_geometry::{format_tum_pose, pose_from_tum, Pose};
use opengs_ipc_schema::{PoseHeader, PoseStatus};

/// Seqs behind the newest that may still change; older ones are written for good.
pub const SETTLE_AFTER: u64 = 64;

/// One tracked frame.
#[derive(Debug, Clone)]
pub struct TrackedFrame {
    pub timestamp: f64,
    pub pose: Pose,
    pub gt: Option<Pose>,
    pub status: PoseStatus,
    pub keyframe: bool,
}

/// Counts over frames.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
struct Counts {
    frames: usize,
    keyframes: usize,
    lost: usize,
    relocalised: usize,
}

impl Counts {
    fn add(&mut self, f: &TrackedFrame) {
        self.frames += 1;
        self.keyframes += usize::from(f.keyframe);
        self.lost += usize::from(!f.status.has_pose());
        self.relocalised += usize::from(f.status == PoseStatus::Relocalised);
    }
}

/// The three files settled frames are appended to, created (emptied) at the first write.
struct Files {
    dir: PathBuf,
    trajectory: File,
    groundtruth: Option<File>,
    lost: File,
}

impl Files {
    fn create(dir: &Path) -> Result<Self, TrajectoryError> {
        let run = RunDir::new(dir);
        let create = |path: PathBuf, header: &str| {
            File::create(&path)
                .and_then(|mut f| f.write_all(header.as_bytes()).map(|()| f))
                .map_err(|error| TrajectoryError::Io { path, error })
        };
        // A ground truth an earlier run left in the same directory is not this run's.
        let _ = std::fs::remove_file(run.groundtruth());
        Ok(Self {
            dir: dir.to_path_buf(),
            trajectory: create(run.trajectory(), TUM_HEADER)?,
            groundtruth: None,
            lost: create(
                run.lost(),
                "# frames without a verified pose: timestamp seq status\n",
            )?,
        })
    }

    fn append(&mut self, frames: &[(u64, TrackedFrame)]) -> Result<(), TrajectoryError> {
        let run = RunDir::new(&self.dir);
        let (mut trajectory, mut groundtruth, mut lost) =
            (String::new(), String::new(), String::new());
        for (seq, f) in frames {
            if f.status.has_pose() {
                trajectory.push_str(&tum_line(f.timestamp, &f.pose));
            } else {
                lost.push_str(&format!("{:.6} {seq} {:?}\n", f.timestamp, f.status));
            }
            if let Some(gt) = &f.gt {
                groundtruth.push_str(&tum_line(f.timestamp, gt));
            }
        }
        if !groundtruth.is_empty() && self.groundtruth.is_none() {
            let path = run.groundtruth();
            let mut file = File::create(&path).map_err(|error| TrajectoryError::Io {
                path: path.clone(),
                error,
            })?;
            file.write_all(TUM_HEADER.as_bytes())
                .map_err(|error| TrajectoryError::Io { path, error })?;
            self.groundtruth = Some(file);
        }
        // The trajectory last: a process killed between two writes leaves no pose on disk
        // without its ground truth (`opengs eval` of such a directory found 0 poses to score).
        let targets = [
            (self.groundtruth.as_mut(), groundtruth, run.groundtruth()),
            (Some(&mut self.lost), lost, run.lost()),
            (Some(&mut self.trajectory), trajectory, run.trajectory()),
        ];
        for (file, text, path) in targets {
            let Some(file) = file else { continue };
            // One write per file and snapshot: whole lines, then on disk.
            file.write_all(text.as_bytes())
                .and_then(|()| file.sync_data())
                .map_err(|error| TrajectoryError::Io { path, error })?;
        }
        Ok(())
    }
}

const TUM_HEADER: &str = "# timestamp tx ty tz qx qy qz qw\n";

fn tum_line(timestamp: f64, pose: &Pose) -> String {
    format!("{timestamp:.6} {}\n", format_tum_pose(pose))
}

/// Poses by frame seq: the newest in memory, the rest on disk.
pub struct Recorder {
    dir: PathBuf,
    /// Frames that may still be replaced.
    recent: BTreeMap<u64, TrackedFrame>,
    /// Every seq up to here is settled (written, counted).
    settled_through: Option<u64>,
    settled: Counts,
    /// Verified keyframe poses (settled and recent), for a restarted tracker.
    keyframe_poses: BTreeMap<u64, TimedPose>,
    /// The newest settled verified pose.
    last_settled_verified: Option<TimedPose>,
    /// Verified poses published again as lost: the tracker started again and gave up the
    /// start they belonged to.
    withdrawn: usize,
    files: Option<Files>,
}

impl Recorder {
    /// A recorder that writes to the run directory `dir` (its files are created, emptied,
    /// at the first snapshot).
    pub fn new(dir: &Path) -> Self {
        Self {
            dir: dir.to_path_buf(),
            recent: BTreeMap::new(),
            settled_through: None,
            settled: Counts::default(),
            keyframe_poses: BTreeMap::new(),
            last_settled_verified: None,
            withdrawn: 0,
            files: None,
        }
    }

    /// Adds a validated pose message.
    pub fn record(&mut self, h: &PoseHeader, status: PoseStatus) {
        let seq = h.stamp.seq;
        if self.settled_through.is_some_and(|s| seq <= s) {
            tracing::warn!("pose #{seq} arrived after its frame was written; ignored");
            return;
        }
        let Ok(pose) = pose_from_tum(&h.pose) else {
            tracing::warn!("pose #{seq} has an invalid rotation; skipped");
            return;
        };
        let gt = if h.has_gt != 0 {
            pose_from_tum(&h.gt_pose).ok()
        } else {
            None
        };
        let frame = TrackedFrame {
            timestamp: h.stamp.capture_ns as f64 / 1e9,
            pose,
            gt,
            status,
            keyframe: h.is_keyframe != 0,
        };
        if frame.keyframe && status.has_pose() {
            self.keyframe_poses.insert(
                seq,
                TimedPose {
                    timestamp: frame.timestamp,
                    pose,
                },
            );
        } else {
            // A repeated seq that is no longer a verified keyframe.
            self.keyframe_poses.remove(&seq);
        }
        if self
            .recent
            .insert(seq, frame)
            .is_some_and(|before| before.status.has_pose() && status == PoseStatus::Lost)
        {
            self.withdrawn += 1;
        }
    }

    fn counts(&self) -> Counts {
        let mut c = self.settled;
        for f in self.recent.values() {
            c.add(f);
        }
        c
    }

    pub fn len(&self) -> usize {
        self.counts().frames
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// What a restarted tracker goes on from: the verified keyframe poses, then the last
    /// verified pose (empty before the first).
    pub fn resume_poses(&self) -> Vec<TimedPose> {
        let mut poses: Vec<TimedPose> = self.keyframe_poses.values().copied().collect();
        let last = self
            .recent
            .values()
            .rev()
            .find(|f| f.status.has_pose())
            .map(|f| TimedPose {
                timestamp: f.timestamp,
                pose: f.pose,
            })
            .or(self.last_settled_verified);
        poses.extend(last);
        poses
    }

    pub fn keyframes(&self) -> usize {
        self.counts().keyframes
    }

    /// Frames whose pose was not verified (the tracker was lost, or had no depth).
    pub fn lost(&self) -> usize {
        self.counts().lost
    }

    /// Frames where tracking resumed after lost frames.
    pub fn relocalised(&self) -> usize {
        self.counts().relocalised
    }

    /// Frames whose verified pose was published again as lost (counted in [`Self::lost`]):
    /// the tracker started again and gave up the start they were tracked from.
    pub fn withdrawn(&self) -> usize {
        self.withdrawn
    }

    /// Appends the frames more than [`SETTLE_AFTER`] seqs behind the newest to
    /// `trajectory.txt` (verified poses), `groundtruth.txt` (when known; both TUM format)
    /// and `lost.txt` (frames without a verified pose), and fsyncs them: a snapshot.
    pub fn write(&mut self) -> Result<(), TrajectoryError> {
        let newest = self.recent.keys().next_back().copied();
        let through = newest.and_then(|n| n.checked_sub(SETTLE_AFTER));
        self.settle(through)
    }

    /// Writes every frame: the end of the run.
    pub fn finish(&mut self) -> Result<(), TrajectoryError> {
        let newest = self.recent.keys().next_back().copied();
        self.settle(newest)
    }

    fn settle(&mut self, through: Option<u64>) -> Result<(), TrajectoryError> {
        if self.files.is_none() {
            self.files = Some(Files::create(&self.dir)?);
        }
        let Some(through) = through else {
            return Ok(());
        };
        let keep = self.recent.split_off(&(through + 1));
        let settling: Vec<(u64, TrackedFrame)> = std::mem::replace(&mut self.recent, keep)
            .into_iter()
            .collect();
        if settling.is_empty() {
            return Ok(());
        }
        let written = match self.files.as_mut() {
            Some(files) => files.append(&settling),
            None => Ok(()),
        };
        for (_, f) in &settling {
            self.settled.add(f);
            if f.status.has_pose() {
                self.last_settled_verified = Some(TimedPose {
                    timestamp: f.timestamp,
                    pose: f.pose,
                });
            }
        }
        self.settled_through = Some(through.max(self.settled_through.unwrap_or(0)));
        written
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opengs_eval::read_tum_trajectory;
    use opengs_ipc_schema::{MessageKind, Stamp};

    fn pose_msg(seq: u64, x: f64, keyframe: bool) -> PoseHeader {
        PoseHeader {
            stamp: Stamp::new(MessageKind::Pose, seq, seq * 100_000_000, 0),
            pose: [x, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            gt_pose: [x + 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            has_gt: 1,
            is_keyframe: u32::from(keyframe),
            ..PoseHeader::default()
        }
    }

    #[test]
    fn frames_are_appended_once_settled_and_the_latest_of_a_repeated_seq_wins() {
        let dir = tempfile::tempdir().expect("tmp");
        let mut r = Recorder::new(dir.path());
        for seq in 0..100 {
            let status = if seq == 10 {
                PoseStatus::Lost
            } else {
                PoseStatus::Tracked
            };
            r.record(&pose_msg(seq, seq as f64, seq % 10 == 0), status);
        }
        // A second tracker repeats seq 90 with another pose: it is recent, so it wins.
        r.record(&pose_msg(90, -1.0, true), PoseStatus::Tracked);
        assert_eq!(r.withdrawn(), 0);
        // The tracker gives up the start seq 95 was tracked from: lost now, and withdrawn.
        r.record(&pose_msg(95, 9.5, false), PoseStatus::Lost);
        assert_eq!((r.lost(), r.withdrawn()), (2, 1));
        r.record(&pose_msg(95, 9.5, false), PoseStatus::Tracked);
        r.write().expect("snapshot");
        let run = RunDir::new(dir.path());
        // Seqs 0..=35 are more than 64 behind 99: written; the rest waits.
        let written = read_tum_trajectory(&run.trajectory()).expect("trajectory");
        assert_eq!(written.len(), 35, "36 settled, one of them lost");
        assert_eq!(
            written[10].timestamp, 1.1,
            "seq 10 is lost, seq 11 follows seq 9"
        );
        assert_eq!(
            read_tum_trajectory(&run.groundtruth()).expect("gt").len(),
            36
        );
        let lost = std::fs::read_to_string(run.lost()).expect("lost.txt");
        assert_eq!(lost.lines().nth(1), Some("1.000000 10 Lost"));
        assert_eq!((r.len(), r.lost(), r.keyframes()), (100, 1, 10));
        // A settled seq cannot change any more.
        r.record(&pose_msg(5, 42.0, false), PoseStatus::Tracked);
        r.finish().expect("finish");
        let written = read_tum_trajectory(&run.trajectory()).expect("trajectory");
        assert_eq!(written.len(), 99);
        assert_eq!(
            written[5].pose.translation.x, 5.0,
            "seq 5 stays as first written"
        );
        let at_90 = written.iter().find(|p| p.timestamp == 9.0).expect("seq 90");
        assert_eq!(at_90.pose.translation.x, -1.0);
        assert_eq!((r.len(), r.lost(), r.keyframes()), (100, 1, 10));
        // Resume: the verified keyframes (seq 10 was lost, so 0, 20, …, 90), then seq 99.
        let resume = r.resume_poses();
        assert_eq!(resume.len(), 10);
        assert_eq!(resume[0].timestamp, 0.0);
        assert_eq!(resume.last().map(|p| p.timestamp), Some(9.9));
    }

    #[test]
    fn memory_holds_only_the_newest_frames() {
        let dir = tempfile::tempdir().expect("tmp");
        let mut r = Recorder::new(dir.path());
        for seq in 0..10_000 {
            r.record(&pose_msg(seq, 0.0, false), PoseStatus::Tracked);
            if seq % 150 == 0 {
                r.write().expect("snapshot");
            }
        }
        assert!(r.recent.len() <= 150 + SETTLE_AFTER as usize + 1);
        r.finish().expect("finish");
        assert!(r.recent.is_empty());
        let run = RunDir::new(dir.path());
        assert_eq!(
            read_tum_trajectory(&run.trajectory())
                .expect("trajectory")
                .len(),
            10_000
        );
    }
}
