//! The status a running supervisor reports to `opengs ctl status`.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct StageStatus {
    pub name: String,
    /// Which of the stage's processes (0 for the first; `replicas`, `opengs ctl scale`).
    #[serde(default)]
    pub replica: u32,
    /// The host it runs on, when not this supervisor's (shown from its telemetry).
    #[serde(default)]
    pub host: Option<String>,
    pub pid: Option<u32>,
    pub state: String,
    pub restarts: u32,
    pub processed: u64,
    pub last_seq: Option<u64>,
    #[serde(default)]
    pub kind: Option<String>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct PipelineStatus {
    pub run_id: String,
    pub out_dir: String,
    pub elapsed_s: f64,
    pub stages: Vec<StageStatus>,
    /// Poses received, and how many of them are lost frames (no verified pose).
    #[serde(default)]
    pub poses: usize,
    #[serde(default)]
    pub lost_frames: usize,
}

impl PipelineStatus {
    pub fn table(&self) -> String {
        let mut s = format!(
            "run {}  ({:.1} s)  {}\nposes {}, lost frames {}\n",
            self.run_id, self.elapsed_s, self.out_dir, self.poses, self.lost_frames
        );
        s.push_str(&format!(
            "{:<12} {:<12} {:>8} {:<11} {:>8} {:>10} {:>9}\n",
            "stage", "kind", "pid", "state", "restarts", "processed", "last seq"
        ));
        for st in &self.stages {
            // A stage with several processes lists each as the latency profile does: NAME#N.
            let replicated = self.stages.iter().filter(|o| o.name == st.name).count() > 1;
            let mut name = match replicated {
                true => format!("{}#{}", st.name, st.replica),
                false => st.name.clone(),
            };
            if let Some(host) = &st.host {
                name.push_str(&format!("@{host}"));
            }
            s.push_str(&format!(
                "{:<12} {:<12} {:>8} {:<11} {:>8} {:>10} {:>9}\n",
                name,
                st.kind.as_deref().unwrap_or("-"),
                st.pid.map_or("-".into(), |p| p.to_string()),
                st.state,
                st.restarts,
                st.processed,
                st.last_seq.map_or("-".into(), |p| p.to_string())
            ));
        }
        s
    }
}
