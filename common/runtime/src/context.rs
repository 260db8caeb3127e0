use std::path::PathBuf;

use iceoryx2::config::Config;
use iceoryx2::prelude::*;
use opengs_ipc_schema::ServiceSpec;

use crate::{Ipc, RuntimeError};

/// Everything a process needs to join one run: the run id and the iceoryx2
/// config whose file prefix isolates this run's shared memory from any other.
#[derive(Clone)]
pub struct RunContext {
    run_id: String,
    config: Config,
}

impl RunContext {
    pub fn new(run_id: &str) -> Result<Self, RuntimeError> {
        let valid = !run_id.is_empty()
            && run_id.len() <= 40
            && run_id
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
        if !valid {
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
}

/// Files of run `run_id` left in `/dev/shm` and under the iceoryx2 root.
pub fn leftover_files(run_id: &str) -> Vec<PathBuf> {
    let prefix = RunContext::prefix_of(run_id);
    let root = Config::default().global.root_path().to_string();
    let mut found = Vec::new();
    let mut stack = vec![PathBuf::from("/dev/shm"), PathBuf::from(root)];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if entry.file_name().to_string_lossy().starts_with(&prefix) {
                found.push(path);
            }
        }
    }
    found.sort();
    found
}
