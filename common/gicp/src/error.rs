/// Why a registration (or one of its inputs) was refused.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum GicpError {
    #[error("{what} point cloud is empty")]
    EmptyCloud { what: &'static str },
    #[error("{what} point cloud has {found} points, at least {needed} are needed")]
    TooFewPoints {
        what: &'static str,
        found: usize,
        needed: usize,
    },
    #[error("degenerate input: {0}")]
    Degenerate(String),
    #[error("only {found} source points have a target point within the maximum correspondence distance, at least {needed} are needed")]
    TooFewCorrespondences { found: usize, needed: usize },
    #[error("{0} have different lengths")]
    LengthMismatch(&'static str),
    #[error("invalid input: {0}")]
    Invalid(String),
}
