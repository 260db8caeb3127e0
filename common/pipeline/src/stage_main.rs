//! What every stage binary's `main` does around its stage loop.

use std::process::ExitCode;

use opengs_runtime::RunContext;

/// The exit status of a stage that stopped on input it cannot use (sysexits' EX_DATAERR).
pub const BAD_INPUT_EXIT: u8 = 65;

/// Input a stage cannot use (a corrupt frame, say): the stage exits [`BAD_INPUT_EXIT`] and the
/// supervisor does not restart it, since a restart would read the same input again.
#[derive(Debug, thiserror::Error)]
#[error("bad input: {0}")]
pub struct BadInput(pub String);

/// Logs to stderr, joins the run, runs `stage`, and turns an error into a message and exit
/// code 1 ([`BAD_INPUT_EXIT`] for [`BadInput`]).
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
            match e.downcast_ref::<BadInput>() {
                Some(_) => ExitCode::from(BAD_INPUT_EXIT),
                None => ExitCode::FAILURE,
            }
        }
    }
}
