use thiserror::Error;

#[derive(Debug, Error)]
pub enum PerceptionError {
    /// A buffer's length does not match the frame size.
    #[error("{what}: expected {expected} elements for the frame size, got {got}")]
    InputSize {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("invalid segmenter input: {0}")]
    InvalidInput(String),
    /// The prior segmenter needs the dataset's instance image.
    #[error("frame has no ground-truth instance labels (the prior segmenter needs a dataset with labels, e.g. synthetic or Replica)")]
    MissingLabels,
    #[error("unknown segmenter '{0}': expected geometry, classic, prior, sam or mobilesamv2")]
    UnknownKind(String),
    /// The segmenter exists in the interface but cannot run in this build/config.
    #[error("segmenter '{kind}' is unavailable: {reason}")]
    Unavailable { kind: String, reason: String },
    /// An ONNX model failed to load or run, or has unexpected outputs.
    #[error("model {path}: {message}")]
    Model {
        path: std::path::PathBuf,
        message: String,
    },
    /// A side file of a model (tag list, text embeddings) is missing or malformed.
    #[error("{path}: {message}")]
    File {
        path: std::path::PathBuf,
        message: String,
    },
    #[error(transparent)]
    Dataset(#[from] opengs_datasets::DatasetError),
}
