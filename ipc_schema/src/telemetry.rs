use iceoryx2::prelude::ZeroCopySend;

use crate::{MessageKind, SchemaError, Stamp};

/// A stage name, NUL-padded ASCII (`sensor`, `tracker`, ...).
pub type StageName = [u8; 16];

/// What a telemetry record reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum TelemetryEvent {
    /// The stage has opened its services and is ready for input.
    Ready = 1,
    /// One input message processed: queue wait and processing time are valid.
    Processed = 2,
    /// One input dropped (newest-only stages, malformed input).
    Dropped = 3,
    /// The stage has no more work (end of data).
    Finished = 4,
    /// Long work after the end of data (the mapper's final optimisation): `work_done` of
    /// `work_total` steps.
    Progress = 5,
    /// Nothing else to report for a while, but alive (the supervisor's watchdog).
    Heartbeat = 6,
}

impl TelemetryEvent {
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            1 => Self::Ready,
            2 => Self::Processed,
            3 => Self::Dropped,
            4 => Self::Finished,
            5 => Self::Progress,
            6 => Self::Heartbeat,
            _ => return None,
        })
    }
}

/// Stage → supervisor: one record per processed message (or lifecycle event). No payload.
///
/// `stamp.seq`, `stamp.origin_ns` identify the source frame; queue wait is
/// `start_ns − input_sent_ns`, processing `end_ns − start_ns`.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[type_name("opengs::TelemetryHeader")]
#[repr(C)]
pub struct TelemetryHeader {
    pub stamp: Stamp,
    pub stage: StageName,
    pub event: u32,
    pub pid: u32,
    /// When the input message was sent by the upstream stage.
    pub input_sent_ns: u64,
    pub start_ns: u64,
    pub end_ns: u64,
    /// Progress events only: steps done and planned (0 otherwise).
    pub work_done: u32,
    pub work_total: u32,
}

impl TelemetryHeader {
    pub fn new(
        stage: &str,
        event: TelemetryEvent,
        input: &Stamp,
        input_sent_ns: u64,
        start_ns: u64,
        end_ns: u64,
    ) -> Self {
        let mut name = [0u8; 16];
        let n = stage.len().min(16);
        name[..n].copy_from_slice(&stage.as_bytes()[..n]);
        let mut stamp = Stamp::derived(MessageKind::Telemetry, input);
        stamp.stage_start_ns = start_ns;
        stamp.sent_ns = end_ns;
        Self {
            stamp,
            stage: name,
            event: event as u32,
            pid: std::process::id(),
            input_sent_ns,
            start_ns,
            end_ns,
            work_done: 0,
            work_total: 0,
        }
    }

    /// A progress record: `done` of `total` steps of long work.
    pub fn progress(stage: &str, done: u32, total: u32, now_ns: u64) -> Self {
        let stamp = Stamp::new(MessageKind::Telemetry, 0, 0, now_ns);
        let mut h = Self::new(
            stage,
            TelemetryEvent::Progress,
            &stamp,
            now_ns,
            now_ns,
            now_ns,
        );
        h.work_done = done;
        h.work_total = total;
        h
    }

    pub fn stage_name(&self) -> &str {
        let end = self.stage.iter().position(|&b| b == 0).unwrap_or(16);
        std::str::from_utf8(&self.stage[..end]).unwrap_or("?")
    }

    pub fn decode(&self, payload: &[u8]) -> Result<TelemetryEvent, SchemaError> {
        self.stamp.validate(MessageKind::Telemetry, payload.len())?;
        if self.stamp.payload_len != 0 {
            return Err(SchemaError::Invalid("telemetry carries no payload"));
        }
        if std::str::from_utf8(&self.stage).is_err() || self.stage[0] == 0 {
            return Err(SchemaError::Invalid("stage name is not UTF-8 or empty"));
        }
        let ev = TelemetryEvent::from_u32(self.event)
            .ok_or(SchemaError::Invalid("unknown telemetry event"))?;
        if ev == TelemetryEvent::Processed
            && (self.end_ns < self.start_ns || self.start_ns < self.input_sent_ns)
        {
            return Err(SchemaError::Invalid("telemetry timestamps out of order"));
        }
        if ev == TelemetryEvent::Progress && self.work_done > self.work_total {
            return Err(SchemaError::Invalid("progress past its total"));
        }
        Ok(ev)
    }
}
