use std::mem::MaybeUninit;

use iceoryx2::prelude::ZeroCopySend;

use crate::payload::{
    check_count, check_dims, check_total, section_len, PayloadReader, PayloadWriter,
};
use crate::{MessageKind, SchemaError, Stamp};

/// Most source points a keyframe may carry (a 1200×680 frame at stride 1).
pub const MAX_KEYFRAME_POINTS: u32 = 1200 * 680;

/// A keyframe from the tracker for the mapper and the segmenter.
/// Payload: points `f32[3n]` (world frame) | covariances `f32[6n]` (xx xy xz yy yz zz) |
/// depth `u16[W·H]` | labels `u16[W·H]` (if [`KeyframeHeader::HAS_LABELS`]) | rgb `u8[3·W·H]`.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[type_name("opengs::KeyframeHeader")]
#[repr(C)]
pub struct KeyframeHeader {
    pub stamp: Stamp,
    pub pose: [f64; 7],
    pub intrinsics: [f64; 4],
    pub width: u32,
    pub height: u32,
    pub depth_scale: f32,
    pub point_count: u32,
    pub flags: u32,
    pub _reserved: u32,
    /// Index of the frame in its dataset.
    pub frame_index: u64,
}

pub struct KeyframeParts<'a> {
    pub points: &'a [[f32; 3]],
    pub covariances: &'a [[f32; 6]],
    pub depth: &'a [u16],
    /// Ground-truth instance labels, when the dataset has them (the prior segmenter uses them).
    pub labels: Option<&'a [u16]>,
    pub rgb: &'a [u8],
}

#[derive(Debug)]
pub struct KeyframeView<'a> {
    pub header: &'a KeyframeHeader,
    pub points: &'a [[f32; 3]],
    pub covariances: &'a [[f32; 6]],
    pub depth: &'a [u16],
    pub labels: Option<&'a [u16]>,
    pub rgb: &'a [u8],
}

impl KeyframeHeader {
    pub const HAS_LABELS: u32 = 1;

    #[allow(clippy::too_many_arguments)]
    pub fn new(
        mut stamp: Stamp,
        pose: [f64; 7],
        intrinsics: [f64; 4],
        width: u32,
        height: u32,
        depth_scale: f32,
        point_count: u32,
        has_labels: bool,
        frame_index: u64,
    ) -> Self {
        stamp.kind = MessageKind::Keyframe as u32;
        let mut h = Self {
            stamp,
            pose,
            intrinsics,
            width,
            height,
            depth_scale,
            point_count,
            flags: if has_labels { Self::HAS_LABELS } else { 0 },
            _reserved: 0,
            frame_index,
        };
        h.stamp.payload_len = h.layout_len() as u64;
        h
    }

    fn layout_len(&self) -> usize {
        let n = self.width as usize * self.height as usize;
        let p = self.point_count as usize;
        let labels = if self.has_labels() {
            section_len::<u16>(n)
        } else {
            0
        };
        section_len::<[f32; 3]>(p)
            + section_len::<[f32; 6]>(p)
            + section_len::<u16>(n)
            + labels
            + section_len::<u8>(3 * n)
    }

    pub fn payload_len(&self) -> usize {
        self.stamp.payload_len as usize
    }

    pub fn has_labels(&self) -> bool {
        self.flags & Self::HAS_LABELS != 0
    }

    pub fn encode(
        &self,
        parts: &KeyframeParts,
        buf: &mut [MaybeUninit<u8>],
    ) -> Result<(), SchemaError> {
        let n = check_dims(self.width, self.height)?;
        let p = check_count("point_count", self.point_count, MAX_KEYFRAME_POINTS)?;
        if parts.points.len() != p
            || parts.covariances.len() != p
            || parts.depth.len() != n
            || parts.rgb.len() != 3 * n
            || parts.labels.map(|l| l.len()) != self.has_labels().then_some(n)
        {
            return Err(SchemaError::Invalid(
                "keyframe parts do not match the header",
            ));
        }
        check_total(self.layout_len(), buf.len())?;
        let mut w = PayloadWriter::new(buf);
        w.put(parts.points)?;
        w.put(parts.covariances)?;
        w.put(parts.depth)?;
        if let Some(labels) = parts.labels {
            w.put(labels)?;
        }
        w.put(parts.rgb)?;
        w.finish()
    }

    pub fn decode<'a>(&'a self, payload: &'a [u8]) -> Result<KeyframeView<'a>, SchemaError> {
        self.stamp.validate(MessageKind::Keyframe, payload.len())?;
        let n = check_dims(self.width, self.height)?;
        let p = check_count("point_count", self.point_count, MAX_KEYFRAME_POINTS)?;
        if self
            .pose
            .iter()
            .chain(&self.intrinsics)
            .any(|v| !v.is_finite())
        {
            return Err(SchemaError::NonFinite("keyframe pose or intrinsics"));
        }
        if !(self.depth_scale.is_finite() && self.depth_scale > 0.0) {
            return Err(SchemaError::NonFinite("depth_scale"));
        }
        if self.flags & !Self::HAS_LABELS != 0 {
            return Err(SchemaError::Invalid("unknown keyframe flags"));
        }
        check_total(self.layout_len(), payload.len())?;
        let mut r = PayloadReader::new(payload)?;
        Ok(KeyframeView {
            header: self,
            points: r.take(p)?,
            covariances: r.take(p)?,
            depth: r.take(n)?,
            labels: if self.has_labels() {
                Some(r.take(n)?)
            } else {
                None
            },
            rgb: r.take(3 * n)?,
        })
    }
}
