//! `opengs bench bridge`: what a Zenoh link between hosts adds to a message's one-way
//! latency. Two `opengs-bridge` processes on this machine, each over its own iceoryx2 domain
//! (they share nothing but a Zenoh link on loopback): messages published on domain A reach a
//! subscriber on A directly (iceoryx2 alone) and one on B through both bridges, in the same
//! run, for a 640×480 RGB-D frame (1.5 MB) and a 640×480 label map (1.2 MB) at 10 Hz.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use hdrhistogram::Histogram;
use opengs_ipc_schema::service::{FRAMES, SEGMENTS};
use opengs_ipc_schema::{
    now_ns, FrameHeader, FrameParts, MessageKind, SegmentLabel, SegmentsHeader, Stamp, Stamped,
};
use opengs_runtime::iceoryx2::prelude::ZeroCopySend;
use opengs_runtime::{waitset, CallbackProgression, Inlet, Outlet, RunContext};

#[derive(clap::Args)]
pub struct BenchBridgeArgs {
    /// Messages of each kind.
    #[arg(long, default_value_t = 300, value_parser = clap::value_parser!(u64).range(1..))]
    count: u64,
}

/// Kills the bridge processes whatever path the bench leaves by.
struct Bridges(Vec<Child>);

impl Drop for Bridges {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

pub fn run(args: BenchBridgeArgs) -> anyhow::Result<()> {
    let binary = opengs_pipeline::stage_process::resolve_binary("opengs-bridge");
    if !binary.exists() {
        anyhow::bail!(
            "opengs-bridge is not built (it needs Zenoh): cargo build --release --workspace \
             --bins --features opengs-bridge/zenoh"
        );
    }
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .context("finding a free port")?
        .port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let link = format!("bb{}", std::process::id());
    let (run_a, run_b) = (format!("{link}a"), format!("{link}b"));
    let logs = std::env::temp_dir();
    let spawn = |run_id: &str, args: &[&str]| -> anyhow::Result<Child> {
        let log = std::fs::File::create(logs.join(format!("opengs-bench-{run_id}.log")))?;
        Command::new(&binary)
            .args(["--run-id", run_id, "--link", &link])
            .args(args)
            .stdin(Stdio::null())
            .stdout(log.try_clone()?)
            .stderr(log)
            .spawn()
            .with_context(|| format!("starting {}", binary.display()))
    };
    let _bridges = Bridges(vec![
        spawn(
            &run_a,
            &[
                "--export", "frames", "--export", "segments", "--listen", &endpoint,
            ],
        )?,
        spawn(
            &run_b,
            &[
                "--import",
                "frames",
                "--import",
                "segments",
                "--connect",
                &endpoint,
            ],
        )?,
    ]);
    let (ctx_a, ctx_b) = (RunContext::new(&run_a)?, RunContext::new(&run_b)?);
    let (node_a, node_b) = (ctx_a.node("bench_a")?, ctx_b.node("bench_b")?);
    let frames_out = Outlet::<FrameHeader>::new(&ctx_a, &node_a, &FRAMES, 640 * 480 * 5 + 64)?;
    let frames_a = Inlet::<FrameHeader>::new(&ctx_a, &node_a, &FRAMES)?;
    let frames_b = Inlet::<FrameHeader>::new(&ctx_b, &node_b, &FRAMES)?;
    let labels_out = Outlet::<SegmentsHeader>::new(&ctx_a, &node_a, &SEGMENTS, 640 * 480 * 4 + 64)?;
    let labels_a = Inlet::<SegmentsHeader>::new(&ctx_a, &node_a, &SEGMENTS)?;
    let labels_b = Inlet::<SegmentsHeader>::new(&ctx_b, &node_b, &SEGMENTS)?;

    let (w, h) = (640u32, 480u32);
    let depth: Vec<u16> = (0..w * h).map(|i| (1000 + i % 3000) as u16).collect();
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i % 251) as u8).collect();
    let label_map: Vec<u32> = (0..w * h).map(|i| 1 + (i / 4096) % 40).collect();
    let labels: Vec<SegmentLabel> = (1..=40)
        .map(|l| SegmentLabel::new(l, 0.9, Some("object"), 0.5))
        .collect();
    let send_frame = |seq: u64| -> anyhow::Result<()> {
        let header = FrameHeader::new(
            Stamp::new(MessageKind::Frame, seq, 0, now_ns()),
            w,
            h,
            5000.0,
            [525.0, 525.0, 319.5, 239.5],
            None,
            false,
            seq,
        );
        let parts = FrameParts {
            depth: &depth,
            labels: None,
            rgb: &rgb,
        };
        frames_out.send(header, |hd, buf| hd.encode(&parts, buf))?;
        Ok(())
    };
    let send_labels = |seq: u64| -> anyhow::Result<()> {
        let header = SegmentsHeader::new(
            Stamp::new(MessageKind::Segments, seq, 0, now_ns()),
            w,
            h,
            labels.len() as u32,
            0,
        );
        labels_out.send(header, |hd, buf| hd.encode(&label_map, &labels, buf))?;
        Ok(())
    };

    println!(
        "bridge latency: 640x480 messages at 10 Hz, iceoryx2 alone vs through Zenoh on loopback"
    );
    let warm = Instant::now();
    loop {
        send_frame(u64::MAX)?;
        send_labels(u64::MAX)?;
        std::thread::sleep(Duration::from_millis(100));
        let through = frames_b.receive()?.is_some() && labels_b.receive()?.is_some();
        while frames_a.receive()?.is_some() || frames_b.receive()?.is_some() {}
        while labels_a.receive()?.is_some() || labels_b.receive()?.is_some() {}
        if through {
            break;
        }
        if warm.elapsed() > Duration::from_secs(30) {
            anyhow::bail!(
                "the two bridges did not connect in 30 s; logs: {}",
                logs.join(format!("opengs-bench-{run_a}.log")).display()
            );
        }
    }
    let frame = measure(args.count, send_frame, &frames_a, &frames_b)?;
    let label = measure(args.count, send_labels, &labels_a, &labels_b)?;
    println!(
        "{:<34} {:>6} {:>10} {:>10} {:>10}",
        "message, path", "count", "p50 ms", "p99 ms", "max ms"
    );
    for (name, (direct, bridged)) in [("RGB-D frame 1.5 MB", frame), ("label map 1.2 MB", label)] {
        for (path, hist) in [("iceoryx2", &direct), ("Zenoh bridge", &bridged)] {
            println!(
                "{:<34} {:>6} {:>10.3} {:>10.3} {:>10.3}",
                format!("{name}, {path}"),
                hist.len(),
                hist.value_at_quantile(0.5) as f64 / 1e3,
                hist.value_at_quantile(0.99) as f64 / 1e3,
                hist.max() as f64 / 1e3
            );
        }
        println!(
            "{:<34} {:>6} {:>10.3} {:>10.3}",
            format!("{name}, added"),
            "",
            (bridged.value_at_quantile(0.5) as f64 - direct.value_at_quantile(0.5) as f64) / 1e3,
            (bridged.value_at_quantile(0.99) as f64 - direct.value_at_quantile(0.99) as f64) / 1e3,
        );
    }
    Ok(())
}

/// Sends `count` messages at 10 Hz; one-way latency (µs) to the direct and bridged receivers.
fn measure<H: Stamped + std::fmt::Debug + ZeroCopySend + 'static>(
    count: u64,
    send: impl Fn(u64) -> anyhow::Result<()>,
    direct: &Inlet<H>,
    bridged: &Inlet<H>,
) -> anyhow::Result<(Histogram<u64>, Histogram<u64>)> {
    let ws = waitset()?;
    let _a = ws
        .attach_notification(direct.listener())
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let _b = ws
        .attach_notification(bridged.listener())
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let mut hists = (Histogram::<u64>::new(3)?, Histogram::<u64>::new(3)?);
    for seq in 0..count {
        let period = Instant::now();
        send(seq)?;
        let (mut got_direct, mut got_bridged) = (false, false);
        while !(got_direct && got_bridged) && period.elapsed() < Duration::from_millis(100) {
            let left = Duration::from_millis(100).saturating_sub(period.elapsed());
            ws.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, left)
                .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
            let now = now_ns();
            direct.clear_wakeups();
            bridged.clear_wakeups();
            for (inlet, got, hist) in [
                (direct, &mut got_direct, &mut hists.0),
                (bridged, &mut got_bridged, &mut hists.1),
            ] {
                while let Some(s) = inlet.receive()? {
                    let stamp = s.user_header().stamp();
                    if stamp.seq == seq {
                        *got = true;
                        hist.saturating_record(now.saturating_sub(stamp.origin_ns) / 1000);
                    }
                }
            }
        }
        std::thread::sleep(Duration::from_millis(100).saturating_sub(period.elapsed()));
    }
    Ok(hists)
}
