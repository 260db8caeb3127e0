use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use serde::Serialize;

use crate::StageSample;

/// Events kept at most; a long run keeps its first part rather than growing without bound.
const MAX_EVENTS: usize = 500_000;

#[derive(Serialize)]
struct Event<'a> {
    name: String,
    cat: &'a str,
    ph: &'static str,
    ts: f64,
    dur: f64,
    pid: u32,
    tid: u32,
    args: BTreeMap<&'static str, u64>,
}

/// A Chrome trace-event file (opens in Perfetto / chrome://tracing).
#[derive(Default)]
pub struct ChromeTrace {
    events: Vec<(String, u32, StageSample)>,
    origin_ns: Option<u64>,
}

impl ChromeTrace {
    pub fn record(&mut self, stage: &str, pid: u32, s: &StageSample) {
        if self.events.len() >= MAX_EVENTS {
            return;
        }
        let first = s.input_sent_ns.min(s.start_ns);
        self.origin_ns = Some(self.origin_ns.map_or(first, |o| o.min(first)));
        self.events.push((stage.to_string(), pid, *s));
    }

    pub fn len(&self) -> usize {
        self.events.len()
    }

    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
    }

    /// Writes `{"traceEvents": [...]}`: per message a queue-wait span and a processing span.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let origin = self.origin_ns.unwrap_or(0);
        let to_us = |ns: u64| ns.saturating_sub(origin) as f64 / 1e3;
        let mut tids: BTreeMap<&str, u32> = BTreeMap::new();
        for (stage, _, _) in &self.events {
            let n = tids.len() as u32;
            tids.entry(stage).or_insert(n + 1);
        }
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        out.write_all(b"{\"traceEvents\":[\n")?;
        let mut first = true;
        for (stage, pid, s) in &self.events {
            let tid = tids[stage.as_str()];
            let args: BTreeMap<&'static str, u64> = [("seq", s.seq)].into_iter().collect();
            let spans = [
                ("wait", s.input_sent_ns, s.start_ns),
                ("process", s.start_ns, s.end_ns),
            ];
            for (kind, a, b) in spans {
                if b <= a && kind == "wait" {
                    continue;
                }
                let ev = Event {
                    name: format!("{stage} {kind} #{}", s.seq),
                    cat: stage,
                    ph: "X",
                    ts: to_us(a),
                    dur: (b.saturating_sub(a)) as f64 / 1e3,
                    pid: *pid,
                    tid,
                    args: args.clone(),
                };
                if !first {
                    out.write_all(b",\n")?;
                }
                first = false;
                serde_json::to_writer(&mut out, &ev).map_err(std::io::Error::other)?;
            }
        }
        out.write_all(b"\n],\"displayTimeUnit\":\"ms\"}\n")?;
        out.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trace_is_valid_json_with_spans() {
        let mut t = ChromeTrace::default();
        t.record(
            "tracker",
            7,
            &StageSample {
                seq: 3,
                origin_ns: 0,
                input_sent_ns: 1_000,
                start_ns: 3_000,
                end_ns: 10_000,
            },
        );
        let path = std::env::temp_dir().join(format!("opengs-trace-{}.json", std::process::id()));
        t.write(&path).expect("write");
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).expect("read")).expect("json");
        let events = v["traceEvents"].as_array().expect("array");
        assert_eq!(events.len(), 2);
        assert_eq!(events[1]["ts"], 2.0);
        assert_eq!(events[1]["dur"], 7.0);
        assert_eq!(events[0]["dur"], 2.0);
        std::fs::remove_file(&path).ok();
    }
}
