use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use serde::{Deserialize, Serialize};

use crate::{RunContext, RuntimeError};

/// Files of a run with no registry entry count as abandoned only once they are this old: a
/// run creates its first file a moment before it registers.
const UNREGISTERED_MIN_AGE: Duration = Duration::from_secs(10);

/// A running pipeline, as `opengs ctl` finds it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ActiveRun {
    pub run_id: String,
    pub pid: u32,
    pub out_dir: PathBuf,
}

impl ActiveRun {
    /// Whether the run's supervisor process still exists.
    pub fn is_alive(&self) -> bool {
        process_alive(self.pid)
    }
}

/// Whether process `pid` exists: a zombie (killed, not yet reaped) does not count, and one
/// of another user (EPERM) does.
pub fn process_alive(pid: u32) -> bool {
    // 0 and values above i32::MAX would address process groups, not a process.
    let Ok(pid) = i32::try_from(pid) else {
        return false;
    };
    if pid <= 0 {
        return false;
    }
    // SAFETY: kill with signal 0 only checks that the process exists.
    let exists = unsafe { libc::kill(pid, 0) } == 0
        || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM);
    if !exists {
        return false;
    }
    // The state follows the command name, which may itself hold ')'.
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(stat) => !matches!(
            stat.rsplit_once(')')
                .and_then(|(_, rest)| rest.trim_start().chars().next()),
            Some('Z' | 'X')
        ),
        Err(_) => true,
    }
}

/// What cleaning one dead run removed (with `dry_run`: what it would remove).
#[derive(Debug, Clone, PartialEq)]
pub struct CleanedRun {
    pub run_id: String,
    /// Its supervisor's pid, when the registry knew the run.
    pub pid: Option<u32>,
    /// Its files in `/dev/shm` and under the iceoryx2 root, as found before cleaning.
    pub files: Vec<PathBuf>,
    /// Its registry entry, when it had one.
    pub registry_entry: Option<PathBuf>,
}

impl CleanedRun {
    pub fn is_empty(&self) -> bool {
        self.files.is_empty() && self.registry_entry.is_none()
    }
}

/// Why a run was not cleaned.
#[derive(Debug, thiserror::Error)]
pub enum CleanError {
    #[error(
        "run {run_id} is running (supervisor pid {pid}); its shared memory is in use. Stop it \
         with `opengs ctl --run {run_id} stop`"
    )]
    Live { run_id: String, pid: u32 },
    #[error(
        "run {run_id}: processes still use its shared memory: {}; end them first",
        .processes.join(", ")
    )]
    InUse {
        run_id: String,
        processes: Vec<String>,
    },
    #[error("cannot remove {}: {source}", .path.display())]
    Remove {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
}

/// What `ActiveRuns::clean_dead` did: the runs it cleaned, those it left alone (still in
/// use) and the files it could not remove.
#[derive(Debug, Default)]
pub struct CleanReport {
    pub cleaned: Vec<CleanedRun>,
    pub skipped: Vec<CleanError>,
    pub failed: Vec<CleanError>,
}

/// Registry of running pipelines: one small JSON file per run in a per-user directory.
/// An entry stays after its supervisor died (SIGKILL) until `clean_run` / `clean_dead`
/// removes it with the run's shared memory.
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

    fn entry_path(&self, run_id: &str) -> PathBuf {
        self.dir.join(format!("{run_id}.json"))
    }

    pub fn register(&self, run: &ActiveRun) -> std::io::Result<()> {
        std::fs::create_dir_all(&self.dir)?;
        let text = serde_json::to_string(run).map_err(std::io::Error::other)?;
        std::fs::write(self.entry_path(&run.run_id), text)
    }

    pub fn unregister(&self, run_id: &str) {
        let _ = std::fs::remove_file(self.entry_path(run_id));
    }

    /// Every registered run, alive or not, with its entry's path, sorted by run id. An
    /// entry that does not parse (being written right now) is left out.
    fn entries(&self) -> Vec<(PathBuf, ActiveRun)> {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return Vec::new();
        };
        let mut runs: Vec<(PathBuf, ActiveRun)> = entries
            .flatten()
            .filter_map(|entry| {
                let text = std::fs::read_to_string(entry.path()).ok()?;
                let run = serde_json::from_str::<ActiveRun>(&text).ok()?;
                Some((entry.path(), run))
            })
            .collect();
        runs.sort_by(|a, b| a.1.run_id.cmp(&b.1.run_id));
        runs
    }

    /// Runs whose supervisor process is alive.
    pub fn live(&self) -> Vec<ActiveRun> {
        self.entries()
            .into_iter()
            .map(|(_, run)| run)
            .filter(ActiveRun::is_alive)
            .collect()
    }

    /// Registered runs whose supervisor process is gone (killed, or crashed).
    pub fn dead(&self) -> Vec<ActiveRun> {
        self.entries()
            .into_iter()
            .map(|(_, run)| run)
            .filter(|run| !run.is_alive())
            .collect()
    }

    /// Removes the shared memory (`/dev/shm`, the iceoryx2 root, the domain segment
    /// included) and the registry entry of run `run_id`, whose supervisor and stages must
    /// all be gone: a live run is refused, never touched. With `dry_run`, only says what it
    /// would remove.
    pub fn clean_run(&self, run_id: &str, dry_run: bool) -> Result<CleanedRun, CleanError> {
        let ctx = RunContext::new(run_id)?;
        let entry = self
            .entries()
            .into_iter()
            .find(|(_, run)| run.run_id == run_id);
        if let Some((_, run)) = &entry {
            if run.is_alive() {
                return Err(CleanError::Live {
                    run_id: run_id.to_string(),
                    pid: run.pid,
                });
            }
        }
        // A stage that outlived its supervisor still maps the files.
        let processes = ctx.alive_nodes()?;
        if !processes.is_empty() {
            return Err(CleanError::InUse {
                run_id: run_id.to_string(),
                processes,
            });
        }
        let cleaned = CleanedRun {
            run_id: run_id.to_string(),
            pid: entry.as_ref().map(|(_, run)| run.pid),
            files: ctx.leftover_files(),
            registry_entry: entry.as_ref().map(|(path, _)| path.clone()),
        };
        if dry_run {
            return Ok(cleaned);
        }
        ctx.remove_leftovers()?;
        if let Some(path) = ctx.leftover_files().into_iter().next() {
            return Err(CleanError::Remove {
                path,
                source: std::io::Error::other("it is still there after removing it"),
            });
        }
        if let Some((path, _)) = entry {
            match std::fs::remove_file(&path) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(source) => return Err(CleanError::Remove { path, source }),
            }
        }
        Ok(cleaned)
    }

    /// Cleans every dead run: registered runs whose supervisor is gone, and runs that left
    /// files without a registry entry (older than a few seconds, so one starting now is
    /// not taken for dead). Runs whose processes still hold their memory are skipped.
    pub fn clean_dead(&self, dry_run: bool) -> CleanReport {
        let registered = self.entries();
        let mut candidates: Vec<String> = registered
            .iter()
            .filter(|(_, run)| !run.is_alive())
            .map(|(_, run)| run.run_id.clone())
            .collect();
        for run_id in crate::runs_with_files() {
            let known = registered.iter().any(|(_, run)| run.run_id == run_id);
            if !known && files_older_than(&run_id, UNREGISTERED_MIN_AGE) {
                candidates.push(run_id);
            }
        }
        candidates.sort();
        candidates.dedup();
        let mut report = CleanReport::default();
        for run_id in candidates {
            match self.clean_run(&run_id, dry_run) {
                Ok(cleaned) if cleaned.is_empty() => {}
                Ok(cleaned) => report.cleaned.push(cleaned),
                Err(e @ (CleanError::Live { .. } | CleanError::InUse { .. })) => {
                    report.skipped.push(e)
                }
                Err(e) => report.failed.push(e),
            }
        }
        report
    }
}

/// Whether every file run `run_id` has is older than `age`.
fn files_older_than(run_id: &str, age: Duration) -> bool {
    let now = SystemTime::now();
    crate::leftover_files(run_id).iter().all(|path| {
        std::fs::metadata(path)
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| now.duration_since(t).ok())
            .is_some_and(|d| d >= age)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn registry(tag: &str) -> (PathBuf, ActiveRuns) {
        let dir = std::env::temp_dir().join(format!("opengs-active-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let runs = ActiveRuns::at(&dir);
        (dir, runs)
    }

    /// The pid of a process that has exited and been reaped.
    fn dead_pid() -> u32 {
        let mut child = std::process::Command::new("true")
            .spawn()
            .expect("`true` starts");
        let pid = child.id();
        child.wait().expect("`true` ends");
        pid
    }

    #[test]
    fn dead_entries_stay_listed_until_cleaned() {
        let (dir, runs) = registry("dead");
        let live = ActiveRun {
            run_id: "u-live".into(),
            pid: std::process::id(),
            out_dir: "runs/a".into(),
        };
        let dead = ActiveRun {
            run_id: format!("u{}-dead", std::process::id()),
            pid: dead_pid(),
            out_dir: "runs/b".into(),
        };
        runs.register(&live).expect("register");
        runs.register(&dead).expect("register");
        assert_eq!(runs.live(), vec![live.clone()]);
        assert_eq!(runs.dead(), vec![dead.clone()]);
        // Asking for live runs leaves the dead entry for `clean` to find.
        assert_eq!(runs.dead(), vec![dead.clone()]);

        let refused = runs.clean_run("u-live", false);
        assert!(
            matches!(refused, Err(CleanError::Live { .. })),
            "{refused:?}"
        );
        let preview = runs.clean_run(&dead.run_id, true).expect("dry run");
        assert_eq!(preview.pid, Some(dead.pid));
        assert!(preview.registry_entry.is_some());
        assert_eq!(runs.dead(), vec![dead.clone()], "a dry run removes nothing");
        let cleaned = runs.clean_run(&dead.run_id, false).expect("clean");
        assert_eq!(cleaned.registry_entry, preview.registry_entry);
        assert!(runs.dead().is_empty());
        assert_eq!(runs.live(), vec![live]);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn the_domain_segment_of_an_ended_run_is_cleaned() {
        let (dir, runs) = registry("segment");
        let run_id = format!("u{}-segment", std::process::id());
        let ctx = RunContext::new(&run_id).expect("context");
        {
            let node = ctx.node("test");
            assert!(node.is_ok(), "{:?}", node.err());
            let refused = runs.clean_run(&run_id, false);
            assert!(
                matches!(refused, Err(CleanError::InUse { .. })),
                "a node of this process is alive: {refused:?}"
            );
        }
        // The node is gone; iceoryx2 keeps the run's domain segment by design.
        let left = ctx.leftover_files();
        assert!(!left.is_empty(), "iceoryx2 left no domain segment");
        let cleaned = runs.clean_run(&run_id, false).expect("clean");
        assert_eq!(cleaned.files, left);
        assert_eq!(cleaned.pid, None);
        assert!(ctx.leftover_files().is_empty());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn a_zombie_is_not_alive() {
        let mut child = std::process::Command::new("true")
            .spawn()
            .expect("`true` starts");
        let pid = child.id();
        // Not yet waited for: it is a zombie until reaped below.
        std::thread::sleep(Duration::from_millis(200));
        assert!(!process_alive(pid));
        assert!(process_alive(std::process::id()));
        assert!(!process_alive(0));
        child.wait().expect("`true` ends");
    }
}
