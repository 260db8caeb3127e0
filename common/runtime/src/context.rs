use std::path::{Path, PathBuf};

use iceoryx2::config::Config;
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use opengs_ipc_schema::ServiceSpec;

use crate::{CleanError, Ipc, RuntimeError};

/// Everything a process needs to join one run: the run id and the iceoryx2
/// config whose file prefix isolates this run's shared memory from any other.
#[derive(Clone)]
pub struct RunContext {
    run_id: String,
    config: Config,
}

impl RunContext {
    pub fn new(run_id: &str) -> Result<Self, RuntimeError> {
        if !Self::valid_run_id(run_id) {
            return Err(RuntimeError::RunId(run_id.to_string()));
        }
        let mut config = Config::default();
        config.global.prefix = FileName::new(Self::prefix_of(run_id).as_bytes())
            .map_err(|e| RuntimeError::Iceoryx(format!("file prefix for run {run_id}: {e:?}")))?;
        Ok(Self {
            run_id: run_id.to_string(),
            config,
        })
    }

    /// Letters, digits, '-' and '_', at most 40: it goes into every file name of the run.
    pub fn valid_run_id(run_id: &str) -> bool {
        !run_id.is_empty()
            && run_id.len() <= 40
            && run_id
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    }

    /// File prefix of a run's iceoryx2 resources (`/dev/shm`, the iceoryx2 root).
    pub fn prefix_of(run_id: &str) -> String {
        format!("ogs_{run_id}_")
    }

    pub fn run_id(&self) -> &str {
        &self.run_id
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    /// A node of this run. Creating it also cleans stale resources of dead nodes.
    pub fn node(&self, name: &str) -> Result<Node<Ipc>, RuntimeError> {
        let node_name = NodeName::new(name)
            .map_err(|e| RuntimeError::Iceoryx(format!("node name '{name}': {e:?}")))?;
        NodeBuilder::new()
            .name(&node_name)
            .config(&self.config)
            .create::<Ipc>()
            .map_err(|e| RuntimeError::Iceoryx(format!("creating node '{name}': {e:?}")))
    }

    pub(crate) fn service_name(&self, spec: &ServiceSpec) -> Result<ServiceName, RuntimeError> {
        let name = format!("opengs/{}/{}", self.run_id, spec.name);
        ServiceName::new(&name)
            .map_err(|e| RuntimeError::Iceoryx(format!("service name '{name}': {e:?}")))
    }

    pub(crate) fn event_name(&self, spec: &ServiceSpec) -> Result<ServiceName, RuntimeError> {
        let name = format!("opengs/{}/{}/wake", self.run_id, spec.name);
        ServiceName::new(&name)
            .map_err(|e| RuntimeError::Iceoryx(format!("service name '{name}': {e:?}")))
    }

    /// Removes the resources of this run's dead nodes (a supervisor calls this
    /// after a stage died). Returns how many dead nodes were cleaned.
    pub fn cleanup_dead_nodes(&self) -> usize {
        let mut cleaned = 0;
        let result = Node::<Ipc>::list(&self.config, |state| {
            if let NodeState::Dead(view) = state {
                match view.try_remove_stale_resources() {
                    Ok(()) => cleaned += 1,
                    Err(e) => tracing::warn!("could not clean a dead node: {e:?}"),
                }
            }
            CallbackProgression::Continue
        });
        if let Err(e) = result {
            tracing::warn!("listing nodes for cleanup failed: {e:?}");
        }
        cleaned
    }

    /// Files this run still has in `/dev/shm` and the iceoryx2 root.
    pub fn leftover_files(&self) -> Vec<PathBuf> {
        leftover_files(&self.run_id)
    }

    /// Removes the run's iceoryx2 domain segment (node counter), which iceoryx2
    /// keeps by design. Call only when every process of the run has ended: the
    /// prefix is private to this run, so no one else can be using it.
    pub fn remove_domain_segment(&self) -> usize {
        let mut removed = 0;
        for path in self.leftover_files() {
            let is_domain = path
                .file_name()
                .is_some_and(|n| n.to_string_lossy().ends_with(".global_mgmt"));
            if is_domain && std::fs::remove_file(&path).is_ok() {
                removed += 1;
            }
        }
        removed
    }

    /// The processes whose iceoryx2 nodes of this run are alive, as "executable (pid N)"; a
    /// node this user may not inspect counts as alive, since it may be.
    pub fn alive_nodes(&self) -> Result<Vec<String>, RuntimeError> {
        let mut alive = Vec::new();
        Node::<Ipc>::list(&self.config, |state| {
            match state {
                NodeState::Alive(view) => alive.push(match view.details() {
                    Some(d) => format!("{} (pid {})", d.executable(), d.process_id()),
                    None => format!("node {}", view.id()),
                }),
                NodeState::Inaccessible(id) => alive.push(format!("node {id} (not accessible)")),
                NodeState::Dead(_) | NodeState::Undefined(_) => {}
            }
            CallbackProgression::Continue
        })
        .map_err(|e| {
            RuntimeError::Iceoryx(format!("listing the nodes of run {}: {e:?}", self.run_id))
        })?;
        Ok(alive)
    }

    /// Removes every file of this run: dead nodes' resources through iceoryx2 first, then
    /// whatever is left (the domain segment included) and the node folders that held them.
    /// Call only when no process of the run is alive (`alive_nodes` empty). Returns how
    /// many files were removed by hand.
    pub fn remove_leftovers(&self) -> Result<usize, CleanError> {
        self.cleanup_dead_nodes();
        let nodes_dir = iceoryx_root().join("nodes");
        let mut removed = 0;
        for path in self.leftover_files() {
            match std::fs::remove_file(&path) {
                Ok(()) => removed += 1,
                // Another cleaner (the supervisor's own exit, a second `opengs clean`) won.
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(source) => return Err(CleanError::Remove { path, source }),
            }
            // A node's folder is named by its node id alone; it goes once this emptied it.
            if let Some(dir) = path.parent().filter(|d| d.parent() == Some(&nodes_dir)) {
                let _ = std::fs::remove_dir(dir);
            }
        }
        Ok(removed)
    }
}

/// The iceoryx2 root folder (`/tmp/iceoryx2` by default).
fn iceoryx_root() -> PathBuf {
    PathBuf::from(Config::default().global.root_path().to_string())
}

/// Every file in `/dev/shm` and under the iceoryx2 root whose name starts with `ogs_`.
fn opengs_files() -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![PathBuf::from("/dev/shm"), iceoryx_root()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            // file_type() does not follow links: a link to elsewhere is never walked.
            let Ok(kind) = entry.file_type() else {
                continue;
            };
            if kind.is_dir() {
                stack.push(path);
            } else if entry.file_name().to_string_lossy().starts_with("ogs_") {
                found.push(path);
            }
        }
    }
    found
}

/// Files of run `run_id` left in `/dev/shm` and under the iceoryx2 root. A file whose
/// name shows it belongs to a longer run id (`ogs_a_1_…` is run `a_1`'s, not `a`'s) is not
/// counted.
pub fn leftover_files(run_id: &str) -> Vec<PathBuf> {
    let prefix = RunContext::prefix_of(run_id);
    let mut found: Vec<PathBuf> = opengs_files()
        .into_iter()
        .filter(|path| {
            let name = file_name(path);
            name.starts_with(&prefix) && run_id_of_file(&name).is_none_or(|id| id == run_id)
        })
        .collect();
    found.sort();
    found
}

/// Run ids that have files in `/dev/shm` or under the iceoryx2 root, read from the names.
pub fn runs_with_files() -> Vec<String> {
    let mut ids: Vec<String> = opengs_files()
        .iter()
        .filter_map(|path| run_id_of_file(&file_name(path)).map(str::to_string))
        .collect();
    ids.sort();
    ids.dedup();
    ids
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The run id in an iceoryx2 file name `ogs_<run id>_<iceoryx2 part>`. Run ids may hold
/// `_`, so the id is the longest valid one followed by a part iceoryx2 writes: a 40-digit
/// hex hash then `_` or `.`, a decimal id then `.`, or `node.`.
pub(crate) fn run_id_of_file(name: &str) -> Option<&str> {
    let rest = name.strip_prefix("ogs_")?;
    rest.match_indices('_')
        .map(|(i, _)| (&rest[..i], &rest[i + 1..]))
        .filter(|(id, part)| RunContext::valid_run_id(id) && is_iceoryx_part(part))
        .map(|(id, _)| id)
        .max_by_key(|id| id.len())
}

fn is_iceoryx_part(part: &str) -> bool {
    let bytes = part.as_bytes();
    let hex = bytes.len() > 40
        && bytes[..40].iter().all(|b| b.is_ascii_hexdigit())
        && matches!(bytes[40], b'_' | b'.');
    let digits = bytes.iter().take_while(|b| b.is_ascii_digit()).count();
    let decimal = digits > 0 && bytes.get(digits) == Some(&b'.');
    hex || decimal || part.starts_with("node.")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_ids_are_read_from_every_kind_of_iceoryx2_file() {
        let hash = "9204dd183d1c4d8e1ff592a30766ffa6765aa8b5";
        for (name, id) in [
            (
                format!("ogs_cx_a_1_{hash}_node.0_10_0.global_mgmt"),
                "cx_a_1",
            ),
            (format!("ogs_r1_{hash}_7130535752650238072__1.data"), "r1"),
            (format!("ogs_r1_{hash}_2376846_1584564.connection"), "r1"),
            (format!("ogs_r1_{hash}_47536908759.event_mgmt"), "r1"),
            (format!("ogs_r1_{hash}.service"), "r1"),
            ("ogs_a_12_34.event".to_string(), "a_12"),
            ("ogs_a_12_396140925263.node_monitor".to_string(), "a_12"),
            ("ogs_t9-x_node.details".to_string(), "t9-x"),
        ] {
            assert_eq!(run_id_of_file(&name), Some(id), "{name}");
        }
        assert_eq!(run_id_of_file("ogs_nothing_here"), None);
        assert_eq!(run_id_of_file("iox2_abc_node.details"), None);
    }
}
