use std::collections::BTreeMap;

use hdrhistogram::Histogram;

use crate::{LatencyReport, Percentiles, StageLatency};

/// One processed message as a stage reported it (CLOCK_MONOTONIC ns).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageSample {
    pub seq: u64,
    /// When the sensor published the source frame.
    pub origin_ns: u64,
    /// When the input was sent upstream.
    pub input_sent_ns: u64,
    pub start_ns: u64,
    pub end_ns: u64,
}

struct StageHistograms {
    total: Histogram<u64>,
    queue_wait: Histogram<u64>,
    processing: Histogram<u64>,
    dropped: u64,
}

fn histogram() -> Histogram<u64> {
    // 1 µs .. 1 h at 3 significant digits; the bounds are constants, so this cannot fail.
    Histogram::new_with_bounds(1, 3_600_000_000, 3).expect("constant histogram bounds are valid")
}

impl StageHistograms {
    fn new() -> Self {
        Self {
            total: histogram(),
            queue_wait: histogram(),
            processing: histogram(),
            dropped: 0,
        }
    }
}

/// Aggregates stage samples into per-stage and end-to-end percentiles.
pub struct LatencyProfile {
    stages: BTreeMap<String, StageHistograms>,
    end_to_end: Histogram<u64>,
    /// The stage whose completion ends a frame's journey (e.g. `tracker`).
    terminal_stage: Option<String>,
}

fn us(ns: u64) -> u64 {
    (ns / 1000).max(1)
}

fn percentiles(h: &Histogram<u64>) -> Percentiles {
    if h.is_empty() {
        return Percentiles::default();
    }
    Percentiles {
        count: h.len(),
        p50_us: h.value_at_quantile(0.50) as f64,
        p90_us: h.value_at_quantile(0.90) as f64,
        p99_us: h.value_at_quantile(0.99) as f64,
        max_us: h.max() as f64,
    }
}

impl LatencyProfile {
    pub fn new(terminal_stage: Option<&str>) -> Self {
        Self {
            stages: BTreeMap::new(),
            end_to_end: histogram(),
            terminal_stage: terminal_stage.map(str::to_string),
        }
    }

    pub fn record(&mut self, stage: &str, s: &StageSample) {
        let h = self
            .stages
            .entry(stage.to_string())
            .or_insert_with(StageHistograms::new);
        let wait = s.start_ns.saturating_sub(s.input_sent_ns);
        let proc = s.end_ns.saturating_sub(s.start_ns);
        h.queue_wait.saturating_record(us(wait));
        h.processing.saturating_record(us(proc));
        h.total.saturating_record(us(wait + proc));
        if self.terminal_stage.as_deref() == Some(stage) && s.origin_ns > 0 {
            self.end_to_end
                .saturating_record(us(s.end_ns.saturating_sub(s.origin_ns)));
        }
    }

    pub fn record_drop(&mut self, stage: &str) {
        self.stages
            .entry(stage.to_string())
            .or_insert_with(StageHistograms::new)
            .dropped += 1;
    }

    pub fn count(&self, stage: &str) -> u64 {
        self.stages.get(stage).map_or(0, |h| h.total.len())
    }

    pub fn report(&self) -> LatencyReport {
        LatencyReport {
            stages: self
                .stages
                .iter()
                .map(|(name, h)| {
                    (
                        name.clone(),
                        StageLatency {
                            total: percentiles(&h.total),
                            queue_wait: percentiles(&h.queue_wait),
                            processing: percentiles(&h.processing),
                            dropped: h.dropped,
                        },
                    )
                })
                .collect(),
            end_to_end: percentiles(&self.end_to_end),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_known_samples() {
        let mut p = LatencyProfile::new(Some("tracker"));
        // 100 samples: queue wait i µs, processing 2i µs, for i = 1..=100.
        for i in 1..=100u64 {
            let s = StageSample {
                seq: i,
                origin_ns: 1_000_000,
                input_sent_ns: 2_000_000,
                start_ns: 2_000_000 + i * 1000,
                end_ns: 2_000_000 + 3 * i * 1000,
            };
            p.record("tracker", &s);
        }
        p.record_drop("tracker");
        let r = p.report();
        let t = &r.stages["tracker"];
        assert_eq!(t.total.count, 100);
        assert_eq!(t.queue_wait.p50_us, 50.0);
        assert_eq!(t.processing.p50_us, 100.0);
        assert_eq!(t.total.p90_us, 270.0);
        assert_eq!(t.total.max_us, 300.0);
        assert_eq!(t.dropped, 1);
        // end to end = 1 ms origin offset + 3i µs.
        assert_eq!(r.end_to_end.count, 100);
        assert_eq!(r.end_to_end.max_us, 1300.0);
        assert!(r.table().contains("tracker"));
    }

    #[test]
    fn report_json_round_trip() {
        let mut p = LatencyProfile::new(None);
        p.record(
            "sensor",
            &StageSample {
                seq: 0,
                origin_ns: 0,
                input_sent_ns: 0,
                start_ns: 0,
                end_ns: 5_000,
            },
        );
        let r = p.report();
        let dir = std::env::temp_dir().join(format!("opengs-telemetry-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let path = dir.join("latency.json");
        r.write(&path).expect("write");
        assert_eq!(LatencyReport::read(&path).expect("read"), r);
        let text = std::fs::read_to_string(&path).expect("read text");
        // The documented flat fields are there per stage.
        for key in ["count", "p50_us", "p90_us", "p99_us", "max_us"] {
            assert!(text.contains(key), "{key} missing");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
