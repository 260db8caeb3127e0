//! Logging setup shared by every process: `RUST_LOG`-style filter, stderr.

use std::io::IsTerminal;

/// Initialises tracing to stderr; `default` is the filter when `RUST_LOG` is unset.
pub fn init(default: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        // Colour codes only for a terminal: stage logs are files the supervisor quotes.
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
}
