//! The supervisor of one run: starts the stages of a deploy file as processes, waits for
//! each to be ready, restarts the ones that die, swaps them on request, answers `opengs ctl`,
//! collects telemetry and poses, and on end of data, Ctrl-C or `ctl stop` stops everything in
//! order. It hands back what it collected ([`Supervised`]); [`crate::run`] writes the outputs
//! and scores them.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use opengs_eval::RunDir;
use opengs_ipc_schema::service::{CONTROL_REPLIES, CONTROL_REQUESTS, POSES, TELEMETRY};
use opengs_ipc_schema::{
    ControlCommand, ControlHeader, PoseHeader, TelemetryEvent, TelemetryHeader,
};
use opengs_runtime::FINISH_SIGNAL;
use opengs_runtime::{
    waitset, ActiveRun, ActiveRuns, CallbackProgression, Inlet, Outlet, RunContext, WaitSet,
    WaitSetRunResult,
};
use opengs_telemetry::{ChromeTrace, LatencyProfile, StageSample};

use crate::deploy::{stage_names, DeployFile, StageRole};
use crate::progress::Progress;
use crate::recorder::Recorder;
use crate::run_options::{RunOptions, StageFlags};
use crate::run_record::StageRecord;
use crate::scale::{Scale, ScaleOutcome};
use crate::service_notify::ServiceNotifier;
use crate::stage_process::{StageProcess, StageState};
use crate::status::{PipelineStatus, StageStatus};
use crate::swap::{Swap, SwapOutcome, SwapStep};

/// Why supervision ended.
#[derive(Debug, PartialEq)]
pub enum Ending {
    EndOfData,
    Interrupted,
    StopRequested,
    StageFailed(String),
    /// A stage stopped on input it cannot use (not restarted: it would read the same input).
    BadInput(String),
}

/// What the supervisor collected while the stages ran.
pub struct Supervised {
    /// How the main loop ended; an error when the pipeline could not start or run.
    pub ending: anyhow::Result<Ending>,
    /// Seconds until the data ended (or the run stopped), without the stages' final work.
    pub streaming_s: f64,
    pub recorder: Recorder,
    pub profile: LatencyProfile,
    pub trace: ChromeTrace,
    /// Each stage's counters, in deploy order.
    pub stages: Vec<StageRecord>,
    /// Frames in the dataset as selected (unknown when it could not be opened).
    pub frames_total: Option<usize>,
    /// Files of this run still in /dev/shm or the iceoryx2 root after shutdown (should be none).
    pub leftover_files: Vec<PathBuf>,
}

impl Supervised {
    /// Messages the stage `name` processed, all its replicas together (0 when there is no
    /// such stage).
    pub fn processed(&self, name: &str) -> u64 {
        self.stages
            .iter()
            .filter(|s| s.name == name)
            .map(|s| s.processed)
            .sum()
    }
}

/// Starts, watches, restarts, swaps and stops the stage processes of one run.
pub struct Supervisor;

struct Channels {
    telemetry: Inlet<TelemetryHeader>,
    poses: Inlet<PoseHeader>,
    control: Inlet<ControlHeader>,
    replies: Outlet<ControlHeader>,
}

impl Supervisor {
    /// Runs the pipeline of `opts` until the data ends, a stop is asked for, or a stage fails
    /// for good; every stage is stopped and the run's shared memory removed on every path.
    pub fn supervise(opts: &RunOptions) -> anyhow::Result<Supervised> {
        let log_dir = RunDir::new(&opts.out_dir).logs_dir();
        std::fs::create_dir_all(&log_dir).map_err(|e| {
            anyhow::anyhow!(
                "cannot create run directory {}: {e}",
                opts.out_dir.display()
            )
        })?;
        // A new run starts from nothing: a mapper checkpoint or label table an earlier run
        // left in this directory would otherwise be "resumed" by the first restart.
        let run_dir = RunDir::new(&opts.out_dir);
        for stale in [
            run_dir.map_checkpoint(),
            run_dir.map_checkpoint_counters(),
            run_dir.label_table(),
            run_dir.consensus_progress(),
            run_dir.mapper_keyframes(),
            run_dir.mapper_consensus(),
            run_dir.segmenter_claims(),
        ] {
            let removed = match stale.is_dir() {
                true => std::fs::remove_dir_all(&stale),
                false if stale.exists() => std::fs::remove_file(&stale),
                false => Ok(()),
            };
            removed.map_err(|e| {
                anyhow::anyhow!("cannot remove an earlier run's {}: {e}", stale.display())
            })?;
        }
        let ctx = RunContext::new(&opts.run_id)?;
        ctx.cleanup_dead_nodes();
        let registry = ActiveRuns::default();
        registry.register(&ActiveRun {
            run_id: opts.run_id.clone(),
            pid: std::process::id(),
            out_dir: opts.out_dir.clone(),
        })?;
        let started = Instant::now();
        let mut state = RunState::new(opts, log_dir);
        let mut streaming_s = None;
        // IPC objects live in this scope so they are gone before the leftover check.
        let ending = {
            let node = ctx.node("supervisor")?;
            let ch = Channels {
                telemetry: Inlet::new(&ctx, &node, &TELEMETRY)?,
                poses: Inlet::new(&ctx, &node, &POSES)?,
                control: Inlet::new(&ctx, &node, &CONTROL_REQUESTS)?,
                replies: Outlet::new(&ctx, &node, &CONTROL_REPLIES, 4096)?,
            };
            let result = state
                .start_all(&ch)
                .and_then(|()| {
                    let status = state.service_status();
                    state.service.ready(&status);
                    state.main_loop(&ctx, &ch, started)
                })
                .and_then(|ending| {
                    streaming_s = Some(started.elapsed().as_secs_f64());
                    let status = format!("stopping ({ending:?}): {}", state.service_status());
                    state.service.stopping(&status);
                    match ending {
                        Ending::EndOfData if opts.finish_after_data => {
                            state.finish_stages(&ch, started)
                        }
                        other => Ok(other),
                    }
                });
            // Stop in order whatever happened: the source first, so consumers see the end.
            state.stop_all(&ch);
            // Collect what the stages sent before they exited.
            state.drain(&ch);
            result
        };
        registry.unregister(&opts.run_id);
        ctx.cleanup_dead_nodes();
        ctx.remove_domain_segment();
        let leftover_files = ctx.leftover_files();
        if !leftover_files.is_empty() {
            tracing::warn!(
                "{} shared-memory files of this run remain: {:?}",
                leftover_files.len(),
                leftover_files
            );
        }
        let stages = state.stage_records();
        Ok(Supervised {
            ending,
            streaming_s: streaming_s.unwrap_or_else(|| started.elapsed().as_secs_f64()),
            recorder: state.recorder,
            profile: state.profile,
            trace: state.trace,
            stages,
            frames_total: state.total_frames,
            leftover_files,
        })
    }
}

struct RunState {
    run_id: String,
    /// The run id all hosts share (`--link` of bridge stages).
    link: String,
    out_dir: PathBuf,
    stages: Vec<StageProcess>,
    stage_flags: StageFlags,
    source_args: Vec<String>,
    deploy: DeployFile,
    profile: LatencyProfile,
    trace: ChromeTrace,
    recorder: Recorder,
    end_of_data: Option<(u64, Instant)>,
    total_frames: Option<usize>,
    progress: Option<Progress>,
    dataset_args: Vec<String>,
    log_dir: PathBuf,
    swap: Option<Swap>,
    scale: Option<Scale>,
    /// Stages that run (or ran) more than one process: the latency profile shows each.
    replicated: BTreeSet<String>,
    /// The dataset selection, for the run record the snapshots write.
    dataset: crate::DatasetArgs,
    last_snapshot: Instant,
    /// systemd readiness, status and watchdog (nothing when not run by systemd).
    service: ServiceNotifier,
}

/// How often the run's files are rewritten while it runs, so a supervisor killed outright
/// (SIGKILL, power) leaves a usable run directory: trajectory, lost frames, ground truth,
/// latency profile, run record.
const SNAPSHOT_EVERY: Duration = Duration::from_secs(5);

/// Seconds an optional stage (the Rerun viewer) may take to report ready before the run
/// starts without it.
const OPTIONAL_STARTUP_S: f64 = 10.0;

impl RunState {
    fn new(opts: &RunOptions, log_dir: PathBuf) -> Self {
        let mut source_args = opts.dataset.to_args();
        if let Some(r) = opts.max_rate {
            source_args.extend(["--max-rate".into(), r.to_string()]);
        }
        if opts.live {
            source_args.push("--live".into());
        }
        // A live dataset grows: no total to count down to.
        let total_frames = opts
            .dataset
            .spec()
            .ok()
            .filter(|_| !opts.live)
            .and_then(|s| opengs_datasets::open_dataset(&s).ok())
            .map(|d| d.len());
        Self {
            run_id: opts.run_id.clone(),
            link: opts.link.clone(),
            out_dir: opts.out_dir.clone(),
            stages: crate::viewer_args::stages_to_start(&opts.deploy, &opts.stage_flags.viewer)
                .into_iter()
                // Under `opengs node`, only this host's stages.
                .filter(|s| opts.host.is_none() || s.host == opts.host)
                .flat_map(|s| (0..s.replicas).map(move |r| (s.clone(), r)))
                .map(|(s, r)| match (&opts.host, &s.host) {
                    (None, Some(_)) => StageProcess::remote(s, &log_dir, r),
                    _ => StageProcess::replica(s, &log_dir, r),
                })
                .collect(),
            stage_flags: opts.stage_flags.clone(),
            source_args,
            deploy: opts.deploy.clone(),
            profile: LatencyProfile::new(opts.deploy.terminal_stage.as_deref()),
            trace: ChromeTrace::default(),
            recorder: Recorder::new(&opts.out_dir),
            end_of_data: None,
            total_frames,
            progress: opts.progress.then(|| Progress::new(total_frames)),
            dataset_args: opts.dataset.to_args(),
            replicated: opts
                .deploy
                .stages
                .iter()
                .filter(|s| s.replicas > 1)
                .map(|s| s.name.clone())
                .collect(),
            log_dir,
            swap: None,
            scale: None,
            dataset: opts.dataset.clone(),
            last_snapshot: Instant::now(),
            service: ServiceNotifier::from_env(),
        }
    }

    fn args_for(&self, i: usize) -> Vec<String> {
        self.args_for_process(&self.stages[i])
    }

    fn args_for_process(&self, s: &StageProcess) -> Vec<String> {
        let mut a = vec![
            "--run-id".to_string(),
            self.run_id.clone(),
            "--out".to_string(),
            self.out_dir.display().to_string(),
        ];
        if s.spec.role == StageRole::Source {
            a.extend(self.source_args.iter().cloned());
            // A restarted source resumes after the last frame it published.
            if let Some(seq) = s.last_seq {
                a.extend(["--start-frame".to_string(), (seq + 1).to_string()]);
            }
        }
        if s.spec.dataset && s.spec.role != StageRole::Source {
            a.extend(self.dataset_args.iter().cloned());
        }
        if let Some(kind) = &s.spec.kind {
            a.extend(["--kind".to_string(), kind.clone()]);
        }
        if s.spec.link {
            a.extend(["--link".to_string(), self.link.clone()]);
        }
        // A restarted tracker goes on from the last pose it published.
        if s.spec.name == stage_names::TRACKER && s.restarts > 0 {
            let poses = self.recorder.resume_poses();
            if !poses.is_empty() {
                let path = RunDir::new(&self.out_dir).tracker_resume();
                match crate::tracker_stage::resume_args(&path, &poses) {
                    Ok(args) => a.extend(args),
                    Err(e) => tracing::error!("the tracker restarts from scratch: {e}"),
                }
            }
        }
        a.extend(self.stage_flags.for_stage(&s.spec.name));
        a
    }

    /// A process started while another of its stage serves (a swap, a scale) has time to
    /// warm its model up before it reports ready (a stage with kinds is the segmenter).
    fn args_beside_running(&self, s: &StageProcess) -> Vec<String> {
        let mut a = self.args_for_process(s);
        if s.spec.kind.is_some() {
            a.push("--warm-up".to_string());
        }
        a
    }

    /// The run's files as of now (atomic rewrites); the end of the run writes them again.
    fn snapshot(&mut self) {
        self.last_snapshot = Instant::now();
        let run = RunDir::new(&self.out_dir);
        let written = (|| -> anyhow::Result<()> {
            if !self.recorder.is_empty() {
                self.recorder.write()?;
            }
            let latency = serde_json::to_string_pretty(&self.profile.report())?;
            opengs_eval::write_atomically(&run.latency(), latency.as_bytes())?;
            self.record().write(&run)
        })();
        if let Err(e) = written {
            tracing::warn!("run snapshot: {e:#}");
        }
    }

    /// One line for `systemctl status`.
    fn service_status(&self) -> String {
        let sensor = self
            .stage_index(stage_names::SENSOR)
            .map_or(0, |i| self.stages[i].processed);
        let restarts: u32 = self.stages.iter().map(|s| s.restarts).sum();
        format!(
            "{sensor} frames, {} poses ({} lost), {} keyframes, {restarts} restarts; run {} in {}",
            self.recorder.len(),
            self.recorder.lost(),
            self.recorder.keyframes(),
            self.run_id,
            self.out_dir.display()
        )
    }

    /// The run record as of now.
    fn record(&self) -> crate::RunRecord {
        crate::RunRecord {
            run_id: self.run_id.clone(),
            dataset_args: self.dataset.clone(),
            frames_total: self.total_frames,
            stages: self.stage_records(),
        }
    }

    fn stage_records(&self) -> Vec<StageRecord> {
        self.stages
            .iter()
            .map(|s| StageRecord {
                name: s.spec.name.clone(),
                replica: s.replica,
                restarts: s.restarts,
                hangs: s.hangs,
                processed: s.processed,
                last_seq: s.last_seq,
            })
            .collect()
    }

    /// The stage's first process still doing its work (replica 0 unless scaled).
    fn stage_index(&self, name: &str) -> Option<usize> {
        crate::scale::active_replicas(&self.stages, name)
            .first()
            .copied()
    }

    /// Starts each stage in deploy order and waits until it reports ready.
    fn start_all(&mut self, ch: &Channels) -> anyhow::Result<()> {
        let ws = waitset()?;
        let _t = ws
            .attach_notification(ch.telemetry.listener())
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let _tick = ws
            .attach_interval(Duration::from_millis(100))
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        for i in 0..self.stages.len() {
            if let Some(host) = &self.stages[i].remote {
                self.note(&format!(
                    "{} runs on host {host} (opengs node --host {host}): shown from its telemetry",
                    self.stages[i].label()
                ));
                continue;
            }
            let args = self.args_for(i);
            let optional = self.stages[i].spec.optional;
            if let Err(e) = self.stages[i].spawn(&args) {
                if !optional {
                    return Err(e);
                }
                self.leave_out(i, &format!("{e:#}"));
                continue;
            }
            self.note(&format!(
                "starting {} (pid {})",
                self.stages[i].label(),
                self.stages[i].pid().unwrap_or(0)
            ));
            // An optional stage never holds the pipeline's start up for long.
            let timeout_s = match optional {
                true => self.deploy.startup_timeout_s.min(OPTIONAL_STARTUP_S),
                false => self.deploy.startup_timeout_s,
            };
            let deadline = Instant::now() + Duration::from_secs_f64(timeout_s);
            let failed = loop {
                if self.stages[i].state == StageState::Ready {
                    break None;
                }
                match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
                    Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                        anyhow::bail!("interrupted while starting {}", self.stages[i].label())
                    }
                    Err(e) => anyhow::bail!("WaitSet: {e:?}"),
                    Ok(_) => {}
                }
                self.handle_telemetry(ch);
                if let Some(status) = self.stages[i].poll_exit() {
                    break Some(format!(
                        "stage {} exited during start-up ({status}); its log {} ends with:\n{}",
                        self.stages[i].label(),
                        self.stages[i].log_path().display(),
                        self.stages[i].log_tail(15)
                    ));
                }
                if Instant::now() > deadline {
                    break Some(format!(
                        "stage {} did not report ready within {timeout_s} s; see {}",
                        self.stages[i].label(),
                        self.stages[i].log_path().display()
                    ));
                }
            };
            match failed {
                Some(why) if optional => self.leave_out(i, &why),
                Some(why) => anyhow::bail!("{why}"),
                None => {}
            }
        }
        Ok(())
    }

    /// An optional stage that failed (to start, or past its restarts): stopped if it still
    /// runs, marked failed, and the run goes on without it.
    fn leave_out(&mut self, i: usize, why: &str) {
        self.stages[i].stop(Duration::from_secs(1));
        self.stages[i].state = StageState::Failed;
        self.note(&format!(
            "optional stage {} left out, the run goes on without it: {why}",
            self.stages[i].spec.name
        ));
    }

    fn main_loop(
        &mut self,
        ctx: &RunContext,
        ch: &Channels,
        started: Instant,
    ) -> anyhow::Result<Ending> {
        let ws = waitset()?;
        let err = |e| anyhow::anyhow!("WaitSet attach: {e:?}");
        let _g1 = ws
            .attach_notification(ch.telemetry.listener())
            .map_err(err)?;
        let _g2 = ws.attach_notification(ch.poses.listener()).map_err(err)?;
        let _g3 = ws.attach_notification(ch.control.listener()).map_err(err)?;
        let _tick = ws
            .attach_interval(Duration::from_millis(100))
            .map_err(err)?;
        // run.json from the start: a killed supervisor's directory says what the run was.
        self.snapshot();
        loop {
            if self.wait_for_news(&ws)? {
                return Ok(Ending::Interrupted);
            }
            self.handle_telemetry(ch);
            self.handle_poses(ch);
            if self.handle_control(ch, started) {
                return Ok(Ending::StopRequested);
            }
            self.advance_swap(ch);
            self.advance_scale(ch);
            if let Some(failed) = self.watch_children(ctx)? {
                return Ok(failed);
            }
            if let Some(p) = &mut self.progress {
                p.update(&self.stages, self.recorder.len(), started);
            }
            if self.last_snapshot.elapsed() >= SNAPSHOT_EVERY {
                self.snapshot();
            }
            let status = self.service.status_due().then(|| self.service_status());
            self.service.tick(status.as_deref());
            if let Some((last_seq, at)) = self.end_of_data {
                let terminal_done = match &self.deploy.terminal_stage {
                    Some(t) => self
                        .stage_index(t)
                        .and_then(|i| self.stages[i].last_seq)
                        .is_some_and(|s| s >= last_seq),
                    None => true,
                };
                if terminal_done || at.elapsed().as_secs_f64() > self.deploy.drain_timeout_s {
                    if !terminal_done {
                        self.note("drain timeout: stopping stages with work still queued");
                    }
                    return Ok(Ending::EndOfData);
                }
            }
        }
    }

    fn handle_telemetry(&mut self, ch: &Channels) {
        ch.telemetry.clear_wakeups();
        loop {
            let sample = match ch.telemetry.receive() {
                Ok(Some(s)) => s,
                Ok(None) => break,
                Err(e) => {
                    tracing::warn!("{e}");
                    break;
                }
            };
            let h = *sample.user_header();
            let event = match h.decode(sample.payload()) {
                Ok(ev) => ev,
                Err(e) => {
                    tracing::error!("malformed telemetry dropped: {e}");
                    continue;
                }
            };
            let name = h.stage_name().to_string();
            if event == TelemetryEvent::Ready
                && self.scale.as_mut().is_some_and(|s| s.observe_ready(h.pid))
            {
                continue;
            }
            // Replicas share a name: the pid says which (else the stage's first process: a
            // swap's new process before it takes the stage's place, or a retired one's last).
            let Some(i) = self
                .stages
                .iter()
                .position(|s| s.spec.name == name && s.pid() == Some(h.pid))
                .or_else(|| self.stage_index(&name))
            else {
                continue;
            };
            if self.stages[i].remote.is_some() {
                self.stages[i].heard_remotely(h.pid);
            }
            self.stages[i].heard_from(h.pid);
            if let Some(swap) = self.swap.as_mut().filter(|s| s.index == i) {
                match event {
                    TelemetryEvent::Ready => swap.observe_ready(h.pid),
                    TelemetryEvent::Processed => swap.observe_output(h.pid, h.end_ns),
                    _ => {}
                }
            }
            let stage = &mut self.stages[i];
            match event {
                TelemetryEvent::Ready => {
                    if matches!(stage.state, StageState::Starting | StageState::Restarting) {
                        stage.state = StageState::Ready;
                    }
                }
                TelemetryEvent::Processed => {
                    stage.processed += 1;
                    stage.last_seq =
                        Some(stage.last_seq.map_or(h.stamp.seq, |s| s.max(h.stamp.seq)));
                    let s = StageSample {
                        seq: h.stamp.seq,
                        origin_ns: h.stamp.origin_ns,
                        input_sent_ns: h.input_sent_ns,
                        start_ns: h.start_ns,
                        end_ns: h.end_ns,
                    };
                    self.profile.record(&name, &s);
                    // The stage's row counts every replica; each has a row of its own too.
                    if self.replicated.contains(&name) {
                        self.profile
                            .record(&format!("{name}#{}", stage.replica), &s);
                    }
                    self.trace.record(&stage.label(), h.pid, &s);
                }
                TelemetryEvent::Dropped => {
                    self.profile.record_drop(&name);
                    if self.replicated.contains(&name) {
                        self.profile
                            .record_drop(&format!("{name}#{}", stage.replica));
                    }
                }
                TelemetryEvent::Progress => stage.work = Some((h.work_done, h.work_total)),
                TelemetryEvent::Heartbeat => {}
                TelemetryEvent::Finished => {
                    if stage.spec.role == StageRole::Source && self.end_of_data.is_none() {
                        self.end_of_data = Some((h.stamp.seq, Instant::now()));
                    }
                }
            }
        }
    }

    fn handle_poses(&mut self, ch: &Channels) {
        ch.poses.clear_wakeups();
        loop {
            match ch.poses.receive() {
                Ok(Some(s)) => match s.user_header().decode(s.payload()) {
                    Ok(status) => self.recorder.record(s.user_header(), status),
                    Err(e) => tracing::error!("malformed pose dropped: {e}"),
                },
                Ok(None) => break,
                Err(e) => {
                    tracing::warn!("{e}");
                    break;
                }
            }
        }
    }

    /// Answers control requests; true when a stop was requested.
    fn handle_control(&mut self, ch: &Channels, started: Instant) -> bool {
        ch.control.clear_wakeups();
        let mut stop = false;
        while let Ok(Some(s)) = ch.control.receive() {
            let view = match s.user_header().decode(s.payload()) {
                Ok(v) => v,
                Err(e) => {
                    tracing::error!("malformed control request dropped: {e}");
                    continue;
                }
            };
            let (ok, text) = match view.command {
                ControlCommand::Status => (
                    true,
                    serde_json::to_string(&self.status(started)).unwrap_or_default(),
                ),
                ControlCommand::Stop => {
                    stop = true;
                    (true, "\"stopping\"".to_string())
                }
                ControlCommand::Swap => match self.begin_swap(view.text, view.request_id) {
                    // The reply goes out when the new process is ready (or fails).
                    Ok(()) => continue,
                    Err(e) => (false, serde_json::Value::String(e).to_string()),
                },
                ControlCommand::Scale => match self.begin_scale(view.text, view.request_id) {
                    // The reply goes out when the new replicas are ready, the old ones gone.
                    Ok(()) => continue,
                    Err(e) => (false, serde_json::Value::String(e).to_string()),
                },
                ControlCommand::Reply => continue,
            };
            let reply = ControlHeader::new(ControlCommand::Reply, view.request_id, ok, &text);
            if let Err(e) = ch.replies.send(reply, |h, buf| h.encode(&text, buf)) {
                tracing::warn!("control reply: {e}");
            }
        }
        stop
    }

    /// Starts the replacement process of a `swap STAGE KIND` request (see [`crate::swap`]).
    fn begin_swap(&mut self, text: &str, request_id: u64) -> Result<(), String> {
        let mut words = text.split_whitespace();
        let (Some(stage), Some(kind), None) = (words.next(), words.next(), words.next()) else {
            return Err(format!("swap needs 'STAGE KIND', got '{text}'"));
        };
        if self.swap.is_some() {
            return Err("a swap is already in progress".into());
        }
        if self.scale.is_some() {
            return Err("a scale is in progress; swap once it is over".into());
        }
        let index = self
            .stage_index(stage)
            .ok_or_else(|| format!("no stage '{stage}' in this pipeline"))?;
        let replicas = crate::scale::active_replicas(&self.stages, stage).len();
        if replicas > 1 {
            return Err(format!(
                "stage '{stage}' runs {replicas} replicas; scale it to 1 first \
                 (opengs ctl scale {stage} --to 1), swap, then scale it up again"
            ));
        }
        let current = &self.stages[index];
        if let Some(host) = &current.remote {
            return Err(format!(
                "stage '{stage}' runs on host {host}: opengs ctl --run {}-{host} swap {stage} --to {kind}",
                self.link
            ));
        }
        let Some(from) = current.spec.kind.clone() else {
            return Err(format!("stage '{stage}' has no kinds to swap"));
        };
        if from == kind {
            return Err(format!("stage '{stage}' already runs '{kind}'"));
        }
        let mut spec = current.spec.clone();
        spec.kind = Some(kind.to_string());
        let mut process = StageProcess::new(spec, &self.log_dir);
        let args = self.args_beside_running(&process);
        process.spawn(&args).map_err(|e| e.to_string())?;
        self.note(&format!(
            "swap {stage}: starting '{kind}' (pid {}) beside the running '{from}'",
            process.pid().unwrap_or(0)
        ));
        self.swap = Some(Swap::new(index, request_id, &from, process));
        Ok(())
    }

    /// Starts a `scale STAGE N` request (see [`crate::scale`]): new replicas spawned, or the
    /// newest ones asked to stop.
    fn begin_scale(&mut self, text: &str, request_id: u64) -> Result<(), String> {
        let mut words = text.split_whitespace();
        let (Some(stage), Some(to), None) = (words.next(), words.next(), words.next()) else {
            return Err(format!("scale needs 'STAGE N', got '{text}'"));
        };
        let to: u32 = to
            .parse()
            .map_err(|_| format!("scale: '{to}' is not a number of replicas"))?;
        if self.swap.is_some() || self.scale.is_some() {
            return Err("a swap or scale is in progress; scale once it is over".into());
        }
        let requested = Instant::now();
        if let Some(host) = self
            .stage_index(stage)
            .and_then(|i| self.stages[i].remote.as_ref())
        {
            return Err(format!(
                "stage '{stage}' runs on host {host}: opengs ctl --run {}-{host} scale {stage} --to {to}",
                self.link
            ));
        }
        let plan = crate::scale::plan(&self.stages, stage, to)?;
        let first = self
            .stage_index(stage)
            .ok_or_else(|| format!("stage '{stage}' has no process running"))?;
        let spec = self.stages[first].spec.clone();
        let mut started = Vec::new();
        for &replica in &plan.add {
            let mut p = StageProcess::replica(spec.clone(), &self.log_dir, replica);
            let args = self.args_beside_running(&p);
            if let Err(e) = p.spawn(&args) {
                // Those spawned already are dropped (killed) with `started`.
                return Err(format!("scale {stage}: {e:#}"));
            }
            self.note(&format!(
                "scale {stage}: starting {} (pid {})",
                p.label(),
                p.pid().unwrap_or(0)
            ));
            started.push(p);
        }
        if to > 1 {
            self.replicated.insert(stage.to_string());
        }
        let scale = Scale::new(
            &mut self.stages,
            stage,
            &plan,
            (to, request_id, requested),
            started,
        );
        for &i in &plan.retire {
            self.note(&format!(
                "scale {stage}: retiring {} (pid {}) after its current keyframe",
                self.stages[i].label(),
                self.stages[i].pid().unwrap_or(0)
            ));
        }
        self.scale = Some(scale);
        Ok(())
    }

    /// Moves a pending scale on, and answers its `ctl scale` once it is over.
    fn advance_scale(&mut self, ch: &Channels) {
        let Some(scale) = &mut self.scale else { return };
        let mut notes = Vec::new();
        let timeout = Duration::from_secs_f64(self.deploy.startup_timeout_s);
        let done = scale.advance(&mut self.stages, timeout, &mut notes);
        let request_id = scale.request_id;
        for n in notes {
            self.note(&n);
        }
        if let Some(outcome) = done {
            self.scale = None;
            self.note(&outcome.describe());
            reply_scale(ch, request_id, &outcome);
        }
    }

    /// Moves a pending swap on, and answers its `ctl swap` once it is over.
    fn advance_swap(&mut self, ch: &Channels) {
        let Some(swap) = &mut self.swap else { return };
        let mut notes = Vec::new();
        let timeout = Duration::from_secs_f64(self.deploy.startup_timeout_s);
        let step = swap.advance(&mut self.stages[swap.index], timeout, &mut notes);
        match step {
            SwapStep::Waiting => {}
            SwapStep::Promote(process) => {
                let old = std::mem::replace(&mut self.stages[swap.index], *process);
                swap.retire(old);
            }
            SwapStep::Done(outcome) => {
                let request_id = swap.request_id;
                self.swap = None;
                reply_swap(ch, request_id, &outcome);
            }
        }
        for n in notes {
            self.note(&n);
        }
    }

    fn status(&self, started: Instant) -> PipelineStatus {
        PipelineStatus {
            run_id: self.run_id.clone(),
            out_dir: self.out_dir.display().to_string(),
            elapsed_s: started.elapsed().as_secs_f64(),
            stages: self
                .stages
                .iter()
                .map(|s| StageStatus {
                    name: s.spec.name.clone(),
                    replica: s.replica,
                    host: s.remote.clone(),
                    pid: (s.is_running() || s.remote.is_some())
                        .then(|| s.pid())
                        .flatten(),
                    state: serde_json::to_value(s.state)
                        .ok()
                        .and_then(|v| v.as_str().map(String::from))
                        .unwrap_or_default(),
                    restarts: s.restarts,
                    processed: s.processed,
                    last_seq: s.last_seq,
                    kind: s.spec.kind.clone(),
                })
                .collect(),
            poses: self.recorder.len(),
            lost_frames: self.recorder.lost(),
        }
    }

    /// Reaps exited stages, restarts them with back-off; the ending when one is out of
    /// restarts, or stopped on bad input.
    fn watch_children(&mut self, ctx: &RunContext) -> anyhow::Result<Option<Ending>> {
        for i in 0..self.stages.len() {
            // Its own host's `opengs node` restarts it.
            if self.stages[i].remote.is_some() {
                continue;
            }
            if self.stages[i].state == StageState::Retired {
                if self.stages[i].retire_overdue(crate::swap::RETIRE_GRACE) {
                    self.note(&format!(
                        "{} (retired) still busy after {:?}: killed",
                        self.stages[i].label(),
                        crate::swap::RETIRE_GRACE
                    ));
                }
                if let Some(status) = self.stages[i].poll_exit() {
                    self.note(&format!("{} retired ({status})", self.stages[i].label()));
                    ctx.cleanup_dead_nodes();
                }
                continue;
            }
            if let Some(silent) = self.stages[i].silent_for() {
                self.note(&format!(
                    "stage {} (pid {}) sent nothing for {:.1} s (watchdog_s {}): hung or stopped; \
                     killing it",
                    self.stages[i].label(),
                    self.stages[i].pid().unwrap_or(0),
                    silent.as_secs_f64(),
                    self.stages[i].spec.watchdog_s
                ));
                self.stages[i].kill_hung();
            }
            if let Some(status) = self.stages[i].poll_exit() {
                let name = self.stages[i].label();
                let clean = status.success();
                if clean && self.stages[i].spec.role == StageRole::Source {
                    self.stages[i].state = StageState::Finished;
                    if self.end_of_data.is_none() {
                        // Finished without its telemetry arriving: the last seq it processed stands.
                        let last = self.stages[i].last_seq.unwrap_or(0);
                        self.end_of_data = Some((last, Instant::now()));
                    }
                    continue;
                }
                self.note(&format!(
                    "stage {name} exited ({status}); log: {}",
                    self.stages[i].log_path().display()
                ));
                // Its shared-memory resources must go before a replacement opens them.
                ctx.cleanup_dead_nodes();
                let optional = self.stages[i].spec.optional;
                if status.code() == Some(i32::from(crate::stage_main::BAD_INPUT_EXIT)) && !optional
                {
                    self.stages[i].state = StageState::Failed;
                    return Ok(Some(Ending::BadInput(format!(
                        "stage {name} stopped on input it cannot use (not restarted: it would \
                         read the same input):\n{}",
                        self.stages[i].log_tail(3)
                    ))));
                }
                if !self.stages[i].schedule_restart() {
                    if optional {
                        let why = format!("it exited ({status}) with no restarts left");
                        self.leave_out(i, &why);
                        continue;
                    }
                    return Ok(Some(Ending::StageFailed(format!(
                        "stage {name} died {} times (limit {}); last log lines:\n{}",
                        self.stages[i].restarts + 1,
                        self.stages[i].spec.restart_limit,
                        self.stages[i].log_tail(15)
                    ))));
                }
            }
            if self.stages[i].restart_due() {
                let args = self.args_for(i);
                self.stages[i].spawn(&args)?;
                self.note(&format!(
                    "restarted {} (pid {}, restart {}/{})",
                    self.stages[i].label(),
                    self.stages[i].pid().unwrap_or(0),
                    self.stages[i].restarts,
                    self.stages[i].spec.restart_limit
                ));
            }
        }
        Ok(None)
    }

    /// Sleeps until a message or the next tick; true on Ctrl-C / SIGTERM.
    fn wait_for_news(&self, ws: &WaitSet) -> anyhow::Result<bool> {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                self.note("interrupted: stopping stages and saving outputs");
                Ok(true)
            }
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
            Ok(_) => Ok(false),
        }
    }

    /// After the end of data, lets the stages with a `finish_timeout_s` do their final work
    /// (SIGUSR1) and waits for them to exit, showing their progress. Ctrl-C stops the wait.
    /// `ctl status` is answered meanwhile, and `ctl stop` ends the wait as Ctrl-C does.
    fn finish_stages(&mut self, ch: &Channels, started: Instant) -> anyhow::Result<Ending> {
        let finishing: Vec<usize> = (0..self.stages.len())
            .filter(|&i| self.stages[i].spec.finish_timeout_s > 0.0 && self.stages[i].is_running())
            .collect();
        if finishing.is_empty() {
            return Ok(Ending::EndOfData);
        }
        let ws = waitset()?;
        let err = |e| anyhow::anyhow!("WaitSet attach: {e:?}");
        let _g = ws
            .attach_notification(ch.telemetry.listener())
            .map_err(err)?;
        let _c = ws.attach_notification(ch.control.listener()).map_err(err)?;
        let _tick = ws
            .attach_interval(Duration::from_millis(200))
            .map_err(err)?;
        let start = Instant::now();
        for &i in &finishing {
            let s = &self.stages[i];
            s.signal(FINISH_SIGNAL);
            self.note(&format!(
                "end of data: {} does its final work (up to {:.0} s; Ctrl-C keeps what is done)",
                s.spec.name, s.spec.finish_timeout_s
            ));
        }
        let mut last_line = Instant::now();
        // Restarted during their final work: they get the finish signal once ready again.
        let mut to_finish: Vec<usize> = Vec::new();
        loop {
            if self.wait_for_news(&ws)? {
                return Ok(Ending::Interrupted);
            }
            self.handle_telemetry(ch);
            if self.handle_control(ch, started) {
                self.note("stop requested: stopping the final work (what is done is kept)");
                return Ok(Ending::StopRequested);
            }
            let mut waiting = 0;
            for &i in &finishing {
                if self.stages[i].restart_due() {
                    let args = self.args_for(i);
                    self.stages[i].spawn(&args)?;
                    to_finish.push(i);
                    self.note(&format!(
                        "restarted {} (pid {}, restart {}/{}) to do its final work again from \
                         its checkpoint and keyframe journal",
                        self.stages[i].spec.name,
                        self.stages[i].pid().unwrap_or(0),
                        self.stages[i].restarts,
                        self.stages[i].spec.restart_limit
                    ));
                }
                if self.stages[i].state == StageState::Restarting {
                    waiting += 1;
                    continue;
                }
                if to_finish.contains(&i) && self.stages[i].state == StageState::Ready {
                    self.stages[i].signal(FINISH_SIGNAL);
                    to_finish.retain(|&j| j != i);
                }
                let stage = &mut self.stages[i];
                if !stage.is_running() {
                    continue;
                }
                if let Some(status) = stage.poll_exit() {
                    stage.state = StageState::Finished;
                    let took = start.elapsed().as_secs_f64();
                    let msg = if status.success() {
                        format!("{} finished its final work in {took:.1} s", stage.spec.name)
                    } else if stage.schedule_restart() {
                        waiting += 1;
                        format!(
                            "{} exited ({status}) during its final work; restarting it; log: {}",
                            stage.spec.name,
                            stage.log_path().display()
                        )
                    } else {
                        format!(
                            "{} exited ({status}) during its final work, no restarts left; log: {}",
                            stage.spec.name,
                            stage.log_path().display()
                        )
                    };
                    self.note(&msg);
                } else if let Some(silent) = stage.silent_for() {
                    // Hung in its final work: waiting out finish_timeout_s would stall the run.
                    let msg = format!(
                        "{} (pid {}) sent nothing for {:.1} s in its final work (watchdog_s {}): \
                         hung or stopped; killing it (its last checkpoint is kept)",
                        stage.spec.name,
                        stage.pid().unwrap_or(0),
                        silent.as_secs_f64(),
                        stage.spec.watchdog_s
                    );
                    stage.kill_hung();
                    self.note(&msg);
                    waiting += 1;
                } else if start.elapsed().as_secs_f64() > stage.spec.finish_timeout_s {
                    let msg = format!(
                        "{}: final work past its {:.0} s limit; stopping it (it keeps what is done)",
                        stage.spec.name, stage.spec.finish_timeout_s
                    );
                    stage.stop(Duration::from_secs(30));
                    self.note(&msg);
                } else {
                    waiting += 1;
                }
            }
            if waiting == 0 {
                return Ok(Ending::EndOfData);
            }
            if self.progress.is_some() && last_line.elapsed() > Duration::from_secs(10) {
                last_line = Instant::now();
                for &i in &finishing {
                    let s = &self.stages[i];
                    if let (true, Some((done, total))) = (s.is_running(), s.work) {
                        self.note(&format!(
                            "{}: final work {done}/{total} steps ({:.0} s)",
                            s.spec.name,
                            start.elapsed().as_secs_f64()
                        ));
                    }
                }
            }
        }
    }

    /// Stops every running stage, the source first.
    fn stop_all(&mut self, ch: &Channels) {
        if let Some(swap) = self.swap.take() {
            let request_id = swap.request_id;
            reply_swap(ch, request_id, &swap.abandon());
        }
        if let Some(scale) = self.scale.take() {
            let request_id = scale.request_id;
            reply_scale(ch, request_id, &scale.abandon(&self.stages));
        }
        let order: Vec<usize> = (0..self.stages.len()).rev().collect();
        for i in order {
            if self.stages[i].is_running() {
                self.stages[i].stop(Duration::from_secs(5));
            }
        }
        if let Some(p) = &self.progress {
            p.finish();
        }
    }

    fn drain(&mut self, ch: &Channels) {
        self.handle_telemetry(ch);
        self.handle_poses(ch);
    }

    fn note(&self, msg: &str) {
        // Lifecycle events (starts, deaths, restarts) are always shown, even with --quiet.
        match &self.progress {
            Some(p) => p.println(msg),
            None => eprintln!("{msg}"),
        }
    }
}

/// Answers a `ctl scale` with its outcome (JSON), ok only when the scale succeeded.
fn reply_scale(ch: &Channels, request_id: u64, outcome: &ScaleOutcome) {
    let body = serde_json::to_string(outcome).unwrap_or_default();
    let reply = ControlHeader::new(ControlCommand::Reply, request_id, outcome.ok, &body);
    if let Err(e) = ch.replies.send(reply, |h, buf| h.encode(&body, buf)) {
        tracing::warn!("control reply: {e}");
    }
}

/// Answers a `ctl swap` with its outcome (JSON), ok only when the swap succeeded.
fn reply_swap(ch: &Channels, request_id: u64, outcome: &SwapOutcome) {
    let body = serde_json::to_string(outcome).unwrap_or_default();
    let reply = ControlHeader::new(ControlCommand::Reply, request_id, outcome.ok, &body);
    if let Err(e) = ch.replies.send(reply, |h, buf| h.encode(&body, buf)) {
        tracing::warn!("control reply: {e}");
    }
}
