//! The viewer stage's loop: subscribes to every pipeline service (it publishes nothing but
//! its own telemetry), turns each message into records ([`crate::convert`]) and hands them to
//! the logging thread ([`crate::outbox`]) without ever waiting for it. It is a sink that may
//! fall behind: of frames and map targets it takes only the newest (older ones are dropped
//! and reported as dropped), and the hand-over drops images and point clouds while the
//! logging side is busy. A publisher never waits for it either: iceoryx2's safe overflow
//! drops the oldest sample of a full subscriber queue.

use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use opengs_ipc_schema::service::{
    CONSENSUS, FRAMES, KEYFRAMES, MAP_TARGET, POSES, RENDERS, SEGMENTS, TELEMETRY,
};
use opengs_ipc_schema::{
    now_ns, ConsensusHeader, FrameHeader, KeyframeHeader, MapTargetHeader, PoseHeader,
    RenderHeader, SchemaError, SegmentsHeader, TelemetryHeader,
};
use opengs_runtime::{
    waitset, CallbackProgression, Inlet, RunContext, TelemetrySink, WaitSetRunResult, HEARTBEAT,
};

use crate::convert::Converter;
use crate::outbox::{spawn_logger, LoggerReport, Outbox, RecordSink};
use crate::record::Record;

/// The stage's name in telemetry and the supervisor.
pub const STAGE: &str = "viewer";

/// At the end, the recording gets this long to flush...
const FLUSH_TIMEOUT: Duration = Duration::from_secs(2);
/// ... and the logging thread this long in all (within the supervisor's 5 s grace); after
/// that the process exits without it (what reached the file so far stays).
const STOP_GRACE: Duration = Duration::from_secs(3);
/// Malformed messages reported one by one; later ones are only counted.
const REPORTED_DECODE_ERRORS: u64 = 5;

/// Counts of what the loop saw, for the last log line.
#[derive(Debug, Default)]
struct Counts {
    frames: u64,
    frames_skipped: u64,
    messages: u64,
    decode_errors: u64,
}

impl Counts {
    fn malformed(&mut self, what: &str, e: &SchemaError) {
        self.decode_errors += 1;
        if self.decode_errors <= REPORTED_DECODE_ERRORS {
            tracing::warn!("malformed {what} skipped: {e}");
        }
    }
}

/// The stage's subscriptions.
struct Inputs {
    frames: Inlet<FrameHeader>,
    poses: Inlet<PoseHeader>,
    keyframes: Inlet<KeyframeHeader>,
    segments: Inlet<SegmentsHeader>,
    renders: Inlet<RenderHeader>,
    consensus: Inlet<ConsensusHeader>,
    map_target: Inlet<MapTargetHeader>,
    telemetry: Inlet<TelemetryHeader>,
}

/// Runs the viewer stage until a termination signal, logging into `sink`.
pub fn run_viewer<S: RecordSink>(ctx: &RunContext, sink: S) -> anyhow::Result<()> {
    let node = ctx.node(STAGE)?;
    let inputs = Inputs {
        frames: Inlet::new(ctx, &node, &FRAMES)?,
        poses: Inlet::new(ctx, &node, &POSES)?,
        keyframes: Inlet::new(ctx, &node, &KEYFRAMES)?,
        segments: Inlet::new(ctx, &node, &SEGMENTS)?,
        renders: Inlet::new(ctx, &node, &RENDERS)?,
        consensus: Inlet::new(ctx, &node, &CONSENSUS)?,
        map_target: Inlet::new(ctx, &node, &MAP_TARGET)?,
        telemetry: Inlet::new(ctx, &node, &TELEMETRY)?,
    };
    let telemetry = TelemetrySink::new(ctx, &node, STAGE)?;
    let ws = waitset()?;
    let attach_err = |e| anyhow::anyhow!("WaitSet: {e:?}");
    let listeners = [
        inputs.frames.listener(),
        inputs.poses.listener(),
        inputs.keyframes.listener(),
        inputs.segments.listener(),
        inputs.renders.listener(),
        inputs.consensus.listener(),
        inputs.map_target.listener(),
        inputs.telemetry.listener(),
    ];
    let mut _guards = Vec::with_capacity(listeners.len());
    for l in listeners {
        _guards.push(ws.attach_notification(l).map_err(attach_err)?);
    }
    let _heartbeat = ws.attach_interval(HEARTBEAT).map_err(attach_err)?;

    let (mut outbox, logger) = spawn_logger(sink, FLUSH_TIMEOUT)?;
    let mut conv = Converter::default();
    outbox.send(conv.start())?;
    let mut counts = Counts::default();
    telemetry.ready();
    loop {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => break,
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
            Ok(_) => {}
        }
        telemetry.alive();
        step(&inputs, &mut conv, &mut outbox, &telemetry, &mut counts)?;
    }
    let mut last = conv.finish();
    // Whatever arrived with the stop request still counts.
    let mut batch = Vec::new();
    drain_small(&inputs, &mut conv, &mut batch, &mut counts)?;
    last.extend(batch);
    if let Err(e) = outbox.send(last) {
        tracing::warn!("{e:#}");
    }
    outbox.close(Duration::from_secs(1));
    let report = wait_for(logger, STOP_GRACE);
    tracing::info!(
        "viewer: {} frames logged, {} skipped while behind, {} other messages, {} malformed; \
         {} records dropped by the hand-over; {} global labels; {}",
        counts.frames,
        counts.frames_skipped,
        counts.messages,
        counts.decode_errors,
        outbox.dropped,
        conv.global_labels(),
        match report {
            Some(r) => format!(
                "{} records logged, {} sink errors, {}",
                r.logged,
                r.errors,
                if r.flushed { "flushed" } else { "not flushed" }
            ),
            None => "the recording was still being written: exiting without it".to_string(),
        }
    );
    if conv.overflowed_labels > 0 {
        tracing::warn!(
            "{} label-map pixels carried labels past 65535 (no Rerun class id): shown as none",
            conv.overflowed_labels
        );
    }
    Ok(())
}

/// Waits up to `grace` for the logging thread.
fn wait_for(logger: JoinHandle<LoggerReport>, grace: Duration) -> Option<LoggerReport> {
    let deadline = Instant::now() + grace;
    while !logger.is_finished() {
        if Instant::now() >= deadline {
            return None;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    match logger.join() {
        Ok(r) => Some(r),
        Err(_) => {
            tracing::error!("the logging thread panicked");
            None
        }
    }
}

/// One wake-up: everything new, as one batch for the logger.
fn step(
    inputs: &Inputs,
    conv: &mut Converter,
    outbox: &mut Outbox,
    telemetry: &TelemetrySink,
    counts: &mut Counts,
) -> anyhow::Result<()> {
    let mut batch: Vec<Record> = Vec::new();
    drain_small(inputs, conv, &mut batch, counts)?;

    // Keyframes and the semantic loop: few, so all of them, in pipeline order.
    inputs.keyframes.clear_wakeups();
    while let Some(s) = inputs.keyframes.receive()? {
        counts.messages += 1;
        match s.user_header().decode(s.payload()) {
            Ok(v) => batch.extend(conv.on_keyframe(&v)),
            Err(e) => counts.malformed("keyframe", &e),
        }
    }
    inputs.segments.clear_wakeups();
    while let Some(s) = inputs.segments.receive()? {
        counts.messages += 1;
        match s.user_header().decode(s.payload()) {
            Ok(v) => batch.extend(conv.on_segments(&v)),
            Err(e) => counts.malformed("segments", &e),
        }
    }
    inputs.renders.clear_wakeups();
    while let Some(s) = inputs.renders.receive()? {
        counts.messages += 1;
        match s.user_header().decode(s.payload()) {
            Ok(v) => batch.extend(conv.on_render(&v)),
            Err(e) => counts.malformed("render", &e),
        }
    }
    inputs.consensus.clear_wakeups();
    while let Some(s) = inputs.consensus.receive()? {
        counts.messages += 1;
        match s.user_header().decode(s.payload()) {
            Ok(v) => batch.extend(conv.on_consensus(&v)),
            Err(e) => counts.malformed("consensus", &e),
        }
    }
    // The map: only the newest matters.
    inputs.map_target.clear_wakeups();
    if let (Some(s), _) = inputs.map_target.receive_newest()? {
        counts.messages += 1;
        match s.user_header().decode(s.payload()) {
            Ok(v) => batch.extend(conv.on_map_target(&v)),
            Err(e) => counts.malformed("map target", &e),
        }
    }
    // Frames: the newest; the ones it overtook are dropped (and said so).
    inputs.frames.clear_wakeups();
    let (newest, skipped) = inputs.frames.receive_newest()?;
    let Some(frame) = newest else {
        outbox.send(batch)?;
        return Ok(());
    };
    let stamp = frame.user_header().stamp;
    let start = now_ns();
    for _ in 0..skipped {
        telemetry.dropped(&stamp);
    }
    counts.frames_skipped += skipped as u64;
    let decoded = frame.user_header().decode(frame.payload());
    let frame_records = match decoded {
        Ok(v) => conv.on_frame(&v),
        Err(e) => {
            counts.malformed("frame", &e);
            telemetry.dropped(&stamp);
            Vec::new()
        }
    };
    // The sample goes back to the sensor before the hand-over.
    drop(frame);
    let had_frame = !frame_records.is_empty();
    batch.extend(frame_records);
    let handed = outbox.send(batch)?;
    if had_frame {
        if handed.dropped > 0 {
            telemetry.dropped(&stamp);
            counts.frames_skipped += 1;
        } else {
            telemetry.processed(&stamp, start, now_ns());
            counts.frames += 1;
        }
    }
    Ok(())
}

/// Poses and telemetry: small, every one of them.
fn drain_small(
    inputs: &Inputs,
    conv: &mut Converter,
    batch: &mut Vec<Record>,
    counts: &mut Counts,
) -> anyhow::Result<()> {
    inputs.poses.clear_wakeups();
    while let Some(s) = inputs.poses.receive()? {
        counts.messages += 1;
        match s.user_header().decode(s.payload()) {
            Ok(status) => batch.extend(conv.on_pose(s.user_header(), status)),
            Err(e) => counts.malformed("pose", &e),
        }
    }
    inputs.telemetry.clear_wakeups();
    while let Some(s) = inputs.telemetry.receive()? {
        counts.messages += 1;
        match s.user_header().decode(s.payload()) {
            Ok(event) => batch.extend(conv.on_telemetry(s.user_header(), event)),
            Err(e) => counts.malformed("telemetry", &e),
        }
    }
    Ok(())
}
