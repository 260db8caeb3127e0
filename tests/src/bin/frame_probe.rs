//! A checking subscriber for the end-to-end tests: receives frames, validates
//! them, and prints `seq checksum` per frame. Runs alone or as a pipeline stage.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use opengs_e2e::frame_checksum;
use opengs_ipc_schema::service::FRAMES;
use opengs_ipc_schema::{now_ns, FrameHeader};
use opengs_runtime::{
    waitset, CallbackProgression, Inlet, RunContext, TelemetrySink, WaitSetRunResult,
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
}

fn run(args: Args) -> anyhow::Result<()> {
    let ctx = RunContext::new(&args.run_id)?;
    let node = ctx.node("probe")?;
    let frames = Inlet::<FrameHeader>::new(&ctx, &node, &FRAMES)?;
    let telemetry = TelemetrySink::new(&ctx, &node, "probe")?;
    let ws = waitset()?;
    let _g = ws
        .attach_notification(frames.listener())
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
