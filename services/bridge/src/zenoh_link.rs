//! The bridge at run time: exported services go from this host's iceoryx2 to Zenoh as
//! [`opengs_ipc_schema::to_wire`] bytes; imported ones come from Zenoh, are validated by
//! [`opengs_ipc_schema::from_wire`] (length, layout, the header's own `decode`) and only then
//! published here. A message that fails is dropped and logged with the service it came on.

use std::mem::MaybeUninit;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;

use opengs_ipc_schema::{
    from_wire, now_ns, service, to_wire, ConsensusHeader, FrameHeader, KeyframeHeader,
    MapTargetHeader, PayloadWriter, PoseHeader, RenderHeader, SchemaError, SegmentsHeader,
    ServiceSpec, Stamp, TelemetryHeader, WireMessage,
};
use opengs_runtime::iceoryx2::port::listener::Listener;
use opengs_runtime::iceoryx2::prelude::{Node, ZeroCopySend};
use opengs_runtime::{
    waitset, CallbackProgression, Inlet, Ipc, Outlet, RunContext, TelemetrySink, WaitSetRunResult,
    HEARTBEAT,
};
use zenoh::qos::CongestionControl;
use zenoh::Wait;

use crate::link::Link;

/// Messages taken off the link and not yet published here (a keyframe is ~2 MB).
const INBOX: usize = 16;

/// One exported service: this host's subscriber.
trait ExportPort {
    fn listener(&self) -> &Listener<Ipc>;
    /// Every waiting message as (its stamp, wire bytes).
    fn drain(&self, send: &mut dyn FnMut(&Stamp, Vec<u8>)) -> anyhow::Result<()>;
}

struct Export<H: std::fmt::Debug + ZeroCopySend + 'static>(Inlet<H>);

impl<H: WireMessage + ZeroCopySend + 'static> ExportPort for Export<H> {
    fn listener(&self) -> &Listener<Ipc> {
        self.0.listener()
    }

    fn drain(&self, send: &mut dyn FnMut(&Stamp, Vec<u8>)) -> anyhow::Result<()> {
        self.0.clear_wakeups();
        while let Some(s) = self.0.receive()? {
            let h = s.user_header();
            send(h.stamp(), to_wire(h, s.payload()));
        }
        Ok(())
    }
}

/// One imported service: this host's publisher.
trait ImportPort {
    /// Validates `bytes` and publishes them here; the message's stamp.
    fn publish(&self, bytes: &[u8]) -> anyhow::Result<Stamp>;
}

struct Import<H: std::fmt::Debug + ZeroCopySend + 'static>(Outlet<H>);

impl<H: WireMessage + ZeroCopySend + Default + 'static> ImportPort for Import<H> {
    fn publish(&self, bytes: &[u8]) -> anyhow::Result<Stamp> {
        let message = from_wire::<H>(bytes)?;
        let payload = message.payload();
        let fill = |_: &H, buf: &mut [MaybeUninit<u8>]| -> Result<(), SchemaError> {
            let mut w = PayloadWriter::new(buf);
            w.put(payload)?;
            w.finish()
        };
        self.0.send(message.header, fill)?;
        Ok(*message.header.stamp())
    }
}

/// `$f::<Header>(args)` with the header type of the service called `$name`.
macro_rules! with_header {
    ($name:expr, $f:ident ( $($arg:expr),* )) => {
        match $name {
            n if n == service::FRAMES.name => $f::<FrameHeader>($($arg),*),
            n if n == service::POSES.name => $f::<PoseHeader>($($arg),*),
            n if n == service::KEYFRAMES.name => $f::<KeyframeHeader>($($arg),*),
            n if n == service::SEGMENTS.name => $f::<SegmentsHeader>($($arg),*),
            n if n == service::RENDERS.name => $f::<RenderHeader>($($arg),*),
            n if n == service::CONSENSUS.name => $f::<ConsensusHeader>($($arg),*),
            n if n == service::MAP_TARGET.name => $f::<MapTargetHeader>($($arg),*),
            n if n == service::TELEMETRY.name => $f::<TelemetryHeader>($($arg),*),
            n => anyhow::bail!("no bridge for service '{n}'"),
        }
    };
}

fn export_port(
    ctx: &RunContext,
    node: &Node<Ipc>,
    spec: &ServiceSpec,
) -> anyhow::Result<Box<dyn ExportPort>> {
    fn make<H: WireMessage + ZeroCopySend + 'static>(
        ctx: &RunContext,
        node: &Node<Ipc>,
        spec: &ServiceSpec,
    ) -> anyhow::Result<Box<dyn ExportPort>> {
        Ok(Box::new(Export(Inlet::<H>::new(ctx, node, spec)?)))
    }
    with_header!(spec.name, make(ctx, node, spec))
}

fn import_port(
    ctx: &RunContext,
    node: &Node<Ipc>,
    spec: &ServiceSpec,
) -> anyhow::Result<Box<dyn ImportPort>> {
    fn make<H: WireMessage + ZeroCopySend + Default + 'static>(
        ctx: &RunContext,
        node: &Node<Ipc>,
        spec: &ServiceSpec,
    ) -> anyhow::Result<Box<dyn ImportPort>> {
        // The pool grows past this for larger messages.
        Ok(Box::new(Import(Outlet::<H>::new(
            ctx,
            node,
            spec,
            1 << 20,
        )?)))
    }
    with_header!(spec.name, make(ctx, node, spec))
}

/// Runs the bridge (the stage called `name`) until a termination signal.
pub fn run_bridge(ctx: &RunContext, link: &Link, name: &str) -> anyhow::Result<()> {
    let config = zenoh::Config::from_json5(&link.zenoh_config().to_string())
        .map_err(|e| anyhow::anyhow!("Zenoh configuration: {e}"))?;
    let session = zenoh::open(config)
        .wait()
        .map_err(|e| anyhow::anyhow!("opening the Zenoh session: {e}"))?;
    tracing::info!(
        "bridge {}: listening on {:?}, connecting to {:?}; out {:?}, in {:?}",
        link.key_prefix,
        link.listen,
        link.connect,
        link.export.iter().map(|s| s.name).collect::<Vec<_>>(),
        link.import.iter().map(|s| s.name).collect::<Vec<_>>()
    );
    // Zenoh delivers on its own threads; the messages wait here for the import thread.
    let (inbox, taken) = std::sync::mpsc::sync_channel::<(usize, Vec<u8>)>(INBOX);
    let mut subscribers = Vec::new();
    for (i, spec) in link.import.iter().enumerate() {
        let inbox: SyncSender<_> = inbox.clone();
        let name = spec.name;
        let sub = session
            .declare_subscriber(link.key(spec))
            .callback(move |sample| {
                let bytes = sample.payload().to_bytes().into_owned();
                if let Err(TrySendError::Full(_)) = inbox.try_send((i, bytes)) {
                    tracing::warn!(
                        "{name}: the link delivers faster than this host takes; dropped one"
                    );
                }
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("subscribing to {}: {e}", link.key(spec)))?;
        subscribers.push(sub);
    }
    drop(inbox);
    let stop = Arc::new(AtomicBool::new(false));
    let importer = {
        let (ctx, imports, stop) = (ctx.clone(), link.import.clone(), stop.clone());
        let name = name.to_string();
        std::thread::spawn(move || import_loop(&ctx, &name, &imports, taken, &stop))
    };
    let exported = export_loop(ctx, name, link, &session);
    stop.store(true, Ordering::Relaxed);
    drop(subscribers);
    let imported = importer
        .join()
        .map_err(|_| anyhow::anyhow!("the import thread panicked"))?;
    if let Err(e) = session.close().wait() {
        tracing::warn!("closing the Zenoh session: {e}");
    }
    exported.and(imported)
}

/// Sends every exported message to the link until a termination signal.
fn export_loop(
    ctx: &RunContext,
    name: &str,
    link: &Link,
    session: &zenoh::Session,
) -> anyhow::Result<()> {
    let node = ctx.node(&format!("bridge_out_{}", std::process::id()))?;
    let telemetry = TelemetrySink::new(ctx, &node, name)?;
    let ports: Vec<Box<dyn ExportPort>> = link
        .export
        .iter()
        .map(|spec| export_port(ctx, &node, spec))
        .collect::<anyhow::Result<_>>()?;
    let mut publishers = Vec::new();
    for spec in &link.export {
        publishers.push(
            session
                .declare_publisher(link.key(spec))
                // Keyframes and segmentations are not to be lost to a busy link.
                .congestion_control(CongestionControl::Block)
                .wait()
                .map_err(|e| anyhow::anyhow!("publishing on {}: {e}", link.key(spec)))?,
        );
    }
    let ws = waitset()?;
    let mut guards = Vec::new();
    for p in &ports {
        guards.push(
            ws.attach_notification(p.listener())
                .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?,
        );
    }
    let _heartbeat = ws
        .attach_interval(HEARTBEAT)
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let mut missed: Vec<Missed> = link.export.iter().map(|_| Missed::default()).collect();
    if link.wait_for_peer {
        let unheard = |publishers: &[zenoh::pubsub::Publisher]| -> Vec<String> {
            publishers
                .iter()
                .filter(|p| !p.matching_status().wait().is_ok_and(|m| m.matching()))
                .map(|p| p.key_expr().to_string())
                .collect()
        };
        let mut said = false;
        loop {
            let waiting = unheard(&publishers);
            if waiting.is_empty() {
                break;
            }
            if !std::mem::replace(&mut said, true) {
                tracing::info!(
                    "waiting for a host that subscribes to {}",
                    waiting.join(", ")
                );
            }
            match ws.wait_and_process_once_with_timeout(
                |_| CallbackProgression::Continue,
                std::time::Duration::from_millis(50),
            ) {
                Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                    return Ok(())
                }
                Err(e) => anyhow::bail!("WaitSet: {e:?}"),
                Ok(_) => {}
            }
            // Local messages meanwhile are not kept: the run has not started.
            for port in &ports {
                port.drain(&mut |_, _| {})?;
            }
        }
        tracing::info!("every exported service has a subscriber on another host");
    }
    telemetry.ready();
    loop {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                for (m, spec) in missed.iter_mut().zip(&link.export) {
                    m.observe(spec.name, true, 0);
                }
                return Ok(());
            }
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
            Ok(_) => {}
        }
        telemetry.alive();
        for (((port, publisher), spec), missed) in ports
            .iter()
            .zip(&publishers)
            .zip(&link.export)
            .zip(&mut missed)
        {
            // Telemetry about carrying telemetry would be carried too, without end.
            let report = spec.name != service::TELEMETRY.name;
            port.drain(&mut |stamp, bytes| {
                if report {
                    let heard = publisher
                        .matching_status()
                        .wait()
                        .is_ok_and(|m| m.matching());
                    missed.observe(spec.name, heard, stamp.seq);
                }
                let start = now_ns();
                match publisher.put(bytes).wait() {
                    Ok(()) if report => telemetry.processed(stamp, start, now_ns()),
                    Ok(()) => {}
                    Err(e) => tracing::warn!("{}: {e}", publisher.key_expr()),
                }
            })?;
        }
    }
}

/// Messages of one exported service sent while no other host subscribed: lost to the other
/// side (the link was down, or that host not started). Said once when it starts and once,
/// with the count and seqs, when a host is back.
#[derive(Default)]
struct Missed {
    /// (count, first seq, last seq) of the current stretch.
    stretch: Option<(u64, u64, u64)>,
}

impl Missed {
    fn observe(&mut self, service: &str, heard: bool, seq: u64) {
        match (&mut self.stretch, heard) {
            (None, false) => {
                tracing::warn!(
                    "{service}: no other host receives it now (link down or not started)"
                );
                self.stretch = Some((1, seq, seq));
            }
            (Some((n, _, last)), false) => {
                *n += 1;
                *last = seq;
            }
            (Some((n, first, last)), true) => {
                tracing::warn!(
                    "{service}: {n} messages (seq {first} to {last}) went out while no other host \
                     received them; they are lost to it"
                );
                self.stretch = None;
            }
            (None, true) => {}
        }
    }
}

/// Publishes here what the link brings, until `stop`.
fn import_loop(
    ctx: &RunContext,
    name: &str,
    imports: &[ServiceSpec],
    taken: Receiver<(usize, Vec<u8>)>,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let node = ctx.node(&format!("bridge_in_{}", std::process::id()))?;
    let telemetry = TelemetrySink::new(ctx, &node, name)?;
    let ports: Vec<Box<dyn ImportPort>> = imports
        .iter()
        .map(|spec| import_port(ctx, &node, spec))
        .collect::<anyhow::Result<_>>()?;
    while !stop.load(Ordering::Relaxed) {
        match taken.recv_timeout(HEARTBEAT) {
            Ok((i, bytes)) => {
                let start = now_ns();
                match ports[i].publish(&bytes) {
                    Ok(stamp) if imports[i].name != service::TELEMETRY.name => {
                        telemetry.processed(&stamp, start, now_ns())
                    }
                    Ok(_) => {}
                    Err(e) => tracing::error!("{} from the link rejected: {e:#}", imports[i].name),
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        telemetry.alive();
    }
    Ok(())
}
