//! What can go wrong when a request names objects, pixels or files.

use std::path::PathBuf;

/// Every error names the label, class, pixel, box or file at fault.
#[derive(Debug, thiserror::Error)]
pub enum ObjectError {
    #[error("the map has no labels: every Gaussian carries label 0 (a map.ply from a run with a segmenter has them)")]
    NoLabels,
    #[error("label 0 is the background (unlabelled Gaussians), not an object")]
    Background,
    #[error("label {label} {reason}; labels in the map: {known}")]
    UnknownLabel {
        label: u32,
        reason: String,
        known: String,
    },
    #[error(
        "no class names: --class needs a labels.json (none next to the map; give --labels FILE)"
    )]
    NoClassNames,
    #[error("class '{class}' is not in {catalog}; classes there: {known}")]
    UnknownClass {
        class: String,
        catalog: String,
        known: String,
    },
    #[error("empty selection: {0}")]
    EmptySelection(String),
    #[error("pixel ({u}, {v}) is outside the {width}x{height} image")]
    PixelOutside {
        u: u32,
        v: u32,
        width: u32,
        height: u32,
    },
    #[error("box {x0},{y0},{x1},{y1}: {reason}")]
    BadBox {
        x0: u32,
        y0: u32,
        x1: u32,
        y1: u32,
        reason: String,
    },
    #[error("rotation axis {0:?} has no direction (zero or not finite)")]
    BadAxis([f64; 3]),
    #[error("{what} {value:?} is not finite")]
    NotFinite { what: &'static str, value: Vec<f64> },
    #[error("{path}: {message}")]
    File { path: PathBuf, message: String },
}

impl ObjectError {
    pub fn file(path: impl Into<PathBuf>, message: impl ToString) -> Self {
        Self::File {
            path: path.into(),
            message: message.to_string(),
        }
    }
}

pub type Result<T, E = ObjectError> = std::result::Result<T, E>;
