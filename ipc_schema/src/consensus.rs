use std::mem::MaybeUninit;

use iceoryx2::prelude::ZeroCopySend;

use crate::payload::{
    check_count, check_dims, check_total, section_len, PayloadReader, PayloadWriter,
};
use crate::{MessageKind, SchemaError, Stamp};

/// Most label mappings / relabel runs / prune runs in one result.
pub const MAX_CONSENSUS_ENTRIES: u32 = 1 << 20;

/// A label change: `from` → `to` for the Gaussians in the top-K of pixels
/// `pixels[offset .. offset + count]` ([`PixelRun::SCOPE_PIXELS`]), or for every Gaussian
/// labelled `from` (the other scopes).
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct PixelRun {
    pub from: u32,
    pub to: u32,
    pub offset: u32,
    pub count: u32,
    pub scope: u32,
}

impl PixelRun {
    /// Only the Gaussians met at the run's pixels change.
    pub const SCOPE_PIXELS: u32 = 0;
    /// Every Gaussian labelled `from` changes (a label absorbed whole) where it lies on the
    /// surface of `to`.
    pub const SCOPE_LABEL: u32 = 1;
    /// Every Gaussian labelled `from` changes, wherever it lies (a Whole merge).
    pub const SCOPE_MERGED: u32 = 2;
    /// Every Gaussian labelled `from` changes where `from` lies on the surface of `to`, after
    /// the consistent label map labelled the unlabelled ones (a fresh label split off `to`).
    pub const SCOPE_REJOIN: u32 = 3;
}

/// A counter-pruning region (docs/METHOD.md §5.3): Gaussians labelled `label` (ℓr) in the top-K of
/// pixels `pixels[offset .. offset + count]` are pruned when larger than the header's θ.
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct PruneRun {
    pub label: u32,
    pub offset: u32,
    pub count: u32,
}

/// Consensus result for one keyframe, for the mapper.
/// Payload: consistent label map `u32[W·H]` | mapping `[u32; 2][mapping_count]` (ℓs → ℓt) |
/// relabel runs [`PixelRun`]`[relabel_count]` | prune runs [`PruneRun`]`[prune_count]` |
/// pixel indices `u32[pixel_count]`.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[type_name("opengs::ConsensusHeader")]
#[repr(C)]
pub struct ConsensusHeader {
    pub stamp: Stamp,
    pub width: u32,
    pub height: u32,
    pub mapping_count: u32,
    pub relabel_count: u32,
    pub prune_count: u32,
    pub pixel_count: u32,
    /// θ (metres): counter Gaussians are pruned when their largest scale exceeds it.
    pub counter_prune_scale: f32,
    pub _reserved: u32,
}

/// Borrowed parts of a consensus result (encode side and decoded view alike).
#[derive(Debug)]
pub struct ConsensusResult<'a> {
    pub label_map: &'a [u32],
    pub mapping: &'a [[u32; 2]],
    pub relabels: &'a [PixelRun],
    pub prunes: &'a [PruneRun],
    pub pixels: &'a [u32],
}

#[derive(Debug)]
pub struct ConsensusView<'a> {
    pub header: &'a ConsensusHeader,
    pub result: ConsensusResult<'a>,
}

impl ConsensusHeader {
    pub fn new(
        mut stamp: Stamp,
        width: u32,
        height: u32,
        counter_prune_scale: f32,
        parts: &ConsensusResult,
    ) -> Self {
        stamp.kind = MessageKind::Consensus as u32;
        let mut h = Self {
            stamp,
            width,
            height,
            mapping_count: parts.mapping.len() as u32,
            relabel_count: parts.relabels.len() as u32,
            prune_count: parts.prunes.len() as u32,
            pixel_count: parts.pixels.len() as u32,
            counter_prune_scale,
            _reserved: 0,
        };
        h.stamp.payload_len = h.layout_len() as u64;
        h
    }

    fn layout_len(&self) -> usize {
        section_len::<u32>(self.width as usize * self.height as usize)
            + section_len::<[u32; 2]>(self.mapping_count as usize)
            + section_len::<PixelRun>(self.relabel_count as usize)
            + section_len::<PruneRun>(self.prune_count as usize)
            + section_len::<u32>(self.pixel_count as usize)
    }

    pub fn payload_len(&self) -> usize {
        self.stamp.payload_len as usize
    }

    fn counts(&self) -> Result<[usize; 5], SchemaError> {
        let n = check_dims(self.width, self.height)?;
        let theta = self.counter_prune_scale;
        if !(theta.is_finite() && theta > 0.0) {
            return Err(SchemaError::Invalid(
                "counter_prune_scale (θ) must be a finite length > 0",
            ));
        }
        Ok([
            n,
            check_count("mapping_count", self.mapping_count, MAX_CONSENSUS_ENTRIES)?,
            check_count("relabel_count", self.relabel_count, MAX_CONSENSUS_ENTRIES)?,
            check_count("prune_count", self.prune_count, MAX_CONSENSUS_ENTRIES)?,
            // 64·n reaches 2^32 at 8192×8192: multiplied in usize, capped at u32::MAX.
            check_count(
                "pixel_count",
                self.pixel_count,
                (64 * n).min(u32::MAX as usize) as u32,
            )?,
        ])
    }

    pub fn encode(
        &self,
        parts: &ConsensusResult,
        buf: &mut [MaybeUninit<u8>],
    ) -> Result<(), SchemaError> {
        let [n, m, r, p, px] = self.counts()?;
        if parts.label_map.len() != n
            || parts.mapping.len() != m
            || parts.relabels.len() != r
            || parts.prunes.len() != p
            || parts.pixels.len() != px
        {
            return Err(SchemaError::Invalid(
                "consensus parts do not match the header",
            ));
        }
        check_runs(parts, n)?;
        check_total(self.layout_len(), buf.len())?;
        let mut w = PayloadWriter::new(buf);
        w.put(parts.label_map)?;
        w.put(parts.mapping)?;
        w.put(parts.relabels)?;
        w.put(parts.prunes)?;
        w.put(parts.pixels)?;
        w.finish()
    }

    pub fn decode<'a>(&'a self, payload: &'a [u8]) -> Result<ConsensusView<'a>, SchemaError> {
        self.stamp.validate(MessageKind::Consensus, payload.len())?;
        let [n, m, r, p, px] = self.counts()?;
        check_total(self.layout_len(), payload.len())?;
        let mut rd = PayloadReader::new(payload)?;
        let result = ConsensusResult {
            label_map: rd.take(n)?,
            mapping: rd.take(m)?,
            relabels: rd.take(r)?,
            prunes: rd.take(p)?,
            pixels: rd.take(px)?,
        };
        check_runs(&result, n)?;
        Ok(ConsensusView {
            header: self,
            result,
        })
    }
}

/// Every run must index inside the pixel list, and every pixel inside the image.
fn check_runs(parts: &ConsensusResult, n: usize) -> Result<(), SchemaError> {
    let total = parts.pixels.len() as u64;
    let relabels = parts.relabels.iter().map(|r| (r.offset, r.count));
    let prunes = parts.prunes.iter().map(|r| (r.offset, r.count));
    for (offset, count) in relabels.chain(prunes) {
        if offset as u64 + count as u64 > total {
            return Err(SchemaError::Invalid("pixel run outside the pixel list"));
        }
    }
    if parts
        .relabels
        .iter()
        .any(|r| r.scope > PixelRun::SCOPE_REJOIN)
    {
        return Err(SchemaError::Invalid("relabel run with an unknown scope"));
    }
    if parts.pixels.iter().any(|&p| p as usize >= n) {
        return Err(SchemaError::Invalid("pixel index outside the image"));
    }
    Ok(())
}
