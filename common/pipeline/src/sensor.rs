//! The sensor stage: stream a dataset's frames into shared memory, paced.

use std::time::{Duration, Instant};

use opengs_datasets::{open_dataset, RgbdFrame};
use opengs_geometry::{pose_to_tum, Intrinsics};
use opengs_ipc_schema::service::FRAMES;
use opengs_ipc_schema::{now_ns, FrameHeader, FrameParts, MessageKind, Stamp};
use opengs_runtime::{
    waitset, CallbackProgression, Outlet, RunContext, TelemetrySink, WaitSet, WaitSetRunResult,
    HEARTBEAT,
};

use crate::frame_reader::{FrameReader, Read};
use crate::pacing::{Pacer, ANNOUNCED_GAP, LONGEST_GAP};
use crate::DatasetArgs;

/// Options of the sensor stage.
#[derive(clap::Args, Debug, Clone)]
pub struct SensorArgs {
    #[command(flatten)]
    pub dataset: DatasetArgs,
    /// Publish at most this many frames per second (default: as recorded, each frame its
    /// timestamp's step after the previous one, so dropped frames keep their gap; 0 = as
    /// fast as possible).
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

/// How long the sensor waits for its reader before a heartbeat and a look for signals.
const READ_POLL: Duration = Duration::from_millis(20);

/// How long the sensor keeps its publisher after the end of data unless stopped first: iceoryx2
/// loses the samples of a publisher that left before a subscriber's first receive from it (a
/// one-frame recording's only frame, on a busy machine); a woken stage receives well within it.
const HOLD_AFTER_END: Duration = Duration::from_secs(2);

/// Sleeps in the WaitSet until `due`, with a heartbeat at least every [`HEARTBEAT`] (a
/// recording's gap may be longer than the watchdog's patience); whether a termination
/// signal came first.
fn wait_until(ws: &WaitSet, telemetry: &TelemetrySink, due: Instant) -> anyhow::Result<bool> {
    loop {
        telemetry.alive();
        let pause = due.saturating_duration_since(Instant::now()).min(HEARTBEAT);
        // Returns after the pause, or at once with a pending SIGINT/SIGTERM.
        match ws.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, pause) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                return Ok(true)
            }
            Ok(_) => {}
            Err(e) => return Err(anyhow::anyhow!("WaitSet: {e:?}")),
        }
        if Instant::now() >= due {
            return Ok(false);
        }
    }
}

/// A frame read this much after its time is late (the pacer's schedule has jitter of its own).
const LATE: Duration = Duration::from_millis(5);

/// Frames that were read after they were due: the machine could not read the dataset at
/// its rate beside the other stages.
#[derive(Default)]
struct Lateness {
    frames: usize,
    worst: Duration,
}

impl Lateness {
    fn note(&mut self, index: usize, late: Duration) {
        if late < LATE {
            return;
        }
        if self.frames == 0 {
            tracing::warn!(
                "sensor: frame {index} was read {:.0} ms after it was due (reading the dataset \
                 is slower than its rate on this machine)",
                late.as_secs_f64() * 1e3
            );
        }
        self.frames += 1;
        self.worst = self.worst.max(late);
    }

    fn report(&self) {
        if self.frames > 0 {
            tracing::warn!(
                "sensor: {} frames published late, read up to {:.0} ms after they were due",
                self.frames,
                self.worst.as_secs_f64() * 1e3
            );
        }
    }
}

/// Writes one frame into a loaned sample and sends it (`last`: the recording's last
/// frame); returns its stamp.
pub fn publish_frame(
    outlet: &Outlet<FrameHeader>,
    frame: &RgbdFrame,
    k: &Intrinsics,
    last: bool,
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
    let header = match last {
        true => header.last(),
        false => header,
    };
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
    let source = open_dataset(&args.dataset.spec()?)?;
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
    let mut pacer = Pacer::new(source.frame_rate(), args.max_rate);
    let ws = waitset()?;
    // Frames are waited for with timeouts; a long interval only lets the WaitSet see signals.
    let _tick = ws
        .attach_interval(Duration::from_secs(3600))
        .map_err(|e| anyhow::anyhow!("WaitSet interval: {e:?}"))?;
    tracing::info!(
        "{}: {total} frames{}, {k:?}, {}",
        source.name(),
        if args.live { " so far (live)" } else { "" },
        match args.max_rate {
            Some(r) if r <= 0.0 => "as fast as possible".to_string(),
            Some(r) => format!("as recorded, at most {r} frames/s"),
            None => format!("as recorded ({:.1} frames/s nominal)", source.frame_rate()),
        }
    );
    telemetry.ready();

    let reader = FrameReader::spawn(source, args.start_frame, args.live)?;
    let mut last = Stamp::new(MessageKind::Frame, 0, 0, 0);
    let mut published = args.start_frame;
    let mut late = Lateness::default();
    let signalled = loop {
        let frame = match reader.next(READ_POLL) {
            Some(Read::Frame(frame)) => frame,
            Some(Read::Failed(why)) => return Err(crate::stage_main::BadInput(why).into()),
            Some(Read::End) => break false,
            // Nothing read yet (a live recording between frames, a slow disk): heartbeat,
            // and look for a signal.
            None => match wait_until(&ws, &telemetry, Instant::now())? {
                true => break true,
                false => continue,
            },
        };
        let index = frame.index;
        if let Some(gap) = pacer
            .recorded_step(frame.timestamp)
            .filter(|gap| *gap >= ANNOUNCED_GAP)
        {
            tracing::info!(
                "sensor: the recording has a {:.1} s gap before frame {index}{}",
                gap.as_secs_f64(),
                match gap >= LONGEST_GAP {
                    true => format!(" (replayed as {} s)", LONGEST_GAP.as_secs()),
                    false => String::new(),
                }
            );
        }
        let due = pacer.due(frame.timestamp, Instant::now());
        late.note(index, pacer.lateness());
        if wait_until(&ws, &telemetry, due)? {
            break true;
        }
        let start = now_ns();
        // At the last frame the tracker lets go of the keyframes it holds back.
        let is_last = !args.live && index + 1 == total;
        let stamp = publish_frame(&frames, &frame, &k, is_last)?;
        let mut input = stamp;
        input.sent_ns = start;
        telemetry.processed(&input, start, now_ns());
        last = stamp;
        published = index + 1;
    };
    late.report();
    if signalled {
        tracing::info!("sensor: stopped by signal after frame {}", last.seq);
    } else {
        tracing::info!("sensor: end of data after {published} frames");
        telemetry.finished(&last);
        // The frames stay deliverable until the supervisor stops the run (or the hold ends).
        wait_until(&ws, &telemetry, Instant::now() + HOLD_AFTER_END)?;
        drop(frames);
    }
    Ok(())
}
