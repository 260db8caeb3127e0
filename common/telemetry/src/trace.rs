//! A Chrome trace-event file (`trace.json`, opens in Perfetto or chrome://tracing) of every
//! message a stage processed:
//! - processing as complete events (`X`) named `"{stage} process"` on thread tracks of the
//!   stage's process; a stage processes one message at a time, and where two spans still
//!   overlap (clock skew, a stage with two loops) the later one goes to a second track, so
//!   no two complete events on one track ever overlap (the format forbids it and Perfetto
//!   drops such slices);
//! - the queue wait before it as an async slice (`b`/`e`, id = seq) named `"{stage} wait"`:
//!   waits of successive messages may overlap each other and the processing;
//! - a flow per frame seq from each stage's processing to the next stage's (sensor → tracker
//!   → mapper → segmenter → consensus), so one frame can be followed through the pipeline;
//! - process and thread names as metadata.
//!
//! Names carry no seq, so Perfetto aggregates them; the seq is in `args`.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use serde_json::{json, Value};

use crate::StageSample;

/// Events kept at most; a long run keeps its first part rather than growing without bound.
const MAX_EVENTS: usize = 500_000;

/// One recorded message.
#[derive(Debug, Clone)]
struct Recorded {
    stage: String,
    pid: u32,
    sample: StageSample,
}

/// The trace of a run, written at its end.
#[derive(Default)]
pub struct ChromeTrace {
    events: Vec<Recorded>,
    origin_ns: Option<u64>,
}

impl ChromeTrace {
    pub fn record(&mut self, stage: &str, pid: u32, s: &StageSample) {
        if self.events.len() >= MAX_EVENTS {
            return;
        }
        let first = s.input_sent_ns.min(s.start_ns);
        self.origin_ns = Some(self.origin_ns.map_or(first, |o| o.min(first)));
        self.events.push(Recorded {
            stage: stage.to_string(),
            pid,
            sample: *s,
        });
    }

    pub fn len(&self) -> usize {
        self.events.len()
    }

    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
    }

    /// The trace events, in the order they are written.
    fn trace_events(&self) -> Vec<Value> {
        let origin = self.origin_ns.unwrap_or(0);
        let us = |ns: u64| ns.saturating_sub(origin) as f64 / 1e3;
        let tracks = assign_tracks(&self.events);
        let mut out = Vec::with_capacity(3 * self.events.len() + 16);
        // Metadata: one name per process and per track.
        let mut named: BTreeMap<(u32, u32), &str> = BTreeMap::new();
        for (r, &tid) in self.events.iter().zip(&tracks) {
            named.entry((r.pid, tid)).or_insert(&r.stage);
        }
        let mut processes = std::collections::BTreeSet::new();
        for (&(pid, tid), stage) in &named {
            if processes.insert(pid) {
                out.push(
                    json!({"ph": "M", "name": "process_name", "pid": pid, "tid": 0,
                    "args": {"name": format!("{stage} (pid {pid})")}}),
                );
            }
            let track = match tid {
                1 => format!("{stage} process"),
                n => format!("{stage} process ({n})"),
            };
            out.push(
                json!({"ph": "M", "name": "thread_name", "pid": pid, "tid": tid,
                "args": {"name": track}}),
            );
        }
        for (r, &tid) in self.events.iter().zip(&tracks) {
            let s = &r.sample;
            let (stage, pid) = (r.stage.as_str(), r.pid);
            if s.start_ns > s.input_sent_ns {
                let wait = format!("{stage} wait");
                let id = format!("{stage}-{}", s.seq);
                for (ph, ts) in [("b", s.input_sent_ns), ("e", s.start_ns)] {
                    out.push(json!({"ph": ph, "cat": stage, "name": wait, "id": id,
                        "ts": us(ts), "pid": pid, "tid": tid, "args": {"seq": s.seq}}));
                }
            }
            out.push(
                json!({"ph": "X", "cat": stage, "name": format!("{stage} process"),
                "ts": us(s.start_ns), "dur": s.end_ns.saturating_sub(s.start_ns) as f64 / 1e3,
                "pid": pid, "tid": tid, "args": {"seq": s.seq}}),
            );
        }
        out.extend(flows(&self.events, &tracks, us));
        out
    }

    /// Writes `{"traceEvents": [...], "otherData": {"origin_ns": "..."}}`.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        out.write_all(b"{\"traceEvents\":[\n")?;
        for (i, ev) in self.trace_events().iter().enumerate() {
            if i > 0 {
                out.write_all(b",\n")?;
            }
            serde_json::to_writer(&mut out, ev).map_err(std::io::Error::other)?;
        }
        // The clock reading (CLOCK_MONOTONIC ns, as a string: exact) that ts 0 stands for, so
        // a tool can place its own events (a `ctl scale` request) on the trace's time line.
        let origin = self.origin_ns.unwrap_or(0);
        write!(
            out,
            "\n],\"displayTimeUnit\":\"ms\",\"otherData\":{{\"origin_ns\":\"{origin}\"}}}}\n"
        )?;
        out.flush()
    }
}

/// The thread track (tid ≥ 1) of each processing span: per process, in start order, the first
/// track whose last span has ended (interval partitioning, so spans on a track never overlap).
fn assign_tracks(events: &[Recorded]) -> Vec<u32> {
    let mut order: Vec<usize> = (0..events.len()).collect();
    order.sort_by_key(|&i| (events[i].pid, events[i].sample.start_ns));
    let mut tracks = vec![1u32; events.len()];
    // Per process: the end of the last span on each of its tracks.
    let mut ends: BTreeMap<u32, Vec<u64>> = BTreeMap::new();
    for i in order {
        let s = &events[i].sample;
        let end = s.end_ns.max(s.start_ns);
        let busy = ends.entry(events[i].pid).or_default();
        let free = busy.iter().position(|&e| e <= s.start_ns);
        let t = match free {
            Some(t) => t,
            None => {
                busy.push(0);
                busy.len() - 1
            }
        };
        busy[t] = end;
        tracks[i] = t as u32 + 1;
    }
    tracks
}

/// Flow arrows per seq, from each processing span to the next one (in start order) of the
/// same frame in another stage.
fn flows(events: &[Recorded], tracks: &[u32], us: impl Fn(u64) -> f64) -> Vec<Value> {
    let mut by_seq: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
    for (i, r) in events.iter().enumerate() {
        by_seq.entry(r.sample.seq).or_default().push(i);
    }
    let mut out = Vec::new();
    let mut next_id = 0u64;
    for (seq, mut spans) in by_seq {
        spans.sort_by_key(|&i| events[i].sample.start_ns);
        for pair in spans.windows(2) {
            let (a, b) = (&events[pair[0]], &events[pair[1]]);
            if a.stage == b.stage {
                continue;
            }
            next_id += 1;
            // Each end binds to the span that encloses its timestamp on its track.
            out.push(
                json!({"ph": "s", "cat": "frame", "name": "frame", "id": next_id,
                "ts": us(a.sample.start_ns), "pid": a.pid, "tid": tracks[pair[0]],
                "args": {"seq": seq}}),
            );
            out.push(
                json!({"ph": "f", "bp": "e", "cat": "frame", "name": "frame",
                "id": next_id, "ts": us(b.sample.start_ns), "pid": b.pid,
                "tid": tracks[pair[1]], "args": {"seq": seq}}),
            );
        }
    }
    out
}

/// Complete events (`X`) of a trace file's events that overlap another on the same track
/// (pid, tid), as (earlier, later) indices; empty for a valid trace.
pub fn overlapping_complete_events(events: &[Value]) -> Vec<(usize, usize)> {
    /// Start, end (µs) and index of a complete event.
    type Span = (f64, f64, usize);
    let mut by_track: BTreeMap<(u64, u64), Vec<Span>> = BTreeMap::new();
    for (i, e) in events.iter().enumerate() {
        if e["ph"] != "X" {
            continue;
        }
        let (Some(pid), Some(tid), Some(ts), Some(dur)) = (
            e["pid"].as_u64(),
            e["tid"].as_u64(),
            e["ts"].as_f64(),
            e["dur"].as_f64(),
        ) else {
            continue;
        };
        by_track
            .entry((pid, tid))
            .or_default()
            .push((ts, ts + dur, i));
    }
    let mut bad = Vec::new();
    for spans in by_track.values_mut() {
        spans.sort_by(|a, b| a.0.total_cmp(&b.0));
        for w in spans.windows(2) {
            // Touching is fine; starting before the previous one ends is not.
            if w[1].0 < w[0].1 {
                bad.push((w[0].2, w[1].2));
            }
        }
    }
    bad
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(seq: u64, sent_us: u64, start_us: u64, end_us: u64) -> StageSample {
        StageSample {
            seq,
            origin_ns: 0,
            input_sent_ns: sent_us * 1000,
            start_ns: start_us * 1000,
            end_ns: end_us * 1000,
        }
    }

    fn events_of(t: &ChromeTrace) -> Vec<Value> {
        let path = std::env::temp_dir().join(format!(
            "opengs-trace-{}-{}.json",
            std::process::id(),
            t.len()
        ));
        t.write(&path).expect("write");
        let v: Value =
            serde_json::from_str(&std::fs::read_to_string(&path).expect("read")).expect("json");
        std::fs::remove_file(&path).ok();
        v["traceEvents"].as_array().expect("array").clone()
    }

    #[test]
    fn the_file_says_which_clock_reading_ts_zero_is() {
        let mut t = ChromeTrace::default();
        t.record("segmenter", 5, &sample(3, 250, 260, 2260));
        t.record("consensus", 6, &sample(3, 2270, 2270, 2300));
        let path = std::env::temp_dir().join(format!("opengs-origin-{}.json", std::process::id()));
        t.write(&path).expect("write");
        let v: Value =
            serde_json::from_str(&std::fs::read_to_string(&path).expect("read")).expect("json");
        std::fs::remove_file(&path).ok();
        assert_eq!(v["otherData"]["origin_ns"], "250000");
        let seg = v["traceEvents"]
            .as_array()
            .expect("array")
            .iter()
            .find(|e| e["ph"] == "X" && e["cat"] == "segmenter")
            .expect("segmenter span")
            .clone();
        // ts 10 µs after the origin: 260 µs on the clock.
        assert_eq!(
            (seg["ts"].as_f64(), seg["dur"].as_f64()),
            (Some(10.0), Some(2000.0))
        );
    }

    #[test]
    fn spans_waits_names_and_flows() {
        let mut t = ChromeTrace::default();
        t.record("sensor", 5, &sample(3, 0, 0, 1));
        t.record("tracker", 7, &sample(3, 1, 3, 10));
        let ev = events_of(&t);
        let of = |ph: &str, name: &str| -> Vec<&Value> {
            ev.iter()
                .filter(|e| e["ph"] == ph && e["name"] == name)
                .collect()
        };
        let process = of("X", "tracker process");
        assert_eq!(process.len(), 1);
        assert_eq!(
            (process[0]["ts"].as_f64(), process[0]["dur"].as_f64()),
            (Some(3.0), Some(7.0))
        );
        assert_eq!(process[0]["args"]["seq"], 3);
        let (b, e) = (of("b", "tracker wait"), of("e", "tracker wait"));
        assert_eq!(
            (b[0]["ts"].as_f64(), e[0]["ts"].as_f64()),
            (Some(1.0), Some(3.0))
        );
        assert_eq!(b[0]["id"], e[0]["id"]);
        // One flow from the sensor's span to the tracker's.
        let (s, f) = (of("s", "frame"), of("f", "frame"));
        assert_eq!((s.len(), f.len()), (1, 1));
        assert_eq!(
            (s[0]["pid"].as_u64(), f[0]["pid"].as_u64()),
            (Some(5), Some(7))
        );
        let names: Vec<&Value> = ev.iter().filter(|e| e["ph"] == "M").collect();
        assert!(names
            .iter()
            .any(|m| m["name"] == "process_name" && m["args"]["name"] == "tracker (pid 7)"));
    }

    #[test]
    fn overlapping_spans_of_one_process_go_to_separate_tracks() {
        let mut t = ChromeTrace::default();
        // Message 2 starts while message 1 is still processed (two loops in one process),
        // message 3 after both.
        t.record("mapper", 9, &sample(1, 0, 10, 50));
        t.record("mapper", 9, &sample(2, 0, 20, 30));
        t.record("mapper", 9, &sample(3, 0, 60, 70));
        let ev = events_of(&t);
        assert_eq!(
            overlapping_complete_events(&ev),
            Vec::<(usize, usize)>::new()
        );
        let tid_of = |seq: u64| {
            ev.iter()
                .find(|e| e["ph"] == "X" && e["args"]["seq"] == seq)
                .and_then(|e| e["tid"].as_u64())
        };
        assert_eq!(
            (tid_of(1), tid_of(2), tid_of(3)),
            (Some(1), Some(2), Some(1))
        );
        // The checker itself sees overlaps when they are there.
        let mut bad = ev.clone();
        for e in bad.iter_mut() {
            if e["ph"] == "X" {
                e["tid"] = json!(1);
            }
        }
        assert_eq!(overlapping_complete_events(&bad).len(), 1);
    }
}
