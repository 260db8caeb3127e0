/// Failures of the IPC runtime; each names what it was doing.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    #[error("iceoryx2: {0}")]
    Iceoryx(String),
    #[error("message rejected: {0}")]
    Schema(#[from] opengs_ipc_schema::SchemaError),
    #[error("invalid run id '{0}': use letters, digits, '-' and '_' only (at most 40)")]
    RunId(String),
    #[error("{0}")]
    Io(#[from] std::io::Error),
}
