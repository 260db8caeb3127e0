//! Per-keyframe inputs of the consensus: the segmenter's output and the map rendered at the same pose.

use std::collections::BTreeMap;

use crate::error::{Result, SemanticsError};

/// One row of the input Label-Class table (paper: M_LC^I).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct InputLabelClass {
    /// Class of the best-overlapping detection box, `None` when no box matched.
    pub class: Option<String>,
    /// Detection score of that box (0.0 with `None`).
    pub score: f32,
}

/// Segmenter output for one keyframe; input labels are arbitrary per frame, 0 = none.
#[derive(Debug, Clone, Copy)]
pub struct SegmenterInput<'a> {
    pub width: usize,
    pub height: usize,
    /// Row-major W×H input label map.
    pub label_map: &'a [u32],
    /// C_s per input label; every non-zero label present in the map needs one.
    pub confidence: &'a BTreeMap<u32, f32>,
    /// Input Label-Class table; a missing label reads as class `None`, score 0.0.
    pub classes: &'a BTreeMap<u32, InputLabelClass>,
}

/// GS Voting render at the keyframe pose.
#[derive(Debug, Clone, Copy)]
pub struct RenderedInput<'a> {
    /// Row-major W×H rendered label map (global labels, 0 = nothing rendered).
    pub label_map: &'a [u32],
    /// Completeness per rendered label: visible Gaussians with ℓr ÷ all Gaussians with ℓr.
    pub completeness: &'a BTreeMap<u32, f32>,
}

/// Checks sizes and dimensions; returns W×H.
pub(crate) fn validate_shapes(input: &SegmenterInput, rendered: &RenderedInput) -> Result<usize> {
    let pixels = input
        .width
        .checked_mul(input.height)
        .filter(|&n| n > 0 && n <= u32::MAX as usize)
        .ok_or(SemanticsError::InvalidImageSize {
            width: input.width,
            height: input.height,
        })?;
    if input.label_map.len() != pixels {
        return Err(SemanticsError::LabelMapSize {
            which: "input",
            expected: pixels,
            got: input.label_map.len(),
        });
    }
    if rendered.label_map.len() != pixels {
        return Err(SemanticsError::LabelMapSize {
            which: "rendered",
            expected: pixels,
            got: rendered.label_map.len(),
        });
    }
    Ok(pixels)
}

/// C_s of every present input label, checked finite and ≥ 0.
pub(crate) fn input_confidences(
    input: &SegmenterInput,
    present: impl Iterator<Item = u32>,
) -> Result<BTreeMap<u32, f32>> {
    let mut out = BTreeMap::new();
    for label in present {
        let value = *input
            .confidence
            .get(&label)
            .ok_or(SemanticsError::MissingConfidence(label))?;
        if !value.is_finite() || value < 0.0 {
            return Err(SemanticsError::InvalidConfidence { label, value });
        }
        if let Some(class) = input.classes.get(&label) {
            if !class.score.is_finite() {
                return Err(SemanticsError::InvalidScore {
                    label,
                    value: class.score,
                });
            }
        }
        out.insert(label, value);
    }
    Ok(out)
}

/// Completeness of every present rendered label, checked to lie in [0, 1].
pub(crate) fn rendered_completeness(
    rendered: &RenderedInput,
    present: impl Iterator<Item = u32>,
) -> Result<BTreeMap<u32, f32>> {
    let mut out = BTreeMap::new();
    for label in present {
        let value = *rendered
            .completeness
            .get(&label)
            .ok_or(SemanticsError::MissingCompleteness(label))?;
        if !(0.0..=1.0).contains(&value) {
            return Err(SemanticsError::InvalidCompleteness { label, value });
        }
        out.insert(label, value);
    }
    Ok(out)
}
