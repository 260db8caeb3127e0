//! One process-wide ONNX Runtime environment, loaded from `ORT_DYLIB_PATH`.

use std::path::Path;
use std::sync::OnceLock;

use ort::environment::Environment;
use ort::session::Session;

use crate::PerceptionError;

static ENVIRONMENT: OnceLock<Result<Environment, String>> = OnceLock::new();

const INSTALL_HINT: &str = "set ORT_DYLIB_PATH to libonnxruntime.so.1.31.1 \
    (pip download --no-deps onnxruntime==1.31.1, then unzip onnxruntime/capi/libonnxruntime.so.1.31.1)";

/// The shared environment; an `Unavailable` error says what to install.
pub fn environment() -> Result<Environment, PerceptionError> {
    ENVIRONMENT
        .get_or_init(|| {
            let path = std::env::var_os("ORT_DYLIB_PATH")
                .ok_or_else(|| format!("ORT_DYLIB_PATH is not set: {INSTALL_HINT}"))?;
            ort::init_from(&path)
                .map_err(|e| {
                    format!(
                        "cannot load {}: {e}; {INSTALL_HINT}",
                        Path::new(&path).display()
                    )
                })?
                .with_name("opengs-perception")
                .build()
                .map_err(|e| format!("ONNX Runtime environment: {e}"))
        })
        .clone()
        .map_err(|reason| PerceptionError::Unavailable {
            kind: "onnx".into(),
            reason,
        })
}

/// Loads one model file.
pub fn load_session(path: &Path, threads: usize) -> Result<Session, PerceptionError> {
    let env = environment()?;
    let model_error = |e: String| PerceptionError::Model {
        path: path.to_path_buf(),
        message: e,
    };
    Session::builder(&env)
        .map_err(|e| model_error(e.to_string()))?
        .with_intra_threads(threads.max(1))
        .map_err(|e| model_error(e.to_string()))?
        .commit_from_file(path)
        .map_err(|e| model_error(e.to_string()))
}
