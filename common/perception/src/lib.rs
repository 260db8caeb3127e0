//! Open-set instance segmentation front-ends for opengs (docs/METHOD.md §6).
//!
//! Every back-end implements [`Segmenter`]: an RGB-D frame in, a label map
//! plus the input Label-Class table out. `geometry` (depth-first, LCCP-style)
//! and `classic` (graph-based) need no weights,
//! `prior` replays the dataset's ground-truth instances and `simulated` corrupts them
//! with SAM's failure modes (a reference for measuring the consensus); `sam` and
//! `mobilesamv2` run exported ONNX models (cargo feature `onnx`, runtime
//! library from `ORT_DYLIB_PATH`, see `scripts/setup-ort.sh`). An optional ensemble
//! (tagger + open-vocabulary detector, [`ensemble`]) names the masks of any
//! segmenter; [`model_check`] checks exported files against their role.

/// True when built with the `onnx` cargo feature (the model runners exist).
pub const ONNX: bool = cfg!(feature = "onnx");

pub mod bench;
pub mod class_match;
pub mod classic;
#[cfg(feature = "onnx")]
pub mod ensemble;
mod error;
pub mod geometry;
mod kind;
pub mod model_check;
mod model_paths;
pub mod npy;
mod prior;
pub mod quality;
#[cfg(feature = "onnx")]
pub mod sam;
mod segmentation;
mod segmenter;
pub mod simulated;

pub use classic::{ClassicParams, ClassicSegmenter, EdgeWeights};
pub use error::PerceptionError;
pub use geometry::{GeometryParams, GeometrySegmenter};
pub use kind::SegmenterKind;
pub use model_paths::{
    EnsembleModelPaths, SamModelPaths, SegmenterOptions, DEFAULT_POINTS_PER_SIDE,
};
pub use prior::PriorSegmenter;
pub use segmentation::{SegmentInfo, Segmentation};
pub use segmenter::{Segmenter, SegmenterInput};
pub use simulated::{SimulatedParams, SimulatedSegmenter};
