//! Make-before-break swap of a stage's kind (`opengs ctl swap STAGE --to KIND`):
//!
//! 1. **starting**: the new kind's process starts beside the running one, with the kind's own
//!    arguments from the deploy file. It loads and checks its models, and runs them once on a
//!    blank frame (`--warm-up`), before it reports ready: a bad model set ends here (the new
//!    process exits, the old one never noticed), and its first keyframe runs at full speed;
//! 2. **retiring**: the new process takes the stage's place and the old one is asked to stop.
//!    A stage stops between two messages, so a busy old process finishes its keyframe, unless
//!    that takes longer than [`RETIRE_GRACE`]: then it is killed mid-keyframe;
//! 3. **first output**: the swap is reported once the new process has processed its first
//!    message (or after [`FIRST_OUTPUT_WAIT`], or when the run ends), with the time it took
//!    and the gap between the last output of the old kind and the first of the new.
//!
//! The outcome goes back to `opengs ctl` as one JSON [`SwapOutcome`].

use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::stage_process::{StageProcess, StageState};

/// How long an old process may take to finish its current message once asked to stop.
pub const RETIRE_GRACE: Duration = Duration::from_secs(5);
/// How long after the new process is ready the swap waits for its first output.
pub const FIRST_OUTPUT_WAIT: Duration = Duration::from_secs(60);

/// What a finished swap reports (`ok` false: the old kind still runs, `error` says why).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct SwapOutcome {
    pub ok: bool,
    pub stage: String,
    pub from: String,
    pub to: String,
    /// The new process (when it started).
    pub pid: Option<u32>,
    /// Seconds from the request to the new process reporting ready.
    pub ready_s: Option<f64>,
    /// Seconds from the request to the new kind's first output.
    pub first_output_s: Option<f64>,
    /// Milliseconds between the old kind's last output and the new kind's first.
    pub gap_ms: Option<f64>,
    /// How the old process ended: at a message boundary, or killed after the grace period.
    pub old_process: Option<String>,
    pub error: Option<String>,
}

impl SwapOutcome {
    /// The lines `opengs ctl swap` prints.
    pub fn describe(&self) -> String {
        if !self.ok {
            return format!(
                "swap {} to {} failed; {} keeps running: {}",
                self.stage,
                self.to,
                self.from,
                self.error.as_deref().unwrap_or("no reason given")
            );
        }
        let secs = |v: Option<f64>| v.map_or("-".to_string(), |s| format!("{s:.2} s"));
        let mut s = format!(
            "swapped {} from {} to {} (pid {})\n  ready after {}",
            self.stage,
            self.from,
            self.to,
            self.pid.map_or("-".into(), |p| p.to_string()),
            secs(self.ready_s)
        );
        match self.first_output_s {
            Some(_) => s.push_str(&format!(
                "; first output after {}",
                secs(self.first_output_s)
            )),
            None => s.push_str("; no output from the new kind yet (no input reached it)"),
        }
        if let Some(gap) = self.gap_ms {
            s.push_str(&format!(
                "\n  gap between the old kind's last output and the new kind's first: {gap:.0} ms"
            ));
        }
        if let Some(old) = &self.old_process {
            s.push_str(&format!("\n  old process: {old}"));
        }
        s
    }
}

enum Phase {
    /// The new process starts beside the old one.
    Starting(StageProcess),
    /// The new process runs the stage; the old one is finishing its current message.
    Retiring { old: StageProcess, since: Instant },
    /// Both done but the new kind has not produced anything yet.
    AwaitingOutput { since: Instant },
}

/// One swap in progress (at most one per run).
pub struct Swap {
    /// The stage's index in the supervisor's stage list.
    pub index: usize,
    pub request_id: u64,
    requested: Instant,
    phase: Phase,
    new_ready: bool,
    new_pid: Option<u32>,
    /// End time (ns, the stages' clock) of the old process's latest output.
    old_last_output_ns: Option<u64>,
    new_first_output: Option<(Instant, u64)>,
    outcome: SwapOutcome,
    /// [`RETIRE_GRACE`], shorter in tests.
    retire_grace: Duration,
}

/// What the supervisor must do after [`Swap::advance`].
pub enum SwapStep {
    /// Nothing yet.
    Waiting,
    /// Put this process in the stage's place and keep going (the old one is retiring).
    Promote(Box<StageProcess>),
    /// The swap is over: reply with this.
    Done(SwapOutcome),
}

impl Swap {
    /// Tracks a new process already spawned for `index`, replacing the running kind `from`.
    pub fn new(index: usize, request_id: u64, from: &str, process: StageProcess) -> Self {
        let outcome = SwapOutcome {
            stage: process.spec.name.clone(),
            from: from.to_string(),
            to: process.spec.kind.clone().unwrap_or_default(),
            pid: process.pid(),
            ..SwapOutcome::default()
        };
        Self {
            index,
            request_id,
            requested: Instant::now(),
            new_pid: process.pid(),
            phase: Phase::Starting(process),
            new_ready: false,
            old_last_output_ns: None,
            new_first_output: None,
            outcome,
            retire_grace: RETIRE_GRACE,
        }
    }

    /// Telemetry of any process of the swapped stage: readiness and outputs, by pid.
    pub fn observe_ready(&mut self, pid: u32) {
        if Some(pid) == self.new_pid && !self.new_ready {
            self.new_ready = true;
            self.outcome.ready_s = Some(self.requested.elapsed().as_secs_f64());
        }
    }

    pub fn observe_output(&mut self, pid: u32, end_ns: u64) {
        if Some(pid) == self.new_pid {
            if self.new_first_output.is_none() {
                self.new_first_output = Some((Instant::now(), end_ns));
            }
        } else {
            self.old_last_output_ns =
                Some(self.old_last_output_ns.map_or(end_ns, |t| t.max(end_ns)));
        }
    }

    /// Moves the swap on; `current` is the process now in the stage's place; `startup_timeout`
    /// bounds the new process's start. Notes for the log go to `notes`.
    pub fn advance(
        &mut self,
        current: &mut StageProcess,
        startup_timeout: Duration,
        notes: &mut Vec<String>,
    ) -> SwapStep {
        let name = self.outcome.stage.clone();
        match &mut self.phase {
            Phase::Starting(process) => {
                let failed = if let Some(status) = process.poll_exit() {
                    Some(format!(
                        "the new process exited during start-up ({status}); its log {} ends with:\n{}",
                        process.log_path().display(),
                        process.log_tail(6)
                    ))
                } else if !self.new_ready && self.requested.elapsed() > startup_timeout {
                    Some(format!(
                        "the new process was not ready within {} s; see {}",
                        startup_timeout.as_secs_f64(),
                        process.log_path().display()
                    ))
                } else {
                    None
                };
                if let Some(why) = failed {
                    process.stop(Duration::from_secs(1));
                    notes.push(format!("swap {name} failed: {why}"));
                    self.outcome.error = Some(why);
                    return SwapStep::Done(self.outcome.clone());
                }
                if !self.new_ready {
                    return SwapStep::Waiting;
                }
                // The new process takes over: it inherits the stage's history.
                let Phase::Starting(mut process) = std::mem::replace(
                    &mut self.phase,
                    Phase::AwaitingOutput {
                        since: Instant::now(),
                    },
                ) else {
                    return SwapStep::Waiting;
                };
                process.restarts = current.restarts;
                process.processed = current.processed;
                process.last_seq = current.last_seq;
                process.state = StageState::Ready;
                notes.push(format!(
                    "swap {name}: '{}' (pid {}) ready after {:.2} s; asking '{}' (pid {}) to stop \
                     after its current message (grace {} s)",
                    self.outcome.to,
                    process.pid().unwrap_or(0),
                    self.outcome.ready_s.unwrap_or(0.0),
                    self.outcome.from,
                    current.pid().unwrap_or(0),
                    self.retire_grace.as_secs_f64()
                ));
                SwapStep::Promote(Box::new(process))
            }
            Phase::Retiring { old, since } => {
                if old.poll_exit().is_some() {
                    let text = format!(
                        "'{}' stopped at a message boundary {:.2} s after the request to stop",
                        self.outcome.from,
                        since.elapsed().as_secs_f64()
                    );
                    notes.push(format!("swap {name}: old {text}"));
                    self.outcome.old_process = Some(text);
                    self.phase = Phase::AwaitingOutput { since: *since };
                } else if since.elapsed() > self.retire_grace {
                    old.stop(Duration::ZERO);
                    let text = format!(
                        "'{}' was still busy after the {} s grace period: killed mid-message",
                        self.outcome.from,
                        self.retire_grace.as_secs_f64()
                    );
                    notes.push(format!("swap {name}: old {text}"));
                    self.outcome.old_process = Some(text);
                    self.phase = Phase::AwaitingOutput { since: *since };
                }
                SwapStep::Waiting
            }
            Phase::AwaitingOutput { since } => {
                if let Some((at, end_ns)) = self.new_first_output {
                    self.outcome.first_output_s =
                        Some(at.duration_since(self.requested).as_secs_f64());
                    self.outcome.gap_ms = self
                        .old_last_output_ns
                        .map(|old| end_ns.saturating_sub(old) as f64 / 1e6);
                } else if since.elapsed() < FIRST_OUTPUT_WAIT {
                    return SwapStep::Waiting;
                }
                self.outcome.ok = true;
                notes.push(format!(
                    "swap {name}: '{}' → '{}' done",
                    self.outcome.from, self.outcome.to
                ));
                SwapStep::Done(self.outcome.clone())
            }
        }
    }

    /// After [`SwapStep::Promote`]: the process that left the stage's place retires.
    pub fn retire(&mut self, mut old: StageProcess) {
        old.request_stop();
        self.phase = Phase::Retiring {
            old,
            since: Instant::now(),
        };
    }

    /// The run ends with the swap unfinished: stop whatever it still holds and say so.
    pub fn abandon(mut self) -> SwapOutcome {
        match std::mem::replace(
            &mut self.phase,
            Phase::AwaitingOutput {
                since: Instant::now(),
            },
        ) {
            Phase::Starting(mut process) => {
                process.stop(Duration::from_secs(1));
                self.outcome.error = Some("the run ended before the new process was ready".into());
            }
            Phase::Retiring { mut old, .. } => {
                old.stop(Duration::from_secs(1));
                self.outcome.ok = true;
            }
            Phase::AwaitingOutput { .. } => self.outcome.ok = true,
        }
        self.outcome
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deploy::StageSpec;

    /// A stage process running `sh -c SCRIPT` as kind `kind`.
    fn process(kind: &str, script: &str, dir: &std::path::Path) -> StageProcess {
        let spec: StageSpec = toml::from_str(&format!(
            "name = \"segmenter\"\nbinary = \"sh\"\nkind = \"{kind}\"\nargs = [\"-c\", \"{script}\"]"
        ))
        .expect("spec");
        let mut p = StageProcess::new(spec, dir);
        p.spawn(&[]).expect("sh starts");
        p
    }

    /// Advances until the swap leaves `Waiting` (or 10 s pass).
    fn step(swap: &mut Swap, current: &mut StageProcess, notes: &mut Vec<String>) -> SwapStep {
        let until = Instant::now() + Duration::from_secs(10);
        loop {
            match swap.advance(current, Duration::from_secs(10), notes) {
                SwapStep::Waiting if Instant::now() < until => {
                    std::thread::sleep(Duration::from_millis(20))
                }
                other => return other,
            }
        }
    }

    #[test]
    fn a_new_kind_that_fails_to_start_leaves_the_old_one_running() {
        let dir = tempfile::tempdir().expect("tmp");
        let mut old = process("sam", "sleep 30", dir.path());
        let new = process(
            "mobilesamv2",
            "echo model broken.onnx: bad input; exit 3",
            dir.path(),
        );
        let mut swap = Swap::new(0, 7, "sam", new);
        let mut notes = Vec::new();
        let SwapStep::Done(outcome) = step(&mut swap, &mut old, &mut notes) else {
            panic!("a dead new process ends the swap")
        };
        assert!(!outcome.ok);
        let error = outcome.error.as_deref().unwrap_or_default();
        assert!(error.contains("exited during start-up"), "{error}");
        assert!(
            error.contains("model broken.onnx"),
            "the log tail is quoted: {error}"
        );
        assert!(old.is_running(), "the old kind was never touched");
        assert!(outcome.describe().contains("sam keeps running"));
        old.stop(Duration::from_secs(1));
    }

    #[test]
    fn a_ready_new_kind_takes_over_and_reports_its_first_output() {
        let dir = tempfile::tempdir().expect("tmp");
        let mut stage = process("sam", "sleep 30", dir.path());
        stage.processed = 12;
        let new = process("mobilesamv2", "sleep 30", dir.path());
        let new_pid = new.pid().expect("pid");
        let old_pid = stage.pid().expect("pid");
        let mut swap = Swap::new(0, 7, "sam", new);
        let mut notes = Vec::new();
        swap.observe_output(old_pid, 1_000_000_000);
        assert!(matches!(
            swap.advance(&mut stage, Duration::from_secs(10), &mut notes),
            SwapStep::Waiting
        ));
        swap.observe_ready(new_pid);
        let SwapStep::Promote(promoted) = step(&mut swap, &mut stage, &mut notes) else {
            panic!("a ready process is promoted")
        };
        assert_eq!(promoted.processed, 12, "the stage keeps its counters");
        let old = std::mem::replace(&mut stage, *promoted);
        swap.retire(old);
        // `sleep` ends on SIGTERM: a message boundary.
        let until = Instant::now() + Duration::from_secs(5);
        while swap.outcome.old_process.is_none() && Instant::now() < until {
            swap.advance(&mut stage, Duration::from_secs(10), &mut notes);
            std::thread::sleep(Duration::from_millis(20));
        }
        let old_text = swap.outcome.old_process.clone().unwrap_or_default();
        assert!(old_text.contains("message boundary"), "{old_text}");
        swap.observe_output(new_pid, 1_250_000_000);
        let SwapStep::Done(outcome) = step(&mut swap, &mut stage, &mut notes) else {
            panic!("the first output ends the swap")
        };
        assert!(outcome.ok);
        assert_eq!(outcome.pid, Some(new_pid));
        assert_eq!(outcome.gap_ms, Some(250.0));
        assert!(outcome.first_output_s.is_some() && outcome.ready_s.is_some());
        assert_eq!(
            (outcome.from.as_str(), outcome.to.as_str()),
            ("sam", "mobilesamv2")
        );
        stage.stop(Duration::from_secs(1));
    }

    #[test]
    fn an_old_process_busy_past_the_grace_period_is_killed() {
        let dir = tempfile::tempdir().expect("tmp");
        // Ignores SIGTERM, like a stage deep in a model call.
        let mut stage = process("sam", "trap '' TERM; echo trapped; sleep 30", dir.path());
        // The shell must have set its trap before the swap asks it to stop.
        let until = Instant::now() + Duration::from_secs(5);
        while !stage.log_tail(5).contains("trapped") && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(10));
        }
        let new = process("mobilesamv2", "sleep 30", dir.path());
        let new_pid = new.pid().expect("pid");
        let mut swap = Swap::new(0, 7, "sam", new);
        swap.retire_grace = Duration::from_millis(200);
        swap.observe_ready(new_pid);
        let mut notes = Vec::new();
        let SwapStep::Promote(promoted) = step(&mut swap, &mut stage, &mut notes) else {
            panic!("promoted")
        };
        let old = std::mem::replace(&mut stage, *promoted);
        swap.retire(old);
        let until = Instant::now() + Duration::from_secs(5);
        while swap.outcome.old_process.is_none() && Instant::now() < until {
            swap.advance(&mut stage, Duration::from_secs(10), &mut notes);
            std::thread::sleep(Duration::from_millis(20));
        }
        let text = swap.outcome.old_process.clone().unwrap_or_default();
        assert!(text.contains("killed mid-message"), "{text}");
        assert!(notes.iter().any(|n| n.contains("killed")), "{notes:?}");
        stage.stop(Duration::from_secs(1));
    }
}
