use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

use serde::{Deserialize, Serialize};

/// Percentiles of one latency distribution, in microseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Percentiles {
    pub count: u64,
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub max_us: f64,
}

/// One stage's latency: the total (queue wait + processing) at top level, plus its parts.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StageLatency {
    #[serde(flatten)]
    pub total: Percentiles,
    pub queue_wait: Percentiles,
    pub processing: Percentiles,
    pub dropped: u64,
}

/// The content of `latency.json`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LatencyReport {
    pub stages: BTreeMap<String, StageLatency>,
    /// Sensor publish → last stage done, per frame.
    pub end_to_end: Percentiles,
}

#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("{path}: {cause}")]
    Io { path: String, cause: std::io::Error },
    #[error("{path}: not a latency report: {cause}")]
    Parse {
        path: String,
        cause: serde_json::Error,
    },
}

impl LatencyReport {
    pub fn write(&self, path: &Path) -> Result<(), ReportError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| ReportError::Parse {
            path: path.display().to_string(),
            cause: e,
        })?;
        std::fs::write(path, text).map_err(|e| ReportError::Io {
            path: path.display().to_string(),
            cause: e,
        })
    }

    pub fn read(path: &Path) -> Result<Self, ReportError> {
        let text = std::fs::read_to_string(path).map_err(|e| ReportError::Io {
            path: path.display().to_string(),
            cause: e,
        })?;
        serde_json::from_str(&text).map_err(|e| ReportError::Parse {
            path: path.display().to_string(),
            cause: e,
        })
    }

    /// The table printed at the end of a run and by `opengs profile`.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{:<14} {:>7} {:>9} {:>9} {:>9} {:>9}   {:>9} {:>9} {:>7}",
            "stage",
            "count",
            "p50 ms",
            "p90 ms",
            "p99 ms",
            "max ms",
            "wait p50",
            "proc p50",
            "dropped"
        );
        let row = |s: &mut String, name: &str, p: &Percentiles, extra: Option<&StageLatency>| {
            let _ = write!(
                s,
                "{:<14} {:>7} {:>9.3} {:>9.3} {:>9.3} {:>9.3}",
                name,
                p.count,
                p.p50_us / 1e3,
                p.p90_us / 1e3,
                p.p99_us / 1e3,
                p.max_us / 1e3
            );
            if let Some(st) = extra {
                let _ = write!(
                    s,
                    "   {:>9.3} {:>9.3} {:>7}",
                    st.queue_wait.p50_us / 1e3,
                    st.processing.p50_us / 1e3,
                    st.dropped
                );
            }
            s.push('\n');
        };
        for (name, st) in &self.stages {
            row(&mut s, name, &st.total, Some(st));
        }
        row(&mut s, "end-to-end", &self.end_to_end, None);
        s
    }
}
