//! The supervisor's side of a systemd `Type=notify` unit (`deploy/opengs.service`):
//! - `READY=1` once every stage has reported ready (so `systemctl start` returns when the
//!   pipeline runs, and a start-up failure fails the start);
//! - `STATUS=` with frames, poses, lost frames and restarts while it runs (`systemctl status`);
//! - `WATCHDOG=1` from the main loop at half the unit's `WatchdogSec=`, so a supervisor that
//!   hangs is killed and restarted by systemd (the supervisor itself watches the stages);
//! - `STOPPING=1` when the data ends or a stop begins.
//!
//! Without `NOTIFY_SOCKET` in the environment (not started by systemd) nothing is sent. The
//! stages never see these variables ([`SERVICE_ENV`] is removed from their environment), so
//! only the supervisor speaks for the service.

use std::time::{Duration, Instant};

use sd_notify::NotifyState;

/// The variables systemd passes to the service's main process only.
pub const SERVICE_ENV: [&str; 3] = ["NOTIFY_SOCKET", "WATCHDOG_USEC", "WATCHDOG_PID"];

/// How often `STATUS=` is refreshed without a watchdog asking for more.
const STATUS_EVERY: Duration = Duration::from_secs(2);

/// Notifications to systemd, paced for the main loop.
pub struct ServiceNotifier {
    enabled: bool,
    /// Ping interval: half of `WATCHDOG_USEC`, as sd_watchdog_enabled(3) advises.
    ping_every: Option<Duration>,
    last_ping: Instant,
    last_status: Instant,
}

impl ServiceNotifier {
    /// Reads `NOTIFY_SOCKET` and `WATCHDOG_USEC`/`WATCHDOG_PID` from the environment.
    pub fn from_env() -> Self {
        let enabled = std::env::var_os("NOTIFY_SOCKET").is_some();
        let ping_every = sd_notify::watchdog_enabled()
            .filter(|_| enabled)
            .map(|t| t / 2);
        if let Some(p) = ping_every {
            tracing::info!("systemd watchdog: pinging every {:.2} s", p.as_secs_f64());
        }
        Self {
            enabled,
            ping_every,
            last_ping: Instant::now(),
            last_status: Instant::now(),
        }
    }

    /// Every stage is up.
    pub fn ready(&mut self, status: &str) {
        self.send(&[NotifyState::Ready, NotifyState::Status(status)]);
        self.last_status = Instant::now();
        self.last_ping = Instant::now();
    }

    /// A new `STATUS=` line is due (build it only then: see [`Self::tick`]).
    pub fn status_due(&self) -> bool {
        self.enabled && self.last_status.elapsed() >= STATUS_EVERY
    }

    /// Called every main-loop iteration: a watchdog ping when one is due, and the status
    /// line when [`Self::status_due`] said so.
    pub fn tick(&mut self, status: Option<&str>) {
        if !self.enabled {
            return;
        }
        if let Some(status) = status {
            self.last_status = Instant::now();
            self.send(&[NotifyState::Status(status)]);
        }
        if self
            .ping_every
            .is_some_and(|p| self.last_ping.elapsed() >= p)
        {
            self.last_ping = Instant::now();
            self.send(&[NotifyState::Watchdog]);
        }
    }

    /// The run is ending (end of data, stop, interrupt or failure): the final work follows.
    pub fn stopping(&mut self, status: &str) {
        self.send(&[NotifyState::Stopping, NotifyState::Status(status)]);
    }

    fn send(&self, states: &[NotifyState]) {
        if !self.enabled {
            return;
        }
        // systemd gone or the socket full: the run goes on, said once per call in the log.
        if let Err(e) = sd_notify::notify(states) {
            tracing::warn!("systemd notification: {e}");
        }
    }
}
