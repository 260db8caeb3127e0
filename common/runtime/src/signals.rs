//! The signal protocol between the supervisor and its stage processes: SIGTERM asks a stage to
//! stop now (it exits through its WaitSet's termination request, keeping what it has);
//! [`FINISH_SIGNAL`] asks it to finish its remaining work first (the mapper's final
//! optimisation) and then exit; a stage also gets SIGTERM when the supervisor dies.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use crate::{CallbackProgression, RuntimeError, WaitSet};

/// Stop now.
pub const STOP_SIGNAL: i32 = libc::SIGTERM;

/// Finish the remaining work, then exit.
pub const FINISH_SIGNAL: i32 = libc::SIGUSR1;

/// Registers the finish signal; the returned flag turns true when it arrives. iceoryx2
/// installs its own handlers for every non-fatal signal (without chaining) the first time a
/// WaitSet checks for termination, so that check is made first: ours then chains to its.
pub fn finish_requested_flag(ws: &WaitSet) -> Result<Arc<AtomicBool>, RuntimeError> {
    let _ =
        ws.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, Duration::ZERO);
    let flag = Arc::new(AtomicBool::new(false));
    signal_hook::flag::register(FINISH_SIGNAL, Arc::clone(&flag))?;
    Ok(flag)
}
