//! A message as bytes on a network link (the Zenoh bridge between hosts): the header's
//! bytes, then the payload's, nothing else. Nothing from a network is trusted: [`from_wire`]
//! checks the length, copies the payload to an aligned buffer and runs the header's own
//! `decode` on it, exactly as a receiver on the same host does.

use crate::payload::aligned_buffer;
use crate::{
    ConsensusHeader, ControlHeader, FrameHeader, KeyframeHeader, MapTargetHeader, PoseHeader,
    RenderHeader, SchemaError, SegmentsHeader, Stamped, TelemetryHeader,
};

/// A header that can cross a network link: plain bytes (no padding, no pointers), and a
/// check of its payload.
pub trait WireMessage: bytemuck::Pod + Stamped + std::fmt::Debug {
    /// Validates `payload` against the header as the receiver's `decode` does.
    fn validate(&self, payload: &[u8]) -> Result<(), SchemaError>;
}

macro_rules! wire_message {
    ($($t:ty),*) => {$(
        impl WireMessage for $t {
            fn validate(&self, payload: &[u8]) -> Result<(), SchemaError> {
                self.decode(payload).map(|_| ())
            }
        }
    )*};
}

wire_message!(
    FrameHeader,
    PoseHeader,
    KeyframeHeader,
    SegmentsHeader,
    RenderHeader,
    ConsensusHeader,
    MapTargetHeader,
    TelemetryHeader,
    ControlHeader
);

/// The bytes of one message for the link.
pub fn to_wire<H: WireMessage>(header: &H, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(std::mem::size_of::<H>() + payload.len());
    out.extend_from_slice(bytemuck::bytes_of(header));
    out.extend_from_slice(payload);
    out
}

/// A message taken off the link and validated: the header and its payload, aligned.
#[derive(Debug)]
pub struct WireIn<H> {
    pub header: H,
    buffer: Vec<u64>,
    len: usize,
}

impl<H> WireIn<H> {
    /// The payload, aligned as payloads in shared memory are.
    pub fn payload(&self) -> &[u8] {
        &bytemuck::cast_slice(&self.buffer)[..self.len]
    }
}

/// Reads and validates one message of type `H` from the link.
pub fn from_wire<H: WireMessage>(bytes: &[u8]) -> Result<WireIn<H>, SchemaError> {
    let size = std::mem::size_of::<H>();
    if bytes.len() < size {
        return Err(SchemaError::LayoutMismatch {
            expected: size,
            actual: bytes.len(),
        });
    }
    let header: H = bytemuck::pod_read_unaligned(&bytes[..size]);
    let payload = &bytes[size..];
    let mut buffer = aligned_buffer(payload.len());
    bytemuck::cast_slice_mut::<u64, u8>(&mut buffer)[..payload.len()].copy_from_slice(payload);
    let message = WireIn {
        header,
        buffer,
        len: payload.len(),
    };
    message.header.validate(message.payload())?;
    Ok(message)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{as_uninit_mut, now_ns, MessageKind, SegmentLabel, Stamp};

    fn segments() -> (SegmentsHeader, Vec<u8>) {
        let labels = [SegmentLabel::new(7, 0.9, Some("cup"), 0.8)];
        let map = vec![7u32; 4 * 3];
        let stamp = Stamp::new(MessageKind::Segments, 42, 1, now_ns());
        let h = SegmentsHeader::new(stamp, 4, 3, 1, 0);
        let mut payload = vec![0u8; h.stamp.payload_len as usize];
        h.encode(&map, &labels, as_uninit_mut(&mut payload))
            .expect("encode");
        (h, payload)
    }

    #[test]
    fn a_message_crosses_the_link_unchanged() {
        let (h, payload) = segments();
        let bytes = to_wire(&h, &payload);
        // Off by one byte: the payload starts unaligned on the link.
        let mut shifted = vec![0u8];
        shifted.extend_from_slice(&bytes);
        let got = from_wire::<SegmentsHeader>(&shifted[1..]).expect("valid");
        assert_eq!(got.header.stamp, h.stamp);
        assert_eq!(got.payload(), &payload[..]);
        let view = got.header.decode(got.payload()).expect("decodes");
        assert_eq!(
            (view.label_map[5], view.labels[0].class()),
            (7, Some("cup"))
        );
    }

    #[test]
    fn what_the_link_garbles_is_refused_with_the_reason() {
        let (h, payload) = segments();
        let bytes = to_wire(&h, &payload);
        // Too short for a header.
        assert!(matches!(
            from_wire::<SegmentsHeader>(&bytes[..10]),
            Err(SchemaError::LayoutMismatch { .. })
        ));
        // A payload cut short.
        assert!(from_wire::<SegmentsHeader>(&bytes[..bytes.len() - 8]).is_err());
        // A header claiming a larger image than the payload holds.
        let mut big = h;
        big.width = 4000;
        assert!(from_wire::<SegmentsHeader>(&to_wire(&big, &payload)).is_err());
        // Another message kind on this service's key.
        let mut other = h;
        other.stamp.kind = MessageKind::Render as u32;
        assert!(matches!(
            from_wire::<SegmentsHeader>(&to_wire(&other, &payload)),
            Err(SchemaError::Kind { .. })
        ));
    }
}
