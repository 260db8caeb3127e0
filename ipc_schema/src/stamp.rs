use iceoryx2::prelude::ZeroCopySend;

use crate::SchemaError;

/// Bumped whenever any header layout or payload layout changes.
pub const SCHEMA_VERSION: u32 = 2;

/// Message kinds; the discriminant travels in [`Stamp::kind`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum MessageKind {
    Frame = 1,
    Pose = 2,
    Keyframe = 3,
    Segments = 4,
    Render = 5,
    Consensus = 6,
    MapTarget = 7,
    Telemetry = 8,
    Control = 9,
}

/// Common prefix of every header: identity and timing of one message.
///
/// All `*_ns` fields are CLOCK_MONOTONIC nanoseconds (one clock for every
/// process on the machine), except `capture_ns` which is the dataset/sensor
/// capture time.
#[derive(
    Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable,
)]
#[repr(C)]
pub struct Stamp {
    pub version: u32,
    pub kind: u32,
    /// Sequence number of the source frame this message derives from.
    pub seq: u64,
    /// Capture timestamp of the source frame (sensor clock), ns.
    pub capture_ns: u64,
    /// When the sensor published the source frame (end-to-end latency origin).
    pub origin_ns: u64,
    /// When the producing stage started work on this message's input.
    pub stage_start_ns: u64,
    /// When this message was sent.
    pub sent_ns: u64,
    pub payload_len: u64,
}

impl Stamp {
    pub fn new(kind: MessageKind, seq: u64, capture_ns: u64, origin_ns: u64) -> Self {
        Self {
            version: SCHEMA_VERSION,
            kind: kind as u32,
            seq,
            capture_ns,
            origin_ns,
            stage_start_ns: 0,
            sent_ns: 0,
            payload_len: 0,
        }
    }

    /// A stamp for a message derived from `input`: same seq and origin.
    pub fn derived(kind: MessageKind, input: &Stamp) -> Self {
        Self::new(kind, input.seq, input.capture_ns, input.origin_ns)
    }

    /// Checks version, kind and declared payload length against the received payload.
    pub fn validate(&self, kind: MessageKind, payload_len: usize) -> Result<(), SchemaError> {
        if self.version != SCHEMA_VERSION {
            return Err(SchemaError::Version {
                found: self.version,
                expected: SCHEMA_VERSION,
            });
        }
        if self.kind != kind as u32 {
            return Err(SchemaError::Kind {
                found: self.kind,
                expected: kind,
            });
        }
        if self.payload_len != payload_len as u64 {
            return Err(SchemaError::PayloadLength {
                declared: self.payload_len,
                actual: payload_len,
            });
        }
        Ok(())
    }
}

/// CLOCK_MONOTONIC in nanoseconds: comparable across processes on one machine.
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the valid timespec we pass.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Every header starts with a [`Stamp`]; this gives generic code access to it.
pub trait Stamped {
    fn stamp(&self) -> &Stamp;
    fn stamp_mut(&mut self) -> &mut Stamp;
}

macro_rules! impl_stamped {
    ($($t:ty),*) => {$(
        impl Stamped for $t {
            fn stamp(&self) -> &Stamp { &self.stamp }
            fn stamp_mut(&mut self) -> &mut Stamp { &mut self.stamp }
        }
    )*};
}

impl_stamped!(
    crate::FrameHeader,
    crate::PoseHeader,
    crate::KeyframeHeader,
    crate::SegmentsHeader,
    crate::RenderHeader,
    crate::ConsensusHeader,
    crate::MapTargetHeader,
    crate::TelemetryHeader,
    crate::ControlHeader
);
