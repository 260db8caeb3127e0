use std::mem::MaybeUninit;

use iceoryx2::prelude::ZeroCopySend;

use crate::payload::{
    check_count, check_dims, check_total, section_len, PayloadReader, PayloadWriter,
};
use crate::{MessageKind, SchemaError, Stamp};

/// Most map labels one render may report.
pub const MAX_RENDER_LABELS: u32 = 65_535;

/// Per-label visibility in one render (docs/METHOD.md §5.2 completeness).
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct LabelCompleteness {
    pub label: u32,
    /// Gaussians with this label visible in this view.
    pub visible: u32,
    /// Gaussians with this label in the whole map.
    pub total: u32,
}

/// The mapper's GS Voting render at a keyframe pose (top-K stays in the mapper).
/// Payload: label map `u32[W·H]` | [`LabelCompleteness`]`[label_count]`.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[type_name("opengs::RenderHeader")]
#[repr(C)]
pub struct RenderHeader {
    pub stamp: Stamp,
    pub width: u32,
    pub height: u32,
    pub label_count: u32,
    pub _reserved: u32,
}

#[derive(Debug)]
pub struct RenderView<'a> {
    pub header: &'a RenderHeader,
    pub label_map: &'a [u32],
    pub labels: &'a [LabelCompleteness],
}

impl RenderHeader {
    pub fn new(mut stamp: Stamp, width: u32, height: u32, label_count: u32) -> Self {
        stamp.kind = MessageKind::Render as u32;
        let mut h = Self {
            stamp,
            width,
            height,
            label_count,
            _reserved: 0,
        };
        h.stamp.payload_len = h.layout_len() as u64;
        h
    }

    fn layout_len(&self) -> usize {
        section_len::<u32>(self.width as usize * self.height as usize)
            + section_len::<LabelCompleteness>(self.label_count as usize)
    }

    pub fn payload_len(&self) -> usize {
        self.stamp.payload_len as usize
    }

    pub fn encode(
        &self,
        label_map: &[u32],
        labels: &[LabelCompleteness],
        buf: &mut [MaybeUninit<u8>],
    ) -> Result<(), SchemaError> {
        let n = check_dims(self.width, self.height)?;
        let l = check_count("label_count", self.label_count, MAX_RENDER_LABELS)?;
        if label_map.len() != n || labels.len() != l {
            return Err(SchemaError::Invalid("render does not match the header"));
        }
        check_total(self.layout_len(), buf.len())?;
        let mut w = PayloadWriter::new(buf);
        w.put(label_map)?;
        w.put(labels)?;
        w.finish()
    }

    pub fn decode<'a>(&'a self, payload: &'a [u8]) -> Result<RenderView<'a>, SchemaError> {
        self.stamp.validate(MessageKind::Render, payload.len())?;
        let n = check_dims(self.width, self.height)?;
        let l = check_count("label_count", self.label_count, MAX_RENDER_LABELS)?;
        check_total(self.layout_len(), payload.len())?;
        let mut r = PayloadReader::new(payload)?;
        let label_map = r.take::<u32>(n)?;
        let labels = r.take::<LabelCompleteness>(l)?;
        if labels.iter().any(|c| c.visible > c.total) {
            return Err(SchemaError::Invalid(
                "a label has more visible Gaussians than it has",
            ));
        }
        Ok(RenderView {
            header: self,
            label_map,
            labels,
        })
    }
}
