//! The message contract between pipeline processes, and nothing else.
//!
//! Every message is a `#[repr(C)]` header (iceoryx2 user header) over a `[u8]`
//! payload. Each header embeds a [`Stamp`] (schema version, kind, frame `seq`,
//! capture and stage timestamps, payload length). Receivers call the message's
//! `decode` before touching the payload: it validates version, kind, sizes,
//! dimensions and counts, and returns typed views or a [`SchemaError`] — never
//! a panic. Senders call `encode` on a loaned, uninitialised slice, which
//! writes every byte in place (zero-copy: no intermediate buffer).

mod consensus;
mod control;
mod error;
mod frame;
mod keyframe;
mod map_target;
mod payload;
mod pose;
mod render;
mod segments;
mod services;
mod stamp;
mod telemetry;
mod wire;

pub use consensus::{ConsensusHeader, ConsensusResult, ConsensusView, PixelRun, PruneRun};
pub use control::{ControlCommand, ControlHeader, ControlRequest, ControlView};
pub use error::SchemaError;
pub use frame::{FrameHeader, FrameParts, FrameView};
pub use keyframe::{KeyframeHeader, KeyframeParts, KeyframeView};
pub use map_target::{MapTargetHeader, MapTargetParts, MapTargetView};
pub use payload::{aligned_buffer, as_uninit_mut, PayloadWriter, ALIGN};
pub use pose::{PoseHeader, PoseStatus};
pub use render::{LabelCompleteness, RenderHeader, RenderView};
pub use segments::{SegmentLabel, SegmentsHeader, SegmentsView};
pub use services::{ServiceSpec, SERVICES};
pub mod service {
    pub use crate::services::*;
}
pub use stamp::{now_ns, MessageKind, Stamp, Stamped, SCHEMA_VERSION};
pub use telemetry::{StageName, TelemetryEvent, TelemetryHeader};
pub use wire::{from_wire, to_wire, WireIn, WireMessage};

/// Largest image side we accept; bounds every size computed from a header.
pub const MAX_IMAGE_SIDE: u32 = 8192;
