use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// A running pipeline, as `opengs ctl` finds it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ActiveRun {
    pub run_id: String,
    pub pid: u32,
    pub out_dir: PathBuf,
}

/// Registry of running pipelines: one small JSON file per run in a per-user directory.
pub struct ActiveRuns {
    dir: PathBuf,
}

impl Default for ActiveRuns {
    fn default() -> Self {
        let base = std::env::var_os("XDG_RUNTIME_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(std::env::temp_dir);
        Self {
            dir: base.join("opengs").join("active"),
        }
    }
}

impl ActiveRuns {
    pub fn at(dir: &Path) -> Self {
        Self {
            dir: dir.to_path_buf(),
        }
    }

    pub fn register(&self, run: &ActiveRun) -> std::io::Result<()> {
        std::fs::create_dir_all(&self.dir)?;
        let text = serde_json::to_string(run).map_err(std::io::Error::other)?;
        std::fs::write(self.dir.join(format!("{}.json", run.run_id)), text)
    }

    pub fn unregister(&self, run_id: &str) {
        let _ = std::fs::remove_file(self.dir.join(format!("{run_id}.json")));
    }

    /// Runs whose supervisor process is alive; stale entries are removed.
    pub fn live(&self) -> Vec<ActiveRun> {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return Vec::new();
        };
        let mut runs = Vec::new();
        for entry in entries.flatten() {
            let Ok(text) = std::fs::read_to_string(entry.path()) else {
                continue;
            };
            let Ok(run) = serde_json::from_str::<ActiveRun>(&text) else {
                continue;
            };
            // SAFETY: kill with signal 0 only checks that the process exists.
            if unsafe { libc::kill(run.pid as i32, 0) } == 0 {
                runs.push(run);
            } else {
                let _ = std::fs::remove_file(entry.path());
            }
        }
        runs.sort_by(|a, b| a.run_id.cmp(&b.run_id));
        runs
    }
}
