//! Errors of the semantics crate: every bad input is reported, nothing panics.

use thiserror::Error;

/// Why a consensus step, a table operation or a top-K helper refused its input.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SemanticsError {
    #[error("invalid config: {0}")]
    InvalidConfig(String),
    #[error("image size {width}×{height} is empty or too large for u32 pixel indices")]
    InvalidImageSize { width: usize, height: usize },
    #[error("{which} label map has {got} pixels, expected {expected} (W×H)")]
    LabelMapSize {
        which: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("input label {0} has pixels but no confidence")]
    MissingConfidence(u32),
    #[error("input label {label} has a non-finite or negative confidence {value}")]
    InvalidConfidence { label: u32, value: f32 },
    #[error("input label {label} has a non-finite detection score {value}")]
    InvalidScore { label: u32, value: f32 },
    #[error("rendered label {0} has pixels but no completeness")]
    MissingCompleteness(u32),
    #[error("rendered label {label} has completeness {value}, expected a value in [0, 1]")]
    InvalidCompleteness { label: u32, value: f32 },
    #[error("global label table is full ({cap} labels)")]
    LabelTableFull { cap: usize },
    #[error("{path}: {message}")]
    TableFile { path: String, message: String },
    #[error("pixel index {pixel} is outside the top-K record of {pixels} pixels")]
    PixelOutOfRange { pixel: u32, pixels: usize },
    #[error("Gaussian id {id} in the top-K record is outside the {gaussians} Gaussians")]
    GaussianOutOfRange { id: u32, gaussians: usize },
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, SemanticsError>;
