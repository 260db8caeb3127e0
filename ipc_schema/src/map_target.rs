use std::mem::MaybeUninit;

use iceoryx2::prelude::ZeroCopySend;

use crate::payload::{check_count, check_total, section_len, PayloadReader, PayloadWriter};
use crate::{MessageKind, SchemaError, Stamp};

/// Most Gaussians one map target may carry.
pub const MAX_TARGET_GAUSSIANS: u32 = 20_000_000;

/// The map's trackable Gaussians, mapper → tracker.
/// Payload: means `f32[3n]` | rotations `f32[4n]` (w x y z) | scales `f32[3n]` (linear).
#[derive(Debug, Clone, Copy, Default, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[type_name("opengs::MapTargetHeader")]
#[repr(C)]
pub struct MapTargetHeader {
    pub stamp: Stamp,
    pub count: u32,
    /// Increases with every map update the mapper publishes.
    pub map_version: u32,
}

pub struct MapTargetParts<'a> {
    pub means: &'a [[f32; 3]],
    pub rotations: &'a [[f32; 4]],
    pub scales: &'a [[f32; 3]],
}

#[derive(Debug)]
pub struct MapTargetView<'a> {
    pub header: &'a MapTargetHeader,
    pub means: &'a [[f32; 3]],
    pub rotations: &'a [[f32; 4]],
    pub scales: &'a [[f32; 3]],
}

impl MapTargetHeader {
    pub fn new(mut stamp: Stamp, count: u32, map_version: u32) -> Self {
        stamp.kind = MessageKind::MapTarget as u32;
        let mut h = Self {
            stamp,
            count,
            map_version,
        };
        h.stamp.payload_len = h.layout_len() as u64;
        h
    }

    fn layout_len(&self) -> usize {
        let n = self.count as usize;
        section_len::<[f32; 3]>(n) + section_len::<[f32; 4]>(n) + section_len::<[f32; 3]>(n)
    }

    pub fn payload_len(&self) -> usize {
        self.stamp.payload_len as usize
    }

    pub fn encode(
        &self,
        parts: &MapTargetParts,
        buf: &mut [MaybeUninit<u8>],
    ) -> Result<(), SchemaError> {
        let n = check_count("count", self.count, MAX_TARGET_GAUSSIANS)?;
        if parts.means.len() != n || parts.rotations.len() != n || parts.scales.len() != n {
            return Err(SchemaError::Invalid(
                "map target parts do not match the header",
            ));
        }
        check_total(self.layout_len(), buf.len())?;
        let mut w = PayloadWriter::new(buf);
        w.put(parts.means)?;
        w.put(parts.rotations)?;
        w.put(parts.scales)?;
        w.finish()
    }

    pub fn decode<'a>(&'a self, payload: &'a [u8]) -> Result<MapTargetView<'a>, SchemaError> {
        self.stamp.validate(MessageKind::MapTarget, payload.len())?;
        let n = check_count("count", self.count, MAX_TARGET_GAUSSIANS)?;
        check_total(self.layout_len(), payload.len())?;
        let mut r = PayloadReader::new(payload)?;
        Ok(MapTargetView {
            header: self,
            means: r.take(n)?,
            rotations: r.take(n)?,
            scales: r.take(n)?,
        })
    }
}
