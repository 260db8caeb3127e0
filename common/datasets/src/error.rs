use std::path::{Path, PathBuf};

/// Everything that can go wrong opening or reading a dataset; each variant
/// names the file (and line) so a user can fix the input without a debugger.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not found")]
    Missing { path: PathBuf },
    #[error("{path}:{line}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("{path}: cannot decode image: {message}")]
    Image { path: PathBuf, message: String },
    #[error("{path}: image is {found_width}x{found_height}, expected {width}x{height}")]
    SizeMismatch {
        path: PathBuf,
        width: u32,
        height: u32,
        found_width: u32,
        found_height: u32,
    },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    /// A message of a ROS 2 bag: the bag file, the topic and the message's index in it.
    #[error("{path}: topic {topic}, message {index}: {message}")]
    BagMessage {
        path: PathBuf,
        topic: String,
        index: usize,
        message: String,
    },
    #[error("frame {index} out of range (dataset has {len} frames)")]
    OutOfRange { index: usize, len: usize },
    #[error("{0}")]
    Spec(String),
}

impl DatasetError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        if source.kind() == std::io::ErrorKind::NotFound {
            return Self::Missing {
                path: path.to_path_buf(),
            };
        }
        Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn parse(path: &Path, line: usize, message: impl Into<String>) -> Self {
        Self::Parse {
            path: path.to_path_buf(),
            line,
            message: message.into(),
        }
    }

    pub(crate) fn invalid(path: &Path, message: impl Into<String>) -> Self {
        Self::Invalid {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}
