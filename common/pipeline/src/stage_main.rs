//! What every stage binary's `main` does around its stage loop.

use std::process::ExitCode;

use opengs_runtime::RunContext;

/// Logs to stderr, joins the run, runs `stage`, and turns an error into a message and exit code 1.
pub fn stage_main(
    name: &str,
    run_id: &str,
    stage: impl FnOnce(&RunContext) -> anyhow::Result<()>,
) -> ExitCode {
    crate::logging::init("info");
    let result = RunContext::new(run_id)
        .map_err(anyhow::Error::from)
        .and_then(|ctx| stage(&ctx));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{name}: {e:#}");
            ExitCode::FAILURE
        }
    }
}
