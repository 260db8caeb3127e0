use std::mem::MaybeUninit;

use iceoryx2::prelude::ZeroCopySend;

use crate::payload::{
    check_count, check_dims, check_total, section_len, PayloadReader, PayloadWriter,
};
use crate::{MessageKind, SchemaError, Stamp};

/// Most labels one segmentation may carry.
pub const MAX_SEGMENT_LABELS: u32 = 65_535;

/// One input label of a segmentation: confidence and class (the input Label-Class table).
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct SegmentLabel {
    pub label: u32,
    pub confidence: f32,
    /// Detection score of the class; 0 for class `None`.
    pub score: f32,
    /// UTF-8 class name, NUL-padded; empty = `None`.
    pub class_name: [u8; 36],
}

impl SegmentLabel {
    pub fn new(label: u32, confidence: f32, class: Option<&str>, score: f32) -> Self {
        let mut class_name = [0u8; 36];
        if let Some(c) = class {
            // Truncate on a char boundary so the name stays valid UTF-8.
            let mut end = c.len().min(36);
            while !c.is_char_boundary(end) {
                end -= 1;
            }
            class_name[..end].copy_from_slice(&c.as_bytes()[..end]);
        }
        Self {
            label,
            confidence,
            score,
            class_name,
        }
    }

    pub fn class(&self) -> Option<&str> {
        let end = self.class_name.iter().position(|&b| b == 0).unwrap_or(36);
        if end == 0 {
            return None;
        }
        std::str::from_utf8(&self.class_name[..end]).ok()
    }
}

/// A segmenter's output for one keyframe.
/// Payload: label map `u32[W·H]` | labels [`SegmentLabel`]`[label_count]`.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[type_name("opengs::SegmentsHeader")]
#[repr(C)]
pub struct SegmentsHeader {
    pub stamp: Stamp,
    pub width: u32,
    pub height: u32,
    pub label_count: u32,
    /// Which segmenter produced this (for swap accounting): an index into the segmenter kinds.
    pub segmenter: u32,
}

#[derive(Debug)]
pub struct SegmentsView<'a> {
    pub header: &'a SegmentsHeader,
    pub label_map: &'a [u32],
    pub labels: &'a [SegmentLabel],
}

impl SegmentsHeader {
    pub fn new(
        mut stamp: Stamp,
        width: u32,
        height: u32,
        label_count: u32,
        segmenter: u32,
    ) -> Self {
        stamp.kind = MessageKind::Segments as u32;
        let mut h = Self {
            stamp,
            width,
            height,
            label_count,
            segmenter,
        };
        h.stamp.payload_len = h.layout_len() as u64;
        h
    }

    fn layout_len(&self) -> usize {
        section_len::<u32>(self.width as usize * self.height as usize)
            + section_len::<SegmentLabel>(self.label_count as usize)
    }

    pub fn payload_len(&self) -> usize {
        self.stamp.payload_len as usize
    }

    pub fn encode(
        &self,
        label_map: &[u32],
        labels: &[SegmentLabel],
        buf: &mut [MaybeUninit<u8>],
    ) -> Result<(), SchemaError> {
        let n = check_dims(self.width, self.height)?;
        let l = check_count("label_count", self.label_count, MAX_SEGMENT_LABELS)?;
        if label_map.len() != n || labels.len() != l {
            return Err(SchemaError::Invalid("segments do not match the header"));
        }
        check_total(self.layout_len(), buf.len())?;
        let mut w = PayloadWriter::new(buf);
        w.put(label_map)?;
        w.put(labels)?;
        w.finish()
    }

    pub fn decode<'a>(&'a self, payload: &'a [u8]) -> Result<SegmentsView<'a>, SchemaError> {
        self.stamp.validate(MessageKind::Segments, payload.len())?;
        let n = check_dims(self.width, self.height)?;
        let l = check_count("label_count", self.label_count, MAX_SEGMENT_LABELS)?;
        check_total(self.layout_len(), payload.len())?;
        let mut r = PayloadReader::new(payload)?;
        let label_map = r.take::<u32>(n)?;
        let labels = r.take::<SegmentLabel>(l)?;
        if labels
            .iter()
            .any(|s| !(s.confidence.is_finite() && s.score.is_finite()))
        {
            return Err(SchemaError::NonFinite("segment confidence or score"));
        }
        Ok(SegmentsView {
            header: self,
            label_map,
            labels,
        })
    }
}
