//! One stage as an OS process: spawn (pinned, niced, logging to a file), watch, stop.

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use crate::deploy::StageSpec;
use crate::watchdog::{sample_process, SilenceClock};

/// How often a quiet stage's CPU use is looked at (coarser than /proc's 10 ms ticks).
const SAMPLE_EVERY: Duration = Duration::from_millis(250);

/// Where a stage is in its life.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum StageState {
    Starting,
    Ready,
    /// Exited cleanly at end of data (sources) or on request.
    Finished,
    /// Dead, waiting for its restart back-off.
    Restarting,
    /// Dead with no restarts left.
    Failed,
    Stopped,
    /// Asked to stop for good by `opengs ctl scale` (never restarted); after its current
    /// message, or killed after [`crate::swap::RETIRE_GRACE`].
    Retired,
}

/// A stage process and its restart bookkeeping.
pub struct StageProcess {
    pub spec: StageSpec,
    /// Which of the stage's processes this is (0 for the first; replicas count up).
    pub replica: u32,
    /// Runs on another host (this supervisor never starts it; it knows it from the telemetry
    /// a bridge brings): that host's name.
    pub remote: Option<String>,
    pub state: StageState,
    pub restarts: u32,
    pub processed: u64,
    pub last_seq: Option<u64>,
    /// Latest progress of work after the end of data: (steps done, steps planned).
    pub work: Option<(u32, u32)>,
    child: Option<Child>,
    pid: Option<u32>,
    started_at: Instant,
    /// Last telemetry from the running process.
    last_heard: Instant,
    /// The watchdog's clock: silence not excused by CPU starvation.
    silence: SilenceClock,
    /// Times the watchdog killed it.
    pub hangs: u32,
    restart_at: Option<Instant>,
    /// When it was asked to stop for good ([`StageState::Retired`]).
    retired_at: Option<Instant>,
    log_path: PathBuf,
}

/// `name`, or `name#N` for replica N ≥ 1.
pub fn replica_label(name: &str, replica: u32) -> String {
    match replica {
        0 => name.to_string(),
        n => format!("{name}#{n}"),
    }
}

/// Finds a stage executable: an explicit path, else beside the running `opengs`, else on PATH.
pub fn resolve_binary(binary: &str) -> PathBuf {
    let p = Path::new(binary);
    if p.components().count() > 1 {
        return p.to_path_buf();
    }
    if let Some(dir) = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(Path::to_path_buf))
    {
        let candidate = dir.join(binary);
        if candidate.exists() {
            return candidate;
        }
        // Test binaries live in target/*/deps; stage binaries one level up.
        if let Some(up) = dir.parent() {
            let candidate = up.join(binary);
            if candidate.exists() {
                return candidate;
            }
        }
    }
    p.to_path_buf()
}

impl StageProcess {
    pub fn new(spec: StageSpec, log_dir: &Path) -> Self {
        Self::replica(spec, log_dir, 0)
    }

    /// Process number `replica` of the stage (`replicas` in the deploy file).
    pub fn replica(spec: StageSpec, log_dir: &Path, replica: u32) -> Self {
        let log_path = log_dir.join(format!("{}.log", replica_label(&spec.name, replica)));
        Self {
            remote: None,
            spec,
            replica,
            state: StageState::Starting,
            restarts: 0,
            processed: 0,
            last_seq: None,
            work: None,
            child: None,
            pid: None,
            started_at: Instant::now(),
            last_heard: Instant::now(),
            silence: SilenceClock::new(Instant::now()),
            hangs: 0,
            restart_at: None,
            retired_at: None,
            log_path,
        }
    }

    /// The stage's name, with `#N` for replicas after the first (`segmenter#2`).
    pub fn label(&self) -> String {
        replica_label(&self.spec.name, self.replica)
    }

    /// Asks it to stop for good after its current message (`opengs ctl scale` down).
    pub fn retire(&mut self) {
        self.signal(opengs_runtime::STOP_SIGNAL);
        self.state = StageState::Retired;
        self.retired_at = Some(Instant::now());
    }

    /// Retired, still running past `grace`: killed (it was stuck in one message).
    pub fn retire_overdue(&mut self, grace: Duration) -> bool {
        let overdue = self.state == StageState::Retired
            && self.child.is_some()
            && self.retired_at.is_some_and(|t| t.elapsed() > grace);
        if overdue {
            self.signal(libc::SIGKILL);
        }
        overdue
    }

    pub fn pid(&self) -> Option<u32> {
        self.pid
    }

    pub fn log_path(&self) -> &Path {
        &self.log_path
    }

    pub fn started_at(&self) -> Instant {
        self.started_at
    }

    /// Starts the process with `extra` arguments after the deploy file's own.
    pub fn spawn(&mut self, extra: &[String]) -> anyhow::Result<()> {
        let binary = resolve_binary(&self.spec.binary);
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.log_path)
            .map_err(|e| {
                anyhow::anyhow!(
                    "stage {}: log file {}: {e}",
                    self.label(),
                    self.log_path.display()
                )
            })?;
        let log_err = log.try_clone()?;
        let mut cmd = Command::new(&binary);
        cmd.args(self.spec.kind_args())
            .args(extra)
            .stdin(Stdio::null())
            .stdout(log)
            .stderr(log_err)
            // Own process group: Ctrl-C reaches the supervisor, which stops stages in order.
            .process_group(0);
        // Only the supervisor speaks to systemd for the service.
        for var in crate::service_notify::SERVICE_ENV {
            cmd.env_remove(var);
        }
        let cpus = self.spec.cpus.clone();
        let nice = self.spec.nice;
        let policy = self.spec.scheduler.policy();
        // SAFETY: only async-signal-safe libc calls between fork and exec.
        unsafe {
            cmd.pre_exec(move || {
                // Die with the supervisor, whatever kills it.
                libc::prctl(libc::PR_SET_PDEATHSIG, opengs_runtime::STOP_SIGNAL);
                if policy != libc::SCHED_OTHER {
                    let param = libc::sched_param { sched_priority: 0 };
                    // Ignore failure (a kernel without the policy): normal scheduling.
                    libc::sched_setscheduler(0, policy, &param);
                }
                if nice != 0 {
                    libc::setpriority(libc::PRIO_PROCESS, 0, nice);
                }
                if !cpus.is_empty() {
                    let mut set: libc::cpu_set_t = std::mem::zeroed();
                    for &c in &cpus {
                        libc::CPU_SET(c, &mut set);
                    }
                    // Ignore failure (cpus absent on this machine): run unpinned.
                    libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
                }
                Ok(())
            });
        }
        let child = cmd.spawn().map_err(|e| {
            anyhow::anyhow!(
                "stage {}: cannot start {}: {e}",
                self.label(),
                binary.display()
            )
        })?;
        self.pid = Some(child.id());
        self.child = Some(child);
        self.state = StageState::Starting;
        self.started_at = Instant::now();
        self.last_heard = Instant::now();
        self.silence.heard(self.last_heard);
        self.restart_at = None;
        Ok(())
    }

    /// Exit status if the process has ended since the last call.
    pub fn poll_exit(&mut self) -> Option<ExitStatus> {
        let child = self.child.as_mut()?;
        match child.try_wait() {
            Ok(Some(status)) => {
                self.child = None;
                Some(status)
            }
            Ok(None) => None,
            Err(e) => {
                tracing::warn!("stage {}: wait failed: {e}", self.label());
                None
            }
        }
    }

    /// Sends `signal` to the running process (e.g. the finish signal); false if none runs.
    pub fn signal(&self, signal: i32) -> bool {
        match &self.child {
            Some(child) => {
                // SAFETY: signalling our own child by pid.
                unsafe { libc::kill(child.id() as i32, signal) == 0 }
            }
            None => false,
        }
    }

    /// A stage on another host, known from its telemetry.
    pub fn remote(spec: StageSpec, log_dir: &Path, replica: u32) -> Self {
        let mut p = Self::replica(spec, log_dir, replica);
        p.remote = p.spec.host.clone();
        p
    }

    /// Telemetry of a remote stage arrived from `pid` (its pid on its own host).
    pub fn heard_remotely(&mut self, pid: u32) {
        self.pid = Some(pid);
        self.last_heard = Instant::now();
        if self.state == StageState::Starting {
            self.state = StageState::Ready;
        }
    }

    /// Telemetry arrived from `pid`: the process is alive if it is this one.
    pub fn heard_from(&mut self, pid: u32) {
        if self.pid == Some(pid) {
            self.last_heard = Instant::now();
            self.silence.heard(self.last_heard);
        }
    }

    /// Ready but silent for longer than its `watchdog_s` (not counting time it waited for a
    /// CPU, see [`crate::watchdog`]): hung, stopped or deadlocked.
    pub fn silent_for(&mut self) -> Option<Duration> {
        let limit = self.spec.watchdog_s;
        if !(limit > 0.0 && self.state == StageState::Ready && self.child.is_some()) {
            return None;
        }
        let now = Instant::now();
        // /proc is read only for a stage already quiet for a while, a few times a second.
        if now.duration_since(self.last_heard) >= SAMPLE_EVERY
            && now.duration_since(self.silence.last_tick()) >= SAMPLE_EVERY
        {
            let sample = self.pid.and_then(sample_process);
            self.silence.tick(now, sample);
        }
        let silent = self.silence.silent();
        (silent.as_secs_f64() > limit).then_some(silent)
    }

    /// SIGKILL, leaving the exit to [`Self::poll_exit`] (a stopped process cannot act on SIGTERM).
    pub fn kill_hung(&mut self) {
        self.hangs += 1;
        self.state = StageState::Stopped;
        self.signal(libc::SIGKILL);
    }

    pub fn is_running(&self) -> bool {
        self.child.is_some()
    }

    /// Schedules a restart after exponential back-off; false when the limit is reached.
    pub fn schedule_restart(&mut self) -> bool {
        if self.restarts >= self.spec.restart_limit {
            self.state = StageState::Failed;
            return false;
        }
        let backoff = Duration::from_millis(200 * (1 << self.restarts.min(5)));
        self.restarts += 1;
        self.state = StageState::Restarting;
        self.restart_at = Some(Instant::now() + backoff);
        true
    }

    pub fn restart_due(&self) -> bool {
        self.state == StageState::Restarting && self.restart_at.is_some_and(|t| Instant::now() >= t)
    }

    /// SIGTERM without waiting: the stage ends after the message it is working on.
    pub fn request_stop(&mut self) {
        self.signal(opengs_runtime::STOP_SIGNAL);
        if !matches!(self.state, StageState::Finished | StageState::Retired) {
            self.state = StageState::Stopped;
        }
    }

    /// SIGTERM, then SIGKILL after `grace`; waits for the process to end.
    pub fn stop(&mut self, grace: Duration) {
        let Some(mut child) = self.child.take() else {
            return;
        };
        // SAFETY: signalling our own child by pid.
        unsafe { libc::kill(child.id() as i32, opengs_runtime::STOP_SIGNAL) };
        let deadline = Instant::now() + grace;
        loop {
            match child.try_wait() {
                Ok(Some(_)) => break,
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(10))
                }
                _ => {
                    tracing::warn!(
                        "stage {} did not stop in {grace:?}; killing it",
                        self.label()
                    );
                    let _ = child.kill();
                    let _ = child.wait();
                    break;
                }
            }
        }
        if !matches!(self.state, StageState::Finished | StageState::Retired) {
            self.state = StageState::Stopped;
        }
    }

    /// Last lines of the stage's log, for error messages.
    pub fn log_tail(&self, lines: usize) -> String {
        let text = std::fs::read_to_string(&self.log_path).unwrap_or_default();
        let all: Vec<&str> = text.lines().collect();
        all[all.len().saturating_sub(lines)..].join("\n")
    }
}

impl Drop for StageProcess {
    fn drop(&mut self) {
        // Never leave a stage behind, whatever path the supervisor leaves by.
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}
