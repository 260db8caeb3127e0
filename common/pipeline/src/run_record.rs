//! `run.json`: what a run was (its id, the dataset selection, each stage's counters), written
//! by `opengs run` and read back by `opengs refine` to reopen the same dataset.

use anyhow::Context;
use opengs_eval::RunDir;
use serde::{Deserialize, Serialize};

use crate::DatasetArgs;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    pub run_id: String,
    pub dataset_args: DatasetArgs,
    /// Frames in the dataset as selected (unknown when it could not be opened).
    #[serde(default)]
    pub frames_total: Option<usize>,
    #[serde(default)]
    pub stages: Vec<StageRecord>,
}

/// One stage's counters at the end of the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageRecord {
    pub name: String,
    /// Which of the stage's processes (0 for the first, and for runs before replicas).
    #[serde(default)]
    pub replica: u32,
    pub restarts: u32,
    /// Of the restarts, those after the watchdog found it hung (silent past its `watchdog_s`).
    #[serde(default)]
    pub hangs: u32,
    /// Messages it processed.
    pub processed: u64,
    /// Sequence number of the last message it processed.
    pub last_seq: Option<u64>,
}

impl RunRecord {
    pub fn write(&self, run: &RunDir) -> anyhow::Result<()> {
        let path = run.run_record();
        let text = serde_json::to_string_pretty(self)?;
        opengs_eval::write_atomically(&path, text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))
    }

    /// `Ok(None)` when the run has no `run.json`.
    pub fn read(run: &RunDir) -> anyhow::Result<Option<Self>> {
        let path = run.run_record();
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => {
                return Err(anyhow::Error::new(e).context(format!("reading {}", path.display())))
            }
        };
        // The error names the field at fault (`dataset_args.frames: invalid type ...`).
        let record =
            serde_path_to_error::deserialize(&mut serde_json::Deserializer::from_str(&text))
                .with_context(|| format!("{}: not a run record", path.display()))?;
        Ok(Some(record))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_reads_back_as_written_and_bad_files_name_themselves() {
        let dir = std::env::temp_dir().join(format!("opengs-run-record-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let run = RunDir::new(&dir);
        assert_eq!(RunRecord::read(&run).expect("no file is fine"), None);
        let record = RunRecord {
            run_id: "r1".into(),
            dataset_args: DatasetArgs {
                dataset: "tum:/data/x".into(),
                frames: Some(30),
                seed: 2,
                ..DatasetArgs::default()
            },
            frames_total: Some(30),
            stages: vec![StageRecord {
                name: "tracker".into(),
                replica: 0,
                restarts: 1,
                hangs: 1,
                processed: 29,
                last_seq: Some(29),
            }],
        };
        record.write(&run).expect("write");
        assert_eq!(RunRecord::read(&run).expect("read"), Some(record));
        // A record from before the scene-suite flags still loads; a wrong type is named.
        std::fs::write(
            run.run_record(),
            r#"{"run_id": "old", "dataset_args": {"dataset": "synthetic", "frames": null, "trajectory": null, "seed": 3, "noise": false}}"#,
        )
        .expect("write");
        let old = RunRecord::read(&run).expect("read").expect("some");
        assert_eq!((old.dataset_args.seed, old.dataset_args.speed), (3, 1));
        std::fs::write(
            run.run_record(),
            r#"{"run_id": "x", "dataset_args": {"dataset": 5}}"#,
        )
        .expect("write");
        let e = format!("{:#}", RunRecord::read(&run).expect_err("bad type"));
        assert!(
            e.contains("run.json") && e.contains("dataset_args.dataset"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
