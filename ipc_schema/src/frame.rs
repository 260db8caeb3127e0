use std::mem::MaybeUninit;

use iceoryx2::prelude::ZeroCopySend;

use crate::payload::{check_dims, check_total, section_len, PayloadReader, PayloadWriter};
use crate::{MessageKind, SchemaError, Stamp};

/// One RGB-D frame from the sensor.
/// Payload: depth `u16[W·H]` | labels `u16[W·H]` (if [`FrameHeader::HAS_LABELS`]) | rgb `u8[3·W·H]`.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[type_name("opengs::FrameHeader")]
#[repr(C)]
pub struct FrameHeader {
    pub stamp: Stamp,
    pub width: u32,
    pub height: u32,
    /// Depth units per metre; 0 in the depth image means missing.
    pub depth_scale: f32,
    pub flags: u32,
    /// fx, fy, cx, cy (OpenCV pixel convention).
    pub intrinsics: [f64; 4],
    /// Ground-truth camera-to-world pose `tx ty tz qx qy qz qw` when [`FrameHeader::HAS_GT`].
    pub gt_pose: [f64; 7],
    /// Index of the frame in its dataset.
    pub frame_index: u64,
}

/// Borrowed image planes to encode into a frame payload.
pub struct FrameParts<'a> {
    pub depth: &'a [u16],
    pub labels: Option<&'a [u16]>,
    pub rgb: &'a [u8],
}

/// Validated zero-copy view of a received frame.
#[derive(Debug)]
pub struct FrameView<'a> {
    pub header: &'a FrameHeader,
    pub depth: &'a [u16],
    pub labels: Option<&'a [u16]>,
    pub rgb: &'a [u8],
}

impl FrameHeader {
    pub const HAS_GT: u32 = 1;
    pub const HAS_LABELS: u32 = 2;
    /// The recording's last frame (a finite dataset's; a live one never sets it).
    pub const LAST: u32 = 4;

    #[allow(clippy::too_many_arguments)]
    pub fn new(
        mut stamp: Stamp,
        width: u32,
        height: u32,
        depth_scale: f32,
        intrinsics: [f64; 4],
        gt_pose: Option<[f64; 7]>,
        has_labels: bool,
        frame_index: u64,
    ) -> Self {
        let mut flags = 0;
        if gt_pose.is_some() {
            flags |= Self::HAS_GT;
        }
        if has_labels {
            flags |= Self::HAS_LABELS;
        }
        stamp.kind = MessageKind::Frame as u32;
        let mut h = Self {
            stamp,
            width,
            height,
            depth_scale,
            flags,
            intrinsics,
            gt_pose: gt_pose.unwrap_or([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]),
            frame_index,
        };
        h.stamp.payload_len = h.layout_len() as u64;
        h
    }

    pub fn has_gt(&self) -> bool {
        self.flags & Self::HAS_GT != 0
    }

    pub fn has_labels(&self) -> bool {
        self.flags & Self::HAS_LABELS != 0
    }

    /// Marks the frame as the recording's last.
    pub fn last(mut self) -> Self {
        self.flags |= Self::LAST;
        self
    }

    pub fn is_last(&self) -> bool {
        self.flags & Self::LAST != 0
    }

    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    fn layout_len(&self) -> usize {
        let n = self.pixels();
        let labels = if self.has_labels() {
            section_len::<u16>(n)
        } else {
            0
        };
        section_len::<u16>(n) + labels + section_len::<u8>(3 * n)
    }

    pub fn payload_len(&self) -> usize {
        self.stamp.payload_len as usize
    }

    pub fn encode(
        &self,
        parts: &FrameParts,
        buf: &mut [MaybeUninit<u8>],
    ) -> Result<(), SchemaError> {
        let n = check_dims(self.width, self.height)?;
        if parts.depth.len() != n
            || parts.rgb.len() != 3 * n
            || parts.labels.map(|l| l.len()) != self.has_labels().then_some(n)
        {
            return Err(SchemaError::Invalid(
                "frame planes do not match the header size",
            ));
        }
        check_total(self.layout_len(), buf.len())?;
        let mut w = PayloadWriter::new(buf);
        w.put(parts.depth)?;
        if let Some(labels) = parts.labels {
            w.put(labels)?;
        }
        w.put(parts.rgb)?;
        w.finish()
    }

    pub fn decode<'a>(&'a self, payload: &'a [u8]) -> Result<FrameView<'a>, SchemaError> {
        self.stamp.validate(MessageKind::Frame, payload.len())?;
        let n = check_dims(self.width, self.height)?;
        if !(self.depth_scale.is_finite() && self.depth_scale > 0.0) {
            return Err(SchemaError::NonFinite("depth_scale"));
        }
        if self.intrinsics.iter().any(|v| !v.is_finite())
            || self.intrinsics[0] <= 0.0
            || self.intrinsics[1] <= 0.0
        {
            return Err(SchemaError::NonFinite("intrinsics"));
        }
        if self.has_gt() && self.gt_pose.iter().any(|v| !v.is_finite()) {
            return Err(SchemaError::NonFinite("gt_pose"));
        }
        if self.flags & !(Self::HAS_GT | Self::HAS_LABELS | Self::LAST) != 0 {
            return Err(SchemaError::Invalid("unknown frame flags"));
        }
        check_total(self.layout_len(), payload.len())?;
        let mut r = PayloadReader::new(payload)?;
        let depth = r.take::<u16>(n)?;
        let labels = if self.has_labels() {
            Some(r.take::<u16>(n)?)
        } else {
            None
        };
        let rgb = r.take::<u8>(3 * n)?;
        Ok(FrameView {
            header: self,
            depth,
            labels,
            rgb,
        })
    }
}
