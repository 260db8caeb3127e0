//! Exit statuses of `opengs`, for scripts and service managers:
//! 0 done (also after `opengs ctl stop`, a requested end); 1 an error (bad input, a missing
//! file, ...; the message names it); 2 a bad command line (clap); 3 a stage died more often
//! than its restart limit allows; 4 a stage stopped on input it cannot use (a corrupt frame:
//! not restarted, it would read the same input; outputs so far are written); 130 interrupted
//! by Ctrl-C or SIGTERM (outputs are written).

use std::process::ExitCode;

use opengs_pipeline::{StageFailed, StoppedOnBadInput};

/// The run was interrupted before the end of its data (Ctrl-C or SIGTERM).
#[derive(Debug, thiserror::Error)]
#[error("interrupted")]
pub struct Interrupted;

pub const ERROR: u8 = 1;
pub const STAGE_FAILED: u8 = 3;
pub const BAD_INPUT: u8 = 4;
pub const INTERRUPTED: u8 = 130;

/// The exit status for `e`, after printing it (an interruption prints nothing more: the
/// summary already says so).
pub fn code_of(e: &anyhow::Error) -> ExitCode {
    if e.downcast_ref::<Interrupted>().is_some() {
        return ExitCode::from(INTERRUPTED);
    }
    eprintln!("error: {e:#}");
    if e.downcast_ref::<StoppedOnBadInput>().is_some() {
        return ExitCode::from(BAD_INPUT);
    }
    match e.downcast_ref::<StageFailed>() {
        Some(_) => ExitCode::from(STAGE_FAILED),
        None => ExitCode::from(ERROR),
    }
}
