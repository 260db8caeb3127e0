//! iceoryx2 helpers: run-namespaced nodes, zero-copy publish, WaitSet-woken
//! subscribe, clean shutdown and dead-node cleanup. Stage `main`s stay short.

mod active_run;
mod channel;
mod context;
mod error;
mod signals;
mod telemetry_sink;

pub use active_run::{process_alive, ActiveRun, ActiveRuns, CleanError, CleanReport, CleanedRun};
pub use channel::{Inlet, Outlet, Received};
pub use context::{leftover_files, runs_with_files, RunContext};
pub use error::RuntimeError;
pub use signals::{finish_requested_flag, FINISH_SIGNAL, STOP_SIGNAL};
pub use telemetry_sink::{TelemetrySink, HEARTBEAT};

pub use iceoryx2;
pub use iceoryx2::prelude::{CallbackProgression, WaitSetAttachmentId};
pub use iceoryx2::waitset::WaitSetRunResult;

/// The iceoryx2 service flavour every stage uses.
pub type Ipc = iceoryx2::prelude::ipc::Service;
/// The WaitSet type stages sleep on.
pub type WaitSet = iceoryx2::prelude::WaitSet<Ipc>;

/// Creates a WaitSet; it also returns on SIGINT/SIGTERM.
pub fn waitset() -> Result<WaitSet, RuntimeError> {
    iceoryx2::prelude::WaitSetBuilder::new()
        .create::<Ipc>()
        .map_err(|e| RuntimeError::Iceoryx(format!("creating a WaitSet: {e:?}")))
}
