//! A checking subscriber for the end-to-end tests: receives frames, validates
//! them, and prints `seq checksum` per frame; or, with `--segments`, prints
//! `seq arrival_ns segmenter labels` per segmentation. Runs alone or as a stage.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_e2e::frame_checksum;
use opengs_ipc_schema::service::{FRAMES, SEGMENTS};
use opengs_ipc_schema::{now_ns, FrameHeader, SegmentsHeader};
use opengs_runtime::{
    waitset, CallbackProgression, Inlet, RunContext, TelemetrySink, WaitSetRunResult, HEARTBEAT,
};

#[derive(Parser)]
struct Args {
    #[arg(long)]
    run_id: String,
    #[arg(long)]
    out: Option<PathBuf>,
    /// Exit after this many frames (default: run until stopped).
    #[arg(long)]
    count: Option<u64>,
    /// Watch the segments stream instead of frames.
    #[arg(long)]
    segments: bool,
}

fn watch_segments(
    ctx: &RunContext,
    node: &opengs_runtime::iceoryx2::prelude::Node<opengs_runtime::Ipc>,
) -> anyhow::Result<()> {
    let segments = Inlet::<SegmentsHeader>::new(ctx, node, &SEGMENTS)?;
    let telemetry = TelemetrySink::new(ctx, node, "probe")?;
    let ws = waitset()?;
    let _g = ws
        .attach_notification(segments.listener())
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    // Wakes at least once per heartbeat, so the supervisor's watchdog hears from it.
    let _tick = ws
        .attach_interval(HEARTBEAT)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    writeln!(out, "ready")?;
    out.flush()?;
    telemetry.ready();
    loop {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => return Ok(()),
            Err(e) => anyhow::bail!("{e:?}"),
            Ok(_) => {}
        }
        telemetry.alive();
        segments.clear_wakeups();
        while let Some(sample) = segments.receive()? {
            let now = now_ns();
            let h = sample.user_header();
            match h.decode(sample.payload()) {
                Ok(view) => {
                    writeln!(
                        out,
                        "{} {now} {} {}",
                        h.stamp.seq,
                        h.segmenter,
                        view.labels.len()
                    )?;
                    out.flush()?;
                    telemetry.processed(&h.stamp, now.max(h.stamp.sent_ns), now_ns());
                }
                Err(e) => writeln!(out, "{} rejected: {e}", h.stamp.seq)?,
            }
        }
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    let ctx = RunContext::new(&args.run_id)?;
    let node = ctx.node("probe")?;
    if args.segments {
        return watch_segments(&ctx, &node);
    }
    let frames = Inlet::<FrameHeader>::new(&ctx, &node, &FRAMES)?;
    let telemetry = TelemetrySink::new(&ctx, &node, "probe")?;
    let ws = waitset()?;
    let _g = ws
        .attach_notification(frames.listener())
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    // Wakes at least once per heartbeat, so the supervisor's watchdog hears from it.
    let _tick = ws
        .attach_interval(HEARTBEAT)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    writeln!(out, "ready")?;
    out.flush()?;
    telemetry.ready();
    let mut seen = 0u64;
    loop {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => return Ok(()),
            Err(e) => anyhow::bail!("{e:?}"),
            Ok(_) => {}
        }
        telemetry.alive();
        frames.clear_wakeups();
        while let Some(sample) = frames.receive()? {
            let start = now_ns();
            let h = sample.user_header();
            match h.decode(sample.payload()) {
                Ok(view) => {
                    writeln!(
                        out,
                        "{} {}",
                        h.stamp.seq,
                        frame_checksum(view.depth, view.rgb)
                    )?;
                    out.flush()?;
                    telemetry.processed(&h.stamp, start.max(h.stamp.sent_ns), now_ns());
                }
                Err(e) => {
                    writeln!(out, "{} rejected: {e}", h.stamp.seq)?;
                    telemetry.dropped(&h.stamp);
                }
            }
            seen += 1;
            if args.count.is_some_and(|c| seen >= c) {
                return Ok(());
            }
        }
    }
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("probe: {e:#}");
            ExitCode::FAILURE
        }
    }
}
