//! `opengs bench ipc`: one-way latency of frames from a publisher to a woken
//! subscriber in another process, for a 640×480 RGB-D frame and a 10× smaller
//! one, paced at 30 Hz and as fast as possible.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::Duration;

use hdrhistogram::Histogram;
use opengs_ipc_schema::service::{FRAMES, TELEMETRY};
use opengs_ipc_schema::{now_ns, FrameHeader, FrameParts, MessageKind, Stamp, TelemetryHeader};
use opengs_runtime::{
    waitset, CallbackProgression, Inlet, Outlet, RunContext, TelemetrySink, WaitSetRunResult,
};
use serde::{Deserialize, Serialize};

#[derive(clap::Args)]
pub struct BenchIpcArgs {
    /// Messages per scenario.
    #[arg(long, default_value_t = 600, value_parser = clap::value_parser!(u64).range(1..))]
    count: u64,
}

#[derive(clap::Args)]
pub struct SinkArgs {
    #[arg(long)]
    run_id: String,
}

/// Scenario id travels in `frame_index`; this one ends the benchmark.
const END: u64 = u64::MAX;

const SCENARIOS: [(&str, u32, u32, Option<f64>); 4] = [
    ("640x480 RGB-D @30Hz", 640, 480, Some(30.0)),
    ("10x smaller @30Hz", 202, 152, Some(30.0)),
    ("640x480 RGB-D max rate", 640, 480, None),
    ("10x smaller max rate", 202, 152, None),
];

#[derive(Serialize, Deserialize)]
struct SinkResult {
    scenario: u64,
    count: u64,
    p50_us: f64,
    p99_us: f64,
    max_us: f64,
}

pub fn run(args: BenchIpcArgs) -> anyhow::Result<()> {
    let run_id = format!("bench-ipc-{}", std::process::id());
    let ctx = RunContext::new(&run_id)?;
    let node = ctx.node("bench_pub")?;
    let frames = Outlet::<FrameHeader>::new(&ctx, &node, &FRAMES, 640 * 480 * 5 + 64)?;
    let ready = Inlet::<TelemetryHeader>::new(&ctx, &node, &TELEMETRY)?;
    let exe = std::env::current_exe()?;
    let mut child = Command::new(exe)
        .args(["ipc-sink", "--run-id", &run_id])
        .stdout(Stdio::piped())
        .spawn()?;
    let ws = waitset()?;
    let _g = ws
        .attach_deadline(ready.listener(), Duration::from_secs(10))
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut is_ready = false;
    while !is_ready {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                anyhow::bail!("interrupted")
            }
            Err(e) => anyhow::bail!("{e:?}"),
            Ok(_) => {}
        }
        ready.clear_wakeups();
        while let Some(s) = ready.receive()? {
            is_ready |= s.user_header().stage_name() == "ipc_sink";
        }
        if !is_ready && child.try_wait()?.is_some() {
            anyhow::bail!("the subscriber process exited before it was ready");
        }
    }
    eprintln!("subscriber ready; {} messages per scenario", args.count);
    for (id, (name, w, h, rate)) in SCENARIOS.iter().enumerate() {
        let n = (*w * *h) as usize;
        let depth = vec![1000u16; n];
        let rgb = vec![128u8; 3 * n];
        let period = rate.map(|r| Duration::from_secs_f64(1.0 / r));
        let tick = ws
            .attach_interval(period.unwrap_or(Duration::from_millis(1)))
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        eprintln!("  {name} ...");
        for seq in 0..args.count {
            if period.is_some() {
                ws.wait_and_process_once(|_| CallbackProgression::Continue)
                    .map_err(|e| anyhow::anyhow!("{e:?}"))?;
            } else if seq % 2 == 0 {
                // Let the subscriber run between bursts on a 2-core box, without sleeping.
                std::thread::yield_now();
            }
            send(&frames, *w, *h, seq, id as u64, &depth, &rgb)?;
        }
        drop(tick);
    }
    send(&frames, 1, 1, 0, END, &[0], &[0, 0, 0])?;
    let stdout = child
        .stdout
        .take()
        .ok_or_else(|| anyhow::anyhow!("no subscriber output"))?;
    let mut results: Vec<SinkResult> = Vec::new();
    for line in BufReader::new(stdout).lines() {
        results.push(serde_json::from_str(&line?)?);
    }
    child.wait()?;
    println!(
        "{:<26} {:>7} {:>10} {:>10} {:>10}",
        "scenario", "count", "p50 µs", "p99 µs", "max µs"
    );
    for r in &results {
        let name = SCENARIOS.get(r.scenario as usize).map_or("?", |s| s.0);
        println!(
            "{name:<26} {:>7} {:>10.1} {:>10.1} {:>10.1}",
            r.count, r.p50_us, r.p99_us, r.max_us
        );
    }
    let p = |i: usize| {
        results
            .iter()
            .find(|r| r.scenario == i as u64)
            .map(|r| (r.p50_us, r.p99_us))
    };
    if let (Some(big), Some(small)) = (p(0), p(1)) {
        println!("big/small ratio at 30 Hz: p50 {:.2}, p99 {:.2}  (zero-copy: cost does not grow with payload)", big.0 / small.0, big.1 / small.1);
    }
    if let (Some(big), Some(small)) = (p(2), p(3)) {
        println!(
            "big/small ratio at max rate: p50 {:.2}, p99 {:.2}",
            big.0 / small.0,
            big.1 / small.1
        );
    }
    Ok(())
}

fn send(
    frames: &Outlet<FrameHeader>,
    w: u32,
    h: u32,
    seq: u64,
    scenario: u64,
    depth: &[u16],
    rgb: &[u8],
) -> anyhow::Result<()> {
    let stamp = Stamp::new(MessageKind::Frame, seq, 0, now_ns());
    let header = FrameHeader::new(
        stamp,
        w,
        h,
        5000.0,
        [500.0, 500.0, w as f64 / 2.0, h as f64 / 2.0],
        None,
        false,
        scenario,
    );
    let parts = FrameParts {
        depth,
        labels: None,
        rgb,
    };
    frames.send(header, |hd, buf| hd.encode(&parts, buf))?;
    Ok(())
}

/// Subscriber process: records wake-up latency per scenario, prints JSON lines at the end.
pub fn run_sink(args: SinkArgs) -> anyhow::Result<()> {
    let ctx = RunContext::new(&args.run_id)?;
    let node = ctx.node("bench_sink")?;
    let frames = Inlet::<FrameHeader>::new(&ctx, &node, &FRAMES)?;
    let telemetry = TelemetrySink::new(&ctx, &node, "ipc_sink")?;
    let mut hists: Vec<Histogram<u64>> = (0..SCENARIOS.len())
        .map(|_| Histogram::new_with_bounds(1, 60_000_000, 3))
        .collect::<Result<_, _>>()?;
    let ws = waitset()?;
    let _g = ws
        .attach_notification(frames.listener())
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    telemetry.ready();
    let mut done = false;
    let mut checksum = 0u64;
    while !done {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => break,
            Err(e) => anyhow::bail!("{e:?}"),
            Ok(_) => {}
        }
        frames.clear_wakeups();
        while let Some(s) = frames.receive()? {
            let now = now_ns();
            let h = s.user_header();
            let view = h.decode(s.payload())?;
            // Touch the payload as a consumer would, at both ends.
            checksum =
                checksum.wrapping_add(view.depth[0] as u64 + view.rgb[view.rgb.len() - 1] as u64);
            if h.frame_index == END {
                done = true;
                continue;
            }
            if let Some(hist) = hists.get_mut(h.frame_index as usize) {
                hist.saturating_record((now.saturating_sub(h.stamp.sent_ns) / 1000).max(1));
            }
        }
    }
    tracing::debug!("checksum {checksum}");
    for (i, h) in hists.iter().enumerate() {
        let r = SinkResult {
            scenario: i as u64,
            count: h.len(),
            p50_us: h.value_at_quantile(0.5) as f64,
            p99_us: h.value_at_quantile(0.99) as f64,
            max_us: h.max() as f64,
        };
        println!("{}", serde_json::to_string(&r)?);
    }
    Ok(())
}
