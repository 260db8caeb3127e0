//! Per-stage latency records, percentile tables and Chrome traces.
//!
//! The supervisor feeds every telemetry record into a [`LatencyProfile`];
//! at the end of a run it writes `latency.json` and `trace.json` and prints
//! the table. `opengs profile RUN_DIR` reads `latency.json` back.

mod profile;
mod summary;
mod trace;

pub use profile::{LatencyProfile, StageSample};
pub use summary::{LatencyReport, Percentiles, StageLatency};
pub use trace::{overlapping_complete_events, ChromeTrace};
