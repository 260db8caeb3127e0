//! `opengs ctl scale STAGE --to N`: change how many processes (replicas) of a stage run while
//! the pipeline goes on. Make-before-break, as [`crate::swap`]:
//!
//! - **up**: the new replicas start beside the running ones, with the stage's current kind and
//!   arguments; each joins the stage once it reports ready. One that exits or never gets
//!   ready makes the scale fail (the others stay: the reply says how many run);
//! - **down**: the newest replicas are retired: each stops after the keyframe it is working
//!   on (killed after [`crate::swap::RETIRE_GRACE`]), and is never restarted. The other
//!   replicas never stop, so the stage's output has no gap.
//!
//! The outcome goes back to `opengs ctl` as one JSON [`ScaleOutcome`].

use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::deploy::check_replicas;
use crate::stage_process::{StageProcess, StageState};

/// What a finished scale reports.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct ScaleOutcome {
    pub ok: bool,
    pub stage: String,
    /// Replicas running before, asked for, and running after.
    pub from: u32,
    pub to: u32,
    pub running: u32,
    /// New processes that joined: `label (pid N)`.
    pub started: Vec<String>,
    /// Processes retired: `label (pid N)`, and how each ended.
    pub retired: Vec<String>,
    /// Seconds from the request to the last new replica ready (scaling up).
    pub ready_s: Option<f64>,
    pub error: Option<String>,
}

impl ScaleOutcome {
    /// The lines `opengs ctl scale` prints.
    pub fn describe(&self) -> String {
        let mut s = match self.ok {
            true => format!(
                "scaled {} from {} to {} replicas",
                self.stage, self.from, self.running
            ),
            false => format!(
                "scale {} to {} failed; {} replicas run: {}",
                self.stage,
                self.to,
                self.running,
                self.error.as_deref().unwrap_or("no reason given")
            ),
        };
        if !self.started.is_empty() {
            s.push_str(&format!("\n  started: {}", self.started.join(", ")));
            if let Some(t) = self.ready_s {
                s.push_str(&format!(" (ready after {t:.2} s)"));
            }
        }
        if !self.retired.is_empty() {
            s.push_str(&format!("\n  retired: {}", self.retired.join(", ")));
        }
        s
    }
}

/// Processes of `stage` doing its work (not retired, not failed for good).
pub fn active_replicas(stages: &[StageProcess], stage: &str) -> Vec<usize> {
    (0..stages.len())
        .filter(|&i| {
            stages[i].spec.name == stage
                && !matches!(stages[i].state, StageState::Retired | StageState::Failed)
        })
        .collect()
}

/// What a scale request changes.
#[derive(Debug, PartialEq)]
pub struct ScalePlan {
    pub from: u32,
    /// Replica numbers to start (after every number the stage has used).
    pub add: Vec<u32>,
    /// Indices (into the stage list) of the replicas to retire, newest first.
    pub retire: Vec<usize>,
}

/// Plans `stage` → `to` replicas, or says why not.
pub fn plan(stages: &[StageProcess], stage: &str, to: u32) -> Result<ScalePlan, String> {
    if !stages.iter().any(|s| s.spec.name == stage) {
        return Err(format!("no stage '{stage}' in this pipeline"));
    }
    check_replicas(stage, to)?;
    let active = active_replicas(stages, stage);
    let from = active.len() as u32;
    if from == to {
        return Err(format!("stage '{stage}' already runs {to} replicas"));
    }
    let next = stages
        .iter()
        .filter(|s| s.spec.name == stage)
        .map(|s| s.replica + 1)
        .max()
        .unwrap_or(0);
    let mut by_age = active;
    by_age.sort_by_key(|&i| std::cmp::Reverse(stages[i].replica));
    Ok(ScalePlan {
        from,
        add: (next..next + to.saturating_sub(from)).collect(),
        retire: by_age
            .into_iter()
            .take(from.saturating_sub(to) as usize)
            .collect(),
    })
}

/// One scale in progress (at most one per run, never beside a swap).
pub struct Scale {
    pub request_id: u64,
    requested: Instant,
    /// New processes not ready yet.
    starting: Vec<StageProcess>,
    /// Pids of the retired processes still running.
    retiring: Vec<u32>,
    outcome: ScaleOutcome,
}

impl Scale {
    /// Tracks `started` (spawned already) and the processes at `retire` (asked to stop here)
    /// for the request `(to, request_id, when it came)`.
    pub fn new(
        stages: &mut [StageProcess],
        stage: &str,
        plan: &ScalePlan,
        (to, request_id, requested): (u32, u64, Instant),
        started: Vec<StageProcess>,
    ) -> Self {
        let mut retiring = Vec::new();
        let mut retired = Vec::new();
        for &i in &plan.retire {
            stages[i].retire();
            retiring.extend(stages[i].pid());
            retired.push(format!(
                "{} (pid {})",
                stages[i].label(),
                pid_text(&stages[i])
            ));
        }
        Self {
            request_id,
            requested,
            starting: started,
            retiring,
            outcome: ScaleOutcome {
                stage: stage.to_string(),
                from: plan.from,
                to,
                retired,
                ..ScaleOutcome::default()
            },
        }
    }

    /// A starting process reported ready (telemetry from `pid`); true when it was one of ours.
    pub fn observe_ready(&mut self, pid: u32) -> bool {
        match self.starting.iter_mut().find(|p| p.pid() == Some(pid)) {
            Some(p) => {
                p.heard_from(pid);
                p.state = StageState::Ready;
                true
            }
            None => false,
        }
    }

    /// Moves the scale on: ready replicas join `stages` (after the stage's last process), a
    /// start that failed or timed out ends the scale as failed. The outcome once it is over.
    pub fn advance(
        &mut self,
        stages: &mut Vec<StageProcess>,
        startup_timeout: Duration,
        notes: &mut Vec<String>,
    ) -> Option<ScaleOutcome> {
        let mut i = 0;
        while i < self.starting.len() {
            let p = &mut self.starting[i];
            if let Some(status) = p.poll_exit() {
                let why = format!(
                    "{} exited while starting ({status}); its log {} ends with:\n{}",
                    p.label(),
                    p.log_path().display(),
                    p.log_tail(10)
                );
                notes.push(format!("scale {}: {why}", self.outcome.stage));
                self.outcome.error.get_or_insert(why);
                self.starting.remove(i);
            } else if p.state == StageState::Ready {
                let p = self.starting.remove(i);
                notes.push(format!(
                    "scale {}: {} (pid {}) joined",
                    self.outcome.stage,
                    p.label(),
                    pid_text(&p)
                ));
                self.outcome
                    .started
                    .push(format!("{} (pid {})", p.label(), pid_text(&p)));
                self.outcome.ready_s = Some(self.requested.elapsed().as_secs_f64());
                let after = stages
                    .iter()
                    .rposition(|s| s.spec.name == self.outcome.stage)
                    .map_or(stages.len(), |k| k + 1);
                stages.insert(after, p);
            } else if self.requested.elapsed() > startup_timeout {
                let why = format!(
                    "{} did not report ready within {:.0} s; see {}",
                    p.label(),
                    startup_timeout.as_secs_f64(),
                    p.log_path().display()
                );
                p.stop(Duration::from_secs(1));
                notes.push(format!("scale {}: {why}", self.outcome.stage));
                self.outcome.error.get_or_insert(why);
                self.starting.remove(i);
            } else {
                i += 1;
            }
        }
        self.retiring.retain(|&pid| {
            stages
                .iter()
                .any(|s| s.pid() == Some(pid) && s.is_running())
        });
        if !(self.starting.is_empty() && self.retiring.is_empty()) {
            return None;
        }
        self.outcome.running = active_replicas(stages, &self.outcome.stage).len() as u32;
        self.outcome.ok = self.outcome.error.is_none();
        Some(self.outcome.clone())
    }

    /// The run ends with the scale unfinished: starting processes are stopped.
    pub fn abandon(mut self, stages: &[StageProcess]) -> ScaleOutcome {
        for p in &mut self.starting {
            p.stop(Duration::from_secs(1));
        }
        self.outcome.running = active_replicas(stages, &self.outcome.stage).len() as u32;
        self.outcome.error = Some("the run ended before the scale was over".into());
        self.outcome
    }
}

fn pid_text(p: &StageProcess) -> String {
    p.pid().map_or("-".into(), |p| p.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deploy::DeployFile;

    fn segmenters(states: &[StageState]) -> Vec<StageProcess> {
        let deploy = DeployFile::load(std::path::Path::new("desktop")).expect("desktop");
        let spec = deploy
            .stages
            .iter()
            .find(|s| s.name == "segmenter")
            .expect("segmenter")
            .clone();
        let dir = std::path::Path::new("/nonexistent");
        let mut all: Vec<StageProcess> = deploy
            .stages
            .iter()
            .filter(|s| s.name != "segmenter")
            .map(|s| StageProcess::new(s.clone(), dir))
            .collect();
        for (r, state) in states.iter().enumerate() {
            let mut p = StageProcess::replica(spec.clone(), dir, r as u32);
            p.state = *state;
            all.insert(1 + r, p);
        }
        all
    }

    #[test]
    fn scaling_up_numbers_new_replicas_after_every_used_number() {
        use StageState::*;
        let stages = segmenters(&[Ready, Retired, Ready]);
        let p = plan(&stages, "segmenter", 4).expect("plan");
        // Two run (replicas 0 and 2; 1 is retired): two more, numbered 3 and 4.
        assert_eq!(
            (p.from, p.add.as_slice(), p.retire.len()),
            (2, &[3, 4][..], 0)
        );
        assert_eq!(stages[1 + 2].label(), "segmenter#2");
    }

    #[test]
    fn scaling_down_retires_the_newest_replicas() {
        use StageState::*;
        let stages = segmenters(&[Ready, Ready, Restarting, Ready]);
        let p = plan(&stages, "segmenter", 1).expect("plan");
        let retired: Vec<u32> = p.retire.iter().map(|&i| stages[i].replica).collect();
        assert_eq!((p.from, p.add.len(), retired), (4, 0, vec![3, 2, 1]));
    }

    #[test]
    fn impossible_requests_are_refused_with_the_reason() {
        use StageState::*;
        let stages = segmenters(&[Ready, Ready]);
        let refused = |stage: &str, to: u32| plan(&stages, stage, to).expect_err("refused");
        assert_eq!(
            refused("segmenter", 2),
            "stage 'segmenter' already runs 2 replicas"
        );
        assert!(refused("mapper", 2).contains("'mapper' cannot run replicas"));
        assert!(refused("segmenter", 0).contains("replicas must be 1-6, got 0"));
        assert!(refused("segmenter", 9).contains("replicas must be 1-6, got 9"));
        assert_eq!(
            refused("detector", 2),
            "no stage 'detector' in this pipeline"
        );
    }

    #[test]
    fn retiring_marks_the_processes_and_the_outcome_names_them() {
        use StageState::*;
        let mut stages = segmenters(&[Ready, Ready, Ready]);
        let p = plan(&stages, "segmenter", 2).expect("plan");
        let request = (2, 7, Instant::now());
        let mut scale = Scale::new(&mut stages, "segmenter", &p, request, Vec::new());
        assert_eq!(stages[1 + 2].state, Retired);
        // Nothing runs in this test: the retired process is gone at once.
        let outcome = scale
            .advance(&mut stages, Duration::from_secs(1), &mut Vec::new())
            .expect("over");
        assert!(outcome.ok, "{outcome:?}");
        assert_eq!((outcome.from, outcome.to, outcome.running), (3, 2, 2));
        assert_eq!(outcome.retired, ["segmenter#2 (pid -)"]);
        assert!(outcome
            .describe()
            .starts_with("scaled segmenter from 3 to 2 replicas"));
    }
}
