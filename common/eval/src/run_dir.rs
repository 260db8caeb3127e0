//! The layout of a run directory: every file a run writes, named once. The stages write
//! into it, the supervisor and the scorers read from it, and `opengs eval`, `refine`,
//! `profile` and `bench` read it back later.

use std::path::{Path, PathBuf};

/// A run directory (`opengs run --out`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

impl RunDir {
    pub fn new(root: impl AsRef<Path>) -> Self {
        Self {
            root: root.as_ref().to_path_buf(),
        }
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    fn file(&self, name: &str) -> PathBuf {
        self.root.join(name)
    }

    /// The final Gaussian map (3DGS PLY with labels), written by the mapper.
    pub fn map(&self) -> PathBuf {
        self.file("map.ply")
    }

    /// The mapper's periodic checkpoint, which a restarted mapper resumes from.
    pub fn map_checkpoint(&self) -> PathBuf {
        self.file("map_checkpoint.ply")
    }

    /// The mapper's counters as of its checkpoint (keyframes, steps, restarts), so a
    /// restarted mapper's report counts the whole run.
    pub fn map_checkpoint_counters(&self) -> PathBuf {
        self.file("map_checkpoint.json")
    }

    /// Written by the supervisor when it restarts the tracker: the verified keyframe poses and,
    /// last, the last verified pose (TUM format), which the new tracker goes on from.
    pub fn tracker_resume(&self) -> PathBuf {
        self.file("tracker_resume.txt")
    }

    /// The map after `opengs refine`.
    pub fn map_refined(&self) -> PathBuf {
        self.file("map_refined.ply")
    }

    /// Verified camera poses (TUM format); after a final optimisation, aligned to the map.
    pub fn trajectory(&self) -> PathBuf {
        self.file("trajectory.txt")
    }

    /// The tracker's poses, kept when trajectory.txt was refined against the final map.
    pub fn trajectory_tracker(&self) -> PathBuf {
        self.file("trajectory_tracker.txt")
    }

    /// Ground-truth poses of the frames in `trajectory.txt`, when the dataset has them.
    pub fn groundtruth(&self) -> PathBuf {
        self.file("groundtruth.txt")
    }

    /// Frames without a verified pose, one per line (`timestamp seq status`).
    pub fn lost(&self) -> PathBuf {
        self.file("lost.txt")
    }

    /// The mapper's keyframes (images, camera, pose), journalled as they arrive so a
    /// restarted mapper optimises against all of them (the pipeline's `keyframe_journal`).
    pub fn mapper_keyframes(&self) -> PathBuf {
        self.file("mapper_keyframes")
    }

    /// The consensus results the mapper applied since its last checkpoint (the pipeline's
    /// `consensus_journal`), so a restarted mapper labels again what the checkpoint lacks.
    pub fn mapper_consensus(&self) -> PathBuf {
        self.file("mapper_consensus")
    }

    /// Keyframe sequence numbers, one per line, appended as the mapper adds them (the
    /// held-out frames of the semantic scoring).
    pub fn keyframes(&self) -> PathBuf {
        self.file("keyframes.txt")
    }

    /// What the run was: id, dataset arguments, stages (see the pipeline's `RunRecord`).
    pub fn run_record(&self) -> PathBuf {
        self.file("run.json")
    }

    /// Scores: ATE, PSNR, mIoU, ... merged by each scorer.
    pub fn metrics(&self) -> PathBuf {
        self.file("metrics.json")
    }

    /// Per-stage latency profile.
    pub fn latency(&self) -> PathBuf {
        self.file("latency.json")
    }

    /// Chrome/Perfetto trace of every message.
    pub fn trace(&self) -> PathBuf {
        self.file("trace.json")
    }

    /// The mapper's own counters (keyframes, iterations, final optimisation).
    pub fn mapper_report(&self) -> PathBuf {
        self.file("mapper.json")
    }

    /// The consensus's global Label-Class table, saved after every keyframe.
    pub fn label_table(&self) -> PathBuf {
        self.file("label_table.json")
    }

    /// The last keyframe the consensus answered (its seq), saved with the label table, so a
    /// restarted consensus neither answers a keyframe twice nor skips one without saying so.
    pub fn consensus_progress(&self) -> PathBuf {
        self.file("consensus_progress.json")
    }

    /// Global labels of the finished map (class, score, Gaussian count).
    pub fn labels(&self) -> PathBuf {
        self.file("labels.json")
    }

    /// The semantic scores in detail.
    pub fn semantics(&self) -> PathBuf {
        self.file("semantics.json")
    }

    /// The render-quality scores in detail.
    pub fn quality(&self) -> PathBuf {
        self.file("quality.json")
    }

    /// The render-quality scores of the refined map.
    pub fn quality_refined(&self) -> PathBuf {
        self.file("quality_refined.json")
    }

    /// The segmenter's label maps as the consensus received them, one PNG per keyframe.
    pub fn segments_dir(&self) -> PathBuf {
        self.file("segments")
    }

    /// Renders at the scored views (colour, depth, labels, side by side).
    pub fn renders_dir(&self) -> PathBuf {
        self.file("renders")
    }

    /// One log file per stage process.
    pub fn logs_dir(&self) -> PathBuf {
        self.file("logs")
    }

    /// Which segmenter process took which keyframe: one file per keyframe, created by the
    /// replica that claimed it (`opengs_pipeline::keyframe_claims`).
    pub fn segmenter_claims(&self) -> PathBuf {
        self.file("segmenter_claims")
    }
}

/// Writes `bytes` to `path` through a temporary file beside it, synced and renamed: a reader
/// (or a run killed mid-write) sees the old file or the new one, never half of one.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let mut tmp_name = path.file_name().unwrap_or_default().to_os_string();
    tmp_name.push(".tmp");
    let tmp = path.with_file_name(tmp_name);
    let mut file = std::fs::File::create(&tmp)?;
    file.write_all(bytes)?;
    file.sync_all()?;
    std::fs::rename(&tmp, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_file_has_its_own_name_inside_the_run() {
        let d = RunDir::new("/r");
        let all = [
            d.map(),
            d.map_checkpoint(),
            d.map_refined(),
            d.trajectory(),
            d.groundtruth(),
            d.lost(),
            d.keyframes(),
            d.run_record(),
            d.metrics(),
            d.latency(),
            d.trace(),
            d.mapper_report(),
            d.label_table(),
            d.labels(),
            d.semantics(),
            d.quality(),
            d.quality_refined(),
            d.segments_dir(),
            d.renders_dir(),
            d.logs_dir(),
            d.segmenter_claims(),
        ];
        let unique: std::collections::BTreeSet<_> = all.iter().collect();
        assert_eq!(unique.len(), all.len());
        assert!(all.iter().all(|p| p.parent() == Some(Path::new("/r"))));
    }
}
