use std::cell::Cell;
use std::time::{Duration, Instant};

use iceoryx2::prelude::Node;
use opengs_ipc_schema::service::TELEMETRY;
use opengs_ipc_schema::{now_ns, MessageKind, Stamp, TelemetryEvent, TelemetryHeader};

use crate::{Ipc, Outlet, RunContext, RuntimeError};

/// How often an otherwise silent stage says it is alive; stage loops wake at least this often.
pub const HEARTBEAT: Duration = Duration::from_millis(250);

/// A stage's telemetry publisher: lifecycle events and per-message timings.
pub struct TelemetrySink {
    outlet: Outlet<TelemetryHeader>,
    stage: String,
    last_sent: Cell<Instant>,
}

impl TelemetrySink {
    pub fn new(ctx: &RunContext, node: &Node<Ipc>, stage: &str) -> Result<Self, RuntimeError> {
        Ok(Self {
            outlet: Outlet::new(ctx, node, &TELEMETRY, 8)?,
            stage: stage.to_string(),
            last_sent: Cell::new(Instant::now()),
        })
    }

    fn send(&self, event: TelemetryEvent, input: &Stamp, start: u64, end: u64) {
        let header = TelemetryHeader::new(
            &self.stage,
            event,
            input,
            input.sent_ns.min(start),
            start,
            end,
        );
        self.publish(header);
    }

    fn publish(&self, header: TelemetryHeader) {
        self.last_sent.set(Instant::now());
        // Telemetry must never take a stage down: log and go on.
        if let Err(e) = self.outlet.send_header(header) {
            tracing::warn!("telemetry from {}: {e}", self.stage);
        }
    }

    /// A heartbeat, when nothing was sent for [`HEARTBEAT`]; call it every loop iteration.
    pub fn alive(&self) {
        if self.last_sent.get().elapsed() >= HEARTBEAT {
            let now = now_ns();
            self.send(
                TelemetryEvent::Heartbeat,
                &Stamp::new(MessageKind::Telemetry, 0, 0, now),
                now,
                now,
            );
        }
    }

    pub fn ready(&self) {
        let now = now_ns();
        self.send(
            TelemetryEvent::Ready,
            &Stamp::new(MessageKind::Telemetry, 0, 0, now),
            now,
            now,
        );
    }

    /// One input processed: `input` is the input message's stamp (its `sent_ns` starts the queue wait).
    pub fn processed(&self, input: &Stamp, start_ns: u64, end_ns: u64) {
        self.send(TelemetryEvent::Processed, input, start_ns, end_ns);
    }

    pub fn dropped(&self, input: &Stamp) {
        let now = now_ns();
        self.send(TelemetryEvent::Dropped, input, now, now);
    }

    /// Long work after the end of data: `done` of `total` steps.
    pub fn progress(&self, done: u32, total: u32) {
        self.publish(TelemetryHeader::progress(
            &self.stage,
            done.min(total),
            total,
            now_ns(),
        ));
    }

    /// End of data; `last` is the stamp of the last input handled.
    pub fn finished(&self, last: &Stamp) {
        let now = now_ns();
        self.send(TelemetryEvent::Finished, last, now, now);
    }
}
