//! Deploy files: which stage processes to start, in which order, pinned how.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

/// What a stage is to the supervisor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum StageRole {
    /// Produces frames; its clean exit means end of data; restarted with `--start-frame`.
    Source,
    /// Consumes and produces messages until stopped.
    #[default]
    Worker,
}

/// The stage names of the built-in deploy files, which `opengs run` addresses by name.
pub mod stage_names {
    pub const SENSOR: &str = "sensor";
    pub const TRACKER: &str = "tracker";
    pub const MAPPER: &str = "mapper";
    pub const SEGMENTER: &str = "segmenter";
    pub const CONSENSUS: &str = "consensus";
    /// The optional Rerun viewer (`opengs run --rerun`), added by the run, not the deploy file.
    pub const VIEWER: &str = "viewer";
}

/// Most processes one stage may run (`replicas`, `opengs ctl scale`).
pub const MAX_REPLICAS: u32 = 6;

/// Stages that may run several processes: their work is per keyframe and they share it out
/// (the segmenter claims keyframes, [`crate::keyframe_claims`]). The tracker, mapper and
/// consensus carry state from one message to the next, so a second process would diverge.
pub const SCALABLE_STAGES: [&str; 1] = [stage_names::SEGMENTER];

/// Why `stage` cannot run `replicas` processes, if it cannot.
pub fn check_replicas(stage: &str, replicas: u32) -> Result<(), String> {
    if !(1..=MAX_REPLICAS).contains(&replicas) {
        return Err(format!(
            "stage '{stage}': replicas must be 1-{MAX_REPLICAS}, got {replicas}"
        ));
    }
    if replicas > 1 && !SCALABLE_STAGES.contains(&stage) {
        return Err(format!(
            "stage '{stage}' cannot run replicas: only {} share their work out (the others \
             carry state from one message to the next)",
            SCALABLE_STAGES.join(", ")
        ));
    }
    Ok(())
}

/// One stage process.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageSpec {
    pub name: String,
    /// Executable name (looked up beside `opengs`) or path.
    pub binary: String,
    #[serde(default)]
    pub args: Vec<String>,
    #[serde(default)]
    pub role: StageRole,
    /// CPUs to pin the process to (edge boxes); empty = no pinning.
    #[serde(default)]
    pub cpus: Vec<usize>,
    /// Niceness to apply (0 = unchanged; higher = lower priority).
    #[serde(default)]
    pub nice: i32,
    /// Linux scheduling policy: `normal`, `batch` (CPU-bound, never preempts on wake-up),
    /// or `idle` (runs only on CPU time nothing else wants).
    #[serde(default)]
    pub scheduler: Scheduler,
    /// Restarts allowed before the run is abandoned.
    #[serde(default = "default_restart_limit")]
    pub restart_limit: u32,
    /// Pass the run's dataset selection (`--dataset ...`) to this stage too.
    #[serde(default)]
    pub dataset: bool,
    /// For swappable stages: the implementation to run (`--kind KIND`), changed by `opengs ctl swap`.
    pub kind: Option<String>,
    /// Each kind's own arguments (its model files), added after `args` while that kind runs:
    /// `[stages.kinds.sam]` `args = [...]`. A kind without an entry gets `args` alone.
    #[serde(default)]
    pub kinds: BTreeMap<String, KindSpec>,
    /// Seconds this stage may work on after the end of the data (the mapper's final
    /// optimisation): it gets SIGUSR1, and the others are stopped once it exits or this
    /// runs out. 0 = none; Ctrl-C always stops at once.
    #[serde(default)]
    pub finish_timeout_s: f64,
    /// Seconds a ready stage may send nothing (no output, no heartbeat) before the
    /// supervisor takes it for hung, kills and restarts it; above the longest single
    /// message (a SAM keyframe on a CPU). 0 = no watchdog.
    #[serde(default = "default_watchdog")]
    pub watchdog_s: f64,
    /// A sink the pipeline does not need (the Rerun viewer): its failure to start, its death
    /// past `restart_limit` or its input errors are reported, and the run goes on without it.
    #[serde(default)]
    pub optional: bool,
    /// Processes of this stage sharing its work (only the stages in [`SCALABLE_STAGES`]);
    /// `opengs ctl scale` changes it while the run goes on.
    #[serde(default = "default_replicas")]
    pub replicas: u32,
    /// The host this stage runs on, when not the one `opengs run` runs on: that host runs
    /// it under `opengs node --host NAME`, and a bridge stage on each side carries the
    /// services between them. The run's supervisor shows it from the telemetry it sends.
    #[serde(default)]
    pub host: Option<String>,
    /// Pass the run id the hosts share (`--link RUN`): for bridge stages.
    #[serde(default)]
    pub link: bool,
}

fn default_replicas() -> u32 {
    1
}

/// The arguments of one kind of a swappable stage.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KindSpec {
    #[serde(default)]
    pub args: Vec<String>,
}

impl StageSpec {
    /// The deploy file's arguments for the kind this spec runs: `args`, then the kind's own.
    pub fn kind_args(&self) -> Vec<String> {
        let own = self
            .kind
            .as_ref()
            .and_then(|k| self.kinds.get(k))
            .map(|k| k.args.as_slice())
            .unwrap_or_default();
        self.args.iter().chain(own).cloned().collect()
    }

    /// Refuses kinds outside `known` in `kind` and `[stages.kinds.*]` (typos would otherwise
    /// surface only when a swap starts the misspelt kind).
    pub fn check_kinds(&self, known: &[&str]) -> Result<(), String> {
        let named = self.kind.iter().chain(self.kinds.keys());
        match named.into_iter().find(|k| !known.contains(&k.as_str())) {
            Some(k) => Err(format!(
                "stage '{}': unknown kind '{k}' (expected one of {})",
                self.name,
                known.join(", ")
            )),
            None => Ok(()),
        }
    }
}

/// A stage's scheduling policy. A niced stage still delays the tracker: each wake-up of
/// the tracker's worker threads waits for the running stage's time slice (measured: the
/// tracker's median frame 10.5 ms alone, 27.8 ms beside two nice-10 CPU hogs, 13.0 ms beside
/// two SCHED_IDLE ones).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Scheduler {
    #[default]
    Normal,
    Batch,
    Idle,
}

impl Scheduler {
    /// The `sched_setscheduler` policy.
    pub fn policy(self) -> libc::c_int {
        match self {
            Self::Normal => libc::SCHED_OTHER,
            Self::Batch => libc::SCHED_BATCH,
            Self::Idle => libc::SCHED_IDLE,
        }
    }
}

fn default_restart_limit() -> u32 {
    3
}

fn default_watchdog() -> f64 {
    10.0
}

fn default_startup_timeout() -> f64 {
    30.0
}

fn default_drain_timeout() -> f64 {
    10.0
}

/// A deploy file (`deploy/desktop.toml`, `deploy/edge.toml`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeployFile {
    #[serde(default)]
    pub description: String,
    /// Seconds a stage may take to report ready.
    #[serde(default = "default_startup_timeout")]
    pub startup_timeout_s: f64,
    /// Seconds to wait, after end of data, for stages to finish their queues.
    #[serde(default = "default_drain_timeout")]
    pub drain_timeout_s: f64,
    /// The stage whose completion of a frame ends its end-to-end latency.
    pub terminal_stage: Option<String>,
    /// Start order: consumers first, so no frame is published before its readers exist.
    pub stages: Vec<StageSpec>,
}

#[derive(Debug, thiserror::Error)]
pub enum DeployError {
    #[error("deploy file {path}: {cause}")]
    Read {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("deploy file {path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("deploy file {path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

/// The desktop deploy file, compiled in so `opengs run` works from any directory.
pub const DESKTOP: &str = include_str!("../../../deploy/desktop.toml");
/// The edge deploy file, compiled in.
pub const EDGE: &str = include_str!("../../../deploy/edge.toml");

impl DeployFile {
    /// Reads a deploy file; `desktop` and `edge` name the built-in ones.
    pub fn load(path: &Path) -> Result<Self, DeployError> {
        let text = match path.to_str() {
            Some("desktop") => DESKTOP.to_string(),
            Some("edge") => EDGE.to_string(),
            _ => std::fs::read_to_string(path).map_err(|e| DeployError::Read {
                path: path.to_path_buf(),
                cause: e,
            })?,
        };
        Self::parse(&text, path)
    }

    pub fn parse(text: &str, path: &Path) -> Result<Self, DeployError> {
        let file: Self = toml::from_str(text).map_err(|e| DeployError::Parse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        file.validate(path)?;
        Ok(file)
    }

    fn validate(&self, path: &Path) -> Result<(), DeployError> {
        let invalid = |message: String| DeployError::Invalid {
            path: path.to_path_buf(),
            message,
        };
        if self.stages.is_empty() {
            return Err(invalid("no [[stages]]".into()));
        }
        let mut names = std::collections::BTreeSet::new();
        for s in &self.stages {
            if !(s.watchdog_s.is_finite() && s.watchdog_s >= 0.0) {
                return Err(invalid(format!(
                    "stage '{}': watchdog_s must be ≥ 0 seconds (0 = off), got {}",
                    s.name, s.watchdog_s
                )));
            }
            if !(s.finish_timeout_s.is_finite() && s.finish_timeout_s >= 0.0) {
                return Err(invalid(format!(
                    "stage '{}': finish_timeout_s must be ≥ 0 seconds, got {}",
                    s.name, s.finish_timeout_s
                )));
            }
            if s.name.is_empty()
                || s.name.len() > 16
                || !s
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_')
            {
                return Err(invalid(format!(
                    "stage name '{}' must be 1-16 letters, digits or '_'",
                    s.name
                )));
            }
            check_replicas(&s.name, s.replicas).map_err(invalid)?;
            if let Some(h) = &s.host {
                if h.is_empty()
                    || h.len() > 16
                    || !h.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                {
                    return Err(invalid(format!(
                        "stage '{}': host '{h}' must be 1-16 letters, digits or '_'",
                        s.name
                    )));
                }
                if s.role == StageRole::Source {
                    return Err(invalid(format!(
                        "stage '{}': the source runs on the host `opengs run` runs on (no `host`)",
                        s.name
                    )));
                }
            }
            if !names.insert(&s.name) {
                return Err(invalid(format!("stage '{}' appears twice", s.name)));
            }
            if !s.kinds.is_empty() && s.kind.is_none() {
                return Err(invalid(format!(
                    "stage '{}': [stages.kinds.*] needs `kind`, the one to start with",
                    s.name
                )));
            }
            if s.optional && s.role == StageRole::Source {
                return Err(invalid(format!(
                    "stage '{}': the source cannot be optional (the run is its data)",
                    s.name
                )));
            }
            if !(-20..=19).contains(&s.nice) {
                return Err(invalid(format!(
                    "stage '{}': nice {} outside -20..19",
                    s.name, s.nice
                )));
            }
            let ncpu = std::thread::available_parallelism().map_or(1, |n| n.get());
            if let Some(c) = s.cpus.iter().find(|&&c| c >= 1024) {
                return Err(invalid(format!(
                    "stage '{}': cpu {c} does not exist",
                    s.name
                )));
            }
            // Pinning to no existing cpu is impossible: refused, as other impossible values.
            if !s.cpus.is_empty() && s.cpus.iter().all(|&c| c >= ncpu) {
                return Err(invalid(format!(
                    "stage '{}': none of cpus {:?} exist on this {ncpu}-cpu machine (cpus 0-{})",
                    s.name,
                    s.cpus,
                    ncpu - 1
                )));
            }
        }
        if self
            .stages
            .iter()
            .filter(|s| s.role == StageRole::Source)
            .count()
            != 1
        {
            return Err(invalid(
                "exactly one stage must have role = \"source\"".into(),
            ));
        }
        if let Some(t) = &self.terminal_stage {
            if !names.contains(t) {
                return Err(invalid(format!("terminal_stage '{t}' is not a stage")));
            }
            if self.stages.iter().any(|s| &s.name == t && s.host.is_some()) {
                return Err(invalid(format!(
                    "terminal_stage '{t}' must run on the host `opengs run` runs on"
                )));
            }
        }
        if !(self.startup_timeout_s > 0.0 && self.drain_timeout_s >= 0.0) {
            return Err(invalid("timeouts must be positive".into()));
        }
        Ok(())
    }

    /// The hosts other than the main one that this file puts stages on.
    pub fn hosts(&self) -> Vec<&str> {
        let mut hosts: Vec<&str> = self
            .stages
            .iter()
            .filter_map(|s| s.host.as_deref())
            .collect();
        hosts.sort_unstable();
        hosts.dedup();
        hosts
    }

    pub fn source(&self) -> &StageSpec {
        // validate() guarantees exactly one source.
        self.stages
            .iter()
            .find(|s| s.role == StageRole::Source)
            .unwrap_or(&self.stages[0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn built_in_files_parse() {
        for name in ["desktop", "edge"] {
            let d = DeployFile::load(Path::new(name)).expect(name);
            assert_eq!(d.source().name, "sensor");
        }
        let edge = DeployFile::load(Path::new("edge")).expect("edge");
        assert!(edge
            .stages
            .iter()
            .any(|s| !s.cpus.is_empty() && s.nice != 0));
    }

    #[test]
    fn bad_files_name_the_problem() {
        let p = Path::new("x.toml");
        let err = DeployFile::parse("stages = []", p).expect_err("empty");
        assert!(err.to_string().contains("no [[stages]]"), "{err}");
        let two_sources = r#"
            [[stages]]
            name = "a"
            binary = "a"
            role = "source"
            [[stages]]
            name = "b"
            binary = "b"
            role = "source"
        "#;
        assert!(DeployFile::parse(two_sources, p)
            .expect_err("two")
            .to_string()
            .contains("exactly one"));
        let typo = "[[stages]]\nname = \"a\"\nbinary = \"a\"\nrol = \"source\"\n";
        let err = DeployFile::parse(typo, p).expect_err("typo");
        assert!(err.to_string().contains("rol"), "{err}");
        let bad_nice = "[[stages]]\nname = \"a\"\nbinary = \"a\"\nrole = \"source\"\nnice = 40\n";
        assert!(DeployFile::parse(bad_nice, p)
            .expect_err("nice")
            .to_string()
            .contains("nice"));
        let bad_watchdog =
            "[[stages]]\nname = \"a\"\nbinary = \"a\"\nrole = \"source\"\nwatchdog_s = -1\n";
        assert!(DeployFile::parse(bad_watchdog, p)
            .expect_err("watchdog")
            .to_string()
            .contains("watchdog_s must be ≥ 0"));
        let optional_source =
            "[[stages]]\nname = \"a\"\nbinary = \"a\"\nrole = \"source\"\noptional = true\n";
        assert!(DeployFile::parse(optional_source, p)
            .expect_err("optional source")
            .to_string()
            .contains("source cannot be optional"));
    }

    #[test]
    fn only_the_segmenter_runs_replicas_and_only_a_few() {
        let p = Path::new("x.toml");
        let file = |stage: &str, replicas: u32| {
            format!(
                "[[stages]]\nname = \"{stage}\"\nbinary = \"b\"\nreplicas = {replicas}\n\
                 [[stages]]\nname = \"sensor\"\nbinary = \"s\"\nrole = \"source\"\n"
            )
        };
        let d = DeployFile::parse(&file("segmenter", 4), p).expect("4 segmenters");
        assert_eq!(d.stages[0].replicas, 4);
        assert_eq!(d.stages[1].replicas, 1, "default");
        let err = DeployFile::parse(&file("mapper", 2), p).expect_err("2 mappers");
        assert!(
            err.to_string().contains("'mapper' cannot run replicas"),
            "{err}"
        );
        let err = DeployFile::parse(&file("segmenter", 7), p).expect_err("7 segmenters");
        assert!(
            err.to_string().contains("replicas must be 1-6, got 7"),
            "{err}"
        );
        let err = DeployFile::parse(&file("segmenter", 0), p).expect_err("none");
        assert!(
            err.to_string().contains("replicas must be 1-6, got 0"),
            "{err}"
        );
    }

    #[test]
    fn each_kind_gets_its_own_arguments() {
        let p = Path::new("x.toml");
        let text = r#"
            [[stages]]
            name = "segmenter"
            binary = "opengs-segmenter"
            kind = "sam"
            args = ["--tagger", "t.onnx"]
            [stages.kinds.sam]
            args = ["--encoder", "vit_h.onnx"]
            [stages.kinds.mobilesamv2]
            args = ["--encoder", "mobile.onnx", "--proposals", "boxes.onnx"]
            [[stages]]
            name = "sensor"
            binary = "opengs-sensor"
            role = "source"
        "#;
        let d = DeployFile::parse(text, p).expect("parses");
        let mut seg = d.stages[0].clone();
        assert_eq!(
            seg.kind_args(),
            ["--tagger", "t.onnx", "--encoder", "vit_h.onnx"]
        );
        seg.kind = Some("mobilesamv2".into());
        assert_eq!(
            seg.kind_args(),
            [
                "--tagger",
                "t.onnx",
                "--encoder",
                "mobile.onnx",
                "--proposals",
                "boxes.onnx"
            ]
        );
        // A kind without its own set runs with the shared arguments alone.
        seg.kind = Some("geometry".into());
        assert_eq!(seg.kind_args(), ["--tagger", "t.onnx"]);
        let known = ["geometry", "sam", "mobilesamv2"];
        assert!(seg.check_kinds(&known).is_ok());
        let err = seg.check_kinds(&["geometry", "sam"]).expect_err("unknown");
        assert!(err.contains("unknown kind 'mobilesamv2'"), "{err}");

        let no_kind = text.replace("kind = \"sam\"\n", "");
        let err = DeployFile::parse(&no_kind, p).expect_err("kinds without kind");
        assert!(err.to_string().contains("needs `kind`"), "{err}");
        let typo = text.replace(
            "[stages.kinds.sam]\n            args",
            "[stages.kinds.sam]\n            arg",
        );
        let err = DeployFile::parse(&typo, p).expect_err("typo");
        assert!(err.to_string().contains("arg"), "{err}");
    }
}
