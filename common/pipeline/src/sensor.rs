//! The sensor stage: stream a dataset's frames into shared memory, paced.

use std::time::Duration;

use opengs_datasets::{open_dataset, RgbdFrame};
use opengs_geometry::{pose_to_tum, Intrinsics};
use opengs_ipc_schema::service::FRAMES;
use opengs_ipc_schema::{now_ns, FrameHeader, FrameParts, MessageKind, Stamp};
use opengs_runtime::{
    waitset, CallbackProgression, Outlet, RunContext, TelemetrySink, WaitSetRunResult,
};

use crate::DatasetArgs;

/// Options of the sensor stage.
#[derive(clap::Args, Debug, Clone)]
pub struct SensorArgs {
    #[command(flatten)]
    pub dataset: DatasetArgs,
    /// Publish at most this many frames per second (default: the dataset's rate; 0 = as fast as possible).
    #[arg(long)]
    pub max_rate: Option<f64>,
    /// First frame to publish (a restarted sensor resumes where it stopped).
    #[arg(long, default_value_t = 0)]
    pub start_frame: usize,
    /// No end of data: after the last frame, wait for frames a recorder appends to the
    /// dataset (a TUM folder's rgb.txt/depth.txt) until stopped.
    #[arg(long)]
    pub live: bool,
}

/// How often a live sensor with nothing to publish looks for appended frames.
const LIVE_POLL: Duration = Duration::from_millis(200);

/// What one attempt to publish did.
enum Step {
    Published,
    /// Live, at the end of what was recorded so far.
    Waiting,
    EndOfData,
}

/// Writes one frame into a loaned sample and sends it; returns its stamp.
pub fn publish_frame(
    outlet: &Outlet<FrameHeader>,
    frame: &RgbdFrame,
    k: &Intrinsics,
) -> anyhow::Result<Stamp> {
    let capture_ns = (frame.timestamp.max(0.0) * 1e9) as u64;
    let mut stamp = Stamp::new(MessageKind::Frame, frame.index as u64, capture_ns, 0);
    stamp.origin_ns = now_ns();
    stamp.stage_start_ns = stamp.origin_ns;
    let header = FrameHeader::new(
        stamp,
        frame.width,
        frame.height,
        frame.depth_scale,
        [k.fx, k.fy, k.cx, k.cy],
        frame.gt_pose.as_ref().map(pose_to_tum),
        frame.labels.is_some(),
        frame.index as u64,
    );
    let parts = FrameParts {
        depth: &frame.depth,
        labels: frame.labels.as_deref(),
        rgb: &frame.rgb,
    };
    outlet.send(header, |h, buf| h.encode(&parts, buf))?;
    Ok(header.stamp)
}

/// Runs the sensor stage until the data ends or a termination signal arrives.
pub fn run_sensor(ctx: &RunContext, args: &SensorArgs) -> anyhow::Result<()> {
    let node = ctx.node("sensor")?;
    let mut source = open_dataset(&args.dataset.spec()?)?;
    let k = source.intrinsics();
    let total = source.len();
    if args.start_frame >= total && total > 0 && !args.live {
        tracing::info!(
            "start frame {} is past the last frame {}; nothing to do",
            args.start_frame,
            total - 1
        );
    }
    let frame_bytes = k.pixel_count() * 7 + 64;
    let frames = Outlet::<FrameHeader>::new(ctx, &node, &FRAMES, frame_bytes)?;
    let telemetry = TelemetrySink::new(ctx, &node, "sensor")?;
    let rate = match args.max_rate {
        Some(r) if r <= 0.0 => None,
        Some(r) => Some(r.min(source.frame_rate())),
        None => Some(source.frame_rate()),
    };
    let ws = waitset()?;
    // Paced: wake on an interval. Unpaced: a long interval only lets the WaitSet see signals.
    let period = rate.map_or(Duration::from_secs(3600), |r| {
        Duration::from_secs_f64(1.0 / r)
    });
    let _tick = ws
        .attach_interval(period)
        .map_err(|e| anyhow::anyhow!("WaitSet interval: {e:?}"))?;
    tracing::info!(
        "{}: {total} frames{}, {k:?}, rate {rate:?}",
        source.name(),
        if args.live { " so far (live)" } else { "" }
    );
    telemetry.ready();

    let mut index = args.start_frame;
    let mut last = Stamp::new(MessageKind::Frame, 0, 0, 0);
    let mut failure: Option<anyhow::Error> = None;
    let mut last_poll: Option<std::time::Instant> = None;
    let mut publish_next = |last: &mut Stamp| -> Result<Step, anyhow::Error> {
        if index >= source.len() {
            if !args.live {
                return Ok(Step::EndOfData);
            }
            telemetry.alive();
            if last_poll.is_some_and(|t| t.elapsed() < LIVE_POLL) {
                return Ok(Step::Waiting);
            }
            last_poll = Some(std::time::Instant::now());
            let added = source
                .refresh()
                .map_err(|e| crate::stage_main::BadInput(format!("{}: {e}", source.name())))?;
            if added == 0 || index >= source.len() {
                return Ok(Step::Waiting);
            }
            tracing::info!("sensor: {added} new frames recorded");
        }
        let start = now_ns();
        let frame = source
            .frame(index)
            .map_err(|e| crate::stage_main::BadInput(format!("frame {index}: {e}")))?;
        let stamp = publish_frame(&frames, &frame, &k)?;
        let mut input = stamp;
        input.sent_ns = start;
        telemetry.processed(&input, start, now_ns());
        *last = stamp;
        index += 1;
        Ok(match args.live || index < source.len() {
            true => Step::Published,
            false => Step::EndOfData,
        })
    };
    let result = if rate.is_some() {
        ws.wait_and_process(|_| match publish_next(&mut last) {
            Ok(Step::Published | Step::Waiting) => CallbackProgression::Continue,
            Ok(Step::EndOfData) => CallbackProgression::Stop,
            Err(e) => {
                failure = Some(e);
                CallbackProgression::Stop
            }
        })
    } else {
        loop {
            // While waiting for a recorder, sleep in the WaitSet rather than spin.
            let mut pause = Duration::ZERO;
            match publish_next(&mut last) {
                Ok(Step::Published) => {}
                Ok(Step::Waiting) => pause = LIVE_POLL / 4,
                Ok(Step::EndOfData) => break Ok(WaitSetRunResult::StopRequest),
                Err(e) => {
                    failure = Some(e);
                    break Ok(WaitSetRunResult::StopRequest);
                }
            }
            // Returns at once (or after the pause), reporting a pending SIGINT/SIGTERM.
            match ws.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, pause) {
                Ok(WaitSetRunResult::TerminationRequest) | Ok(WaitSetRunResult::Interrupt) => {
                    break Ok(WaitSetRunResult::TerminationRequest)
                }
                Ok(_) => {}
                Err(e) => break Err(e),
            }
        }
    };
    if let Some(e) = failure {
        return Err(e);
    }
    match result.map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))? {
        WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt => {
            tracing::info!("sensor: stopped by signal after frame {}", last.seq);
        }
        _ => {
            tracing::info!("sensor: end of data after {index} frames");
            telemetry.finished(&last);
        }
    }
    Ok(())
}
