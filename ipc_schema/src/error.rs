use crate::MessageKind;

/// Why a message was rejected. Receivers log it and drop the message.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SchemaError {
    #[error("schema version {found}, this build speaks {expected}")]
    Version { found: u32, expected: u32 },
    #[error("message kind {found} where {expected:?} was expected")]
    Kind { found: u32, expected: MessageKind },
    #[error("payload is {actual} bytes but the header says {declared}")]
    PayloadLength { declared: u64, actual: usize },
    #[error("header fields imply a {expected}-byte payload but it is {actual} bytes")]
    LayoutMismatch { expected: usize, actual: usize },
    #[error("image size {width}x{height} is out of range")]
    Dimensions { width: u32, height: u32 },
    #[error("{what} = {value} is out of range")]
    Count { what: &'static str, value: u64 },
    #[error("{0} is not finite")]
    NonFinite(&'static str),
    #[error("payload is not {0}-byte aligned")]
    Alignment(usize),
    #[error("payload writer filled {written} of {len} bytes")]
    Incomplete { written: usize, len: usize },
    #[error("{0}")]
    Invalid(&'static str),
}
