//! Errors of quality evaluation and refinement; every file error names its file.

use std::path::PathBuf;

use opengs_datasets::DatasetError;
use opengs_eval::TrajectoryError;

#[derive(Debug, thiserror::Error)]
pub enum QualityError {
    // The underlying error is part of the message (not a `source`) so it prints once.
    #[error("{path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: {error}")]
    Image {
        path: PathBuf,
        error: image::ImageError,
    },
    #[error("{path}: {message}")]
    Json { path: PathBuf, message: String },
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    #[error(transparent)]
    Trajectory(#[from] TrajectoryError),
    /// A map file that could not be read.
    #[error("{path}: {message}")]
    Map { path: PathBuf, message: String },
    /// A frame whose buffers do not match its size or the camera's.
    #[error("frame {index}: {message}")]
    Frame { index: usize, message: String },
    #[error("no frame could be evaluated ({reason})")]
    NoFrames { reason: String },
}
