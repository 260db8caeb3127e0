//! The hand-over between the viewer's IPC loop and its logging thread. The loop must never
//! wait on the logging side (a slow disk or network would stall it, its subscriptions would
//! overflow and its heartbeats stop), so it hands batches over a bounded channel without
//! blocking: when the logger is behind, bulk records (images, point clouds) are dropped and
//! counted, and small ones (poses, scalars, names) wait in a bounded backlog for the next
//! batch. The logging thread feeds a [`RecordSink`] (Rerun, with the `rerun` feature).

use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::thread::JoinHandle;
use std::time::Duration;

use crate::record::Record;

/// Where records end up.
pub trait RecordSink: Send + 'static {
    /// Logs one record; an error is counted and reported, and logging goes on.
    fn log(&mut self, record: &Record) -> anyhow::Result<()>;
    /// Writes out what is buffered, waiting at most `timeout`.
    fn flush(&mut self, timeout: Duration) -> anyhow::Result<()>;
}

/// Batches in flight between the loop and the logging thread.
const CHANNEL_BATCHES: usize = 4;
/// Small records kept for a later batch while the logger is behind (then the oldest go).
const BACKLOG_MAX: usize = 20_000;
/// Errors of the sink reported one by one; later ones are only counted.
const REPORTED_ERRORS: u64 = 5;

/// What one hand-over did.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Handed {
    pub sent: usize,
    pub dropped: usize,
}

/// What the logging thread did.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct LoggerReport {
    pub logged: u64,
    pub errors: u64,
    pub flushed: bool,
}

/// The loop's end of the hand-over.
pub struct Outbox {
    tx: Option<SyncSender<Vec<Record>>>,
    backlog: Vec<Record>,
    /// Records dropped so far (bulk ones while behind, small ones past the backlog).
    pub dropped: u64,
}

/// Starts the logging thread on `sink`; it flushes with `flush_timeout` when the outbox closes.
pub fn spawn_logger<S: RecordSink>(
    sink: S,
    flush_timeout: Duration,
) -> std::io::Result<(Outbox, JoinHandle<LoggerReport>)> {
    let (tx, rx) = sync_channel(CHANNEL_BATCHES);
    let handle = std::thread::Builder::new()
        .name("viewer-log".into())
        .spawn(move || log_batches(sink, rx, flush_timeout))?;
    Ok((
        Outbox {
            tx: Some(tx),
            backlog: Vec::new(),
            dropped: 0,
        },
        handle,
    ))
}

fn log_batches<S: RecordSink>(
    mut sink: S,
    rx: Receiver<Vec<Record>>,
    flush_timeout: Duration,
) -> LoggerReport {
    let mut report = LoggerReport::default();
    for batch in rx {
        for record in &batch {
            match sink.log(record) {
                Ok(()) => report.logged += 1,
                Err(e) => {
                    report.errors += 1;
                    if report.errors <= REPORTED_ERRORS {
                        tracing::warn!("logging {}: {e:#}", record.path);
                    }
                }
            }
        }
    }
    match sink.flush(flush_timeout) {
        Ok(()) => report.flushed = true,
        Err(e) => tracing::warn!("flushing the recording: {e:#}"),
    }
    report
}

impl Outbox {
    /// Hands `batch` (after the backlog) to the logging thread without waiting. Fails only
    /// when the logging thread is gone.
    pub fn send(&mut self, batch: Vec<Record>) -> anyhow::Result<Handed> {
        let Some(tx) = &self.tx else {
            anyhow::bail!("the recording is closed");
        };
        if batch.is_empty() && self.backlog.is_empty() {
            return Ok(Handed::default());
        }
        let mut all = std::mem::take(&mut self.backlog);
        all.extend(batch);
        let count = all.len();
        match tx.try_send(all) {
            Ok(()) => Ok(Handed {
                sent: count,
                dropped: 0,
            }),
            Err(TrySendError::Full(all)) => {
                let before = all.len();
                let mut kept: Vec<Record> =
                    all.into_iter().filter(|r| !r.item.droppable()).collect();
                if kept.len() > BACKLOG_MAX {
                    kept.drain(..kept.len() - BACKLOG_MAX);
                }
                let dropped = before - kept.len();
                self.backlog = kept;
                self.dropped += dropped as u64;
                Ok(Handed { sent: 0, dropped })
            }
            Err(TrySendError::Disconnected(_)) => {
                self.tx = None;
                anyhow::bail!("the logging thread has stopped")
            }
        }
    }

    /// Hands over the backlog (waiting for room, up to `timeout`) and closes the channel:
    /// the logging thread logs what it has, flushes and ends.
    pub fn close(&mut self, timeout: Duration) {
        let Some(tx) = self.tx.take() else { return };
        let mut rest = std::mem::take(&mut self.backlog);
        let deadline = std::time::Instant::now() + timeout;
        while !rest.is_empty() {
            match tx.try_send(rest) {
                Ok(()) => break,
                Err(TrySendError::Full(back)) if std::time::Instant::now() < deadline => {
                    rest = back;
                    std::thread::sleep(Duration::from_millis(5));
                }
                Err(TrySendError::Full(back)) => {
                    self.dropped += back.len() as u64;
                    break;
                }
                Err(TrySendError::Disconnected(_)) => break,
            }
        }
    }

    /// Small records waiting for the logger.
    pub fn backlog(&self) -> usize {
        self.backlog.len()
    }
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use super::*;
    use crate::record::{Item, Time};

    /// A sink that keeps paths, and can be held back by a lock the test owns.
    #[derive(Clone, Default)]
    struct Keep {
        paths: Arc<Mutex<Vec<String>>>,
        gate: Arc<Mutex<()>>,
        fail_on: Option<&'static str>,
    }

    impl RecordSink for Keep {
        fn log(&mut self, record: &Record) -> anyhow::Result<()> {
            let _open = self.gate.lock().map_err(|_| anyhow::anyhow!("gate"))?;
            if self.fail_on == Some(record.path.as_str()) {
                anyhow::bail!("refused");
            }
            self.paths
                .lock()
                .map_err(|_| anyhow::anyhow!("paths"))?
                .push(record.path.clone());
            Ok(())
        }

        fn flush(&mut self, _timeout: Duration) -> anyhow::Result<()> {
            Ok(())
        }
    }

    fn small(path: &str) -> Record {
        Record::new(path, Time::LogTime, Item::Scalar(1.0))
    }

    fn big(path: &str) -> Record {
        Record::new(
            path,
            Time::LogTime,
            Item::Rgb {
                width: 1,
                height: 1,
                rgb: vec![0; 3],
            },
        )
    }

    #[test]
    fn everything_arrives_in_order_when_the_logger_keeps_up() {
        let sink = Keep::default();
        let (mut out, handle) = spawn_logger(sink.clone(), Duration::from_secs(1)).expect("spawn");
        // As many batches as the channel holds: none can find it full, however slow the
        // logging thread is to start.
        for i in 0..CHANNEL_BATCHES {
            let batch = (0..5)
                .flat_map(|j| [small(&format!("s{i}.{j}")), big(&format!("b{i}.{j}"))])
                .collect();
            let h = out.send(batch).expect("send");
            assert_eq!(
                h,
                Handed {
                    sent: 10,
                    dropped: 0
                },
                "batch {i}"
            );
        }
        out.close(Duration::from_secs(1));
        let report = handle.join().expect("logger");
        let all = 10 * CHANNEL_BATCHES as u64;
        assert_eq!(
            report,
            LoggerReport {
                logged: all,
                errors: 0,
                flushed: true
            }
        );
        let paths = sink.paths.lock().expect("paths").clone();
        let want: Vec<String> = (0..CHANNEL_BATCHES)
            .flat_map(|i| (0..5).flat_map(move |j| [format!("s{i}.{j}"), format!("b{i}.{j}")]))
            .collect();
        assert_eq!(paths, want);
    }

    #[test]
    fn a_stalled_logger_costs_bulk_records_never_small_ones_and_never_blocks() {
        let sink = Keep::default();
        let gate = Arc::clone(&sink.gate);
        let held = gate.lock().expect("gate");
        let (mut out, handle) = spawn_logger(sink.clone(), Duration::from_secs(1)).expect("spawn");
        let started = std::time::Instant::now();
        let mut dropped = 0;
        for i in 0..50 {
            dropped += out
                .send(vec![small(&format!("s{i}")), big(&format!("b{i}"))])
                .expect("send")
                .dropped;
        }
        assert!(
            started.elapsed() < Duration::from_secs(1),
            "send never waits"
        );
        assert!(dropped > 0 && out.backlog() > 0);
        assert_eq!(out.dropped, dropped as u64);
        drop(held);
        out.close(Duration::from_secs(5));
        let report = handle.join().expect("logger");
        let paths = sink.paths.lock().expect("paths").clone();
        let smalls: Vec<&String> = paths.iter().filter(|p| p.starts_with('s')).collect();
        assert_eq!(smalls.len(), 50, "every small record arrives");
        let bigs = paths.len() - smalls.len();
        assert_eq!(
            bigs + dropped,
            50,
            "every bulk record arrives or is counted"
        );
        assert_eq!(report.logged as usize, paths.len());
        // Small records keep their order, whatever was dropped between them.
        let order: Vec<usize> = smalls.iter().filter_map(|p| p[1..].parse().ok()).collect();
        assert!(order.windows(2).all(|w| w[0] < w[1]), "{order:?}");
    }

    #[test]
    fn sink_errors_are_counted_and_logging_goes_on_and_a_dead_logger_is_an_error() {
        let sink = Keep {
            fail_on: Some("bad"),
            ..Keep::default()
        };
        let (mut out, handle) = spawn_logger(sink.clone(), Duration::from_secs(1)).expect("spawn");
        out.send(vec![small("a"), small("bad"), small("b")])
            .expect("send");
        out.close(Duration::from_secs(1));
        let report = handle.join().expect("logger");
        assert_eq!((report.logged, report.errors), (2, 1));
        assert!(out.send(vec![small("late")]).is_err(), "closed");

        let (tx, rx) = sync_channel::<Vec<Record>>(1);
        drop(rx);
        let mut orphan = Outbox {
            tx: Some(tx),
            backlog: Vec::new(),
            dropped: 0,
        };
        let err = orphan.send(vec![small("x")]).expect_err("logger gone");
        assert!(err.to_string().contains("stopped"), "{err}");
    }
}
