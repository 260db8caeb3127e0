use std::mem::MaybeUninit;

use iceoryx2::prelude::ZeroCopySend;

use crate::payload::{
    check_count, check_dims, check_total, section_len, PayloadReader, PayloadWriter,
};
use crate::{MessageKind, SchemaError, Stamp};

/// Most source points a keyframe may carry (a 1200×680 frame at stride 1).
pub const MAX_KEYFRAME_POINTS: u32 = 1200 * 680;

/// A keyframe from the tracker for the mapper.
/// Payload: points `f32[3n]` (world frame) | covariances `f32[6n]` (xx xy xz yy yz zz) |
/// depth `u16[W·H]` | rgb `u8[3·W·H]`.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend)]
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
    /// Index of the frame in its dataset.
    pub frame_index: u64,
}

pub struct KeyframeParts<'a> {
    pub points: &'a [[f32; 3]],
    pub covariances: &'a [[f32; 6]],
    pub depth: &'a [u16],
    pub rgb: &'a [u8],
}

#[derive(Debug)]
pub struct KeyframeView<'a> {
    pub header: &'a KeyframeHeader,
    pub points: &'a [[f32; 3]],
    pub covariances: &'a [[f32; 6]],
    pub depth: &'a [u16],
    pub rgb: &'a [u8],
}

impl KeyframeHeader {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        mut stamp: Stamp,
        pose: [f64; 7],
        intrinsics: [f64; 4],
        width: u32,
        height: u32,
        depth_scale: f32,
        point_count: u32,
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
            frame_index,
        };
        h.stamp.payload_len = h.layout_len() as u64;
        h
    }

    fn layout_len(&self) -> usize {
        let n = self.width as usize * self.height as usize;
        let p = self.point_count as usize;
        section_len::<[f32; 3]>(p)
            + section_len::<[f32; 6]>(p)
            + section_len::<u16>(n)
            + section_len::<u8>(3 * n)
    }

    pub fn payload_len(&self) -> usize {
        self.stamp.payload_len as usize
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
        check_total(self.layout_len(), payload.len())?;
        let mut r = PayloadReader::new(payload)?;
        Ok(KeyframeView {
            header: self,
            points: r.take(p)?,
            covariances: r.take(p)?,
            depth: r.take(n)?,
            rgb: r.take(3 * n)?,
        })
    }
}
