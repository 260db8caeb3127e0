use std::fmt::Debug;
use std::mem::MaybeUninit;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use opengs_ipc_schema::{now_ns, SchemaError, ServiceSpec, Stamped};

use crate::{Ipc, RunContext, RuntimeError};

/// Payload alignment of every service, so typed views need no copy.
const PAYLOAD_ALIGN: usize = opengs_ipc_schema::ALIGN;

fn open_pubsub<H: Debug + ZeroCopySend + 'static>(
    ctx: &RunContext,
    node: &Node<Ipc>,
    spec: &ServiceSpec,
) -> Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, [u8], H>,
    RuntimeError,
> {
    node.service_builder(&ctx.service_name(spec)?)
        .publish_subscribe::<[u8]>()
        .user_header::<H>()
        .payload_alignment(
            Alignment::new(PAYLOAD_ALIGN)
                .ok_or_else(|| RuntimeError::Iceoryx("alignment".into()))?,
        )
        .max_publishers(spec.max_publishers)
        .max_subscribers(spec.max_subscribers)
        .subscriber_max_buffer_size(spec.subscriber_buffer)
        .history_size(spec.history)
        // Camera-like streams: drop the oldest sample rather than block a publisher.
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| RuntimeError::Iceoryx(format!("opening service '{}': {e:?}", spec.name)))
}

fn open_event(
    ctx: &RunContext,
    node: &Node<Ipc>,
    spec: &ServiceSpec,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Ipc>, RuntimeError> {
    node.service_builder(&ctx.event_name(spec)?)
        .event()
        .max_notifiers(spec.max_publishers + 2)
        .max_listeners(spec.max_subscribers + 2)
        .open_or_create()
        .map_err(|e| RuntimeError::Iceoryx(format!("opening event '{}': {e:?}", spec.name)))
}

/// Publishing end of a service: loans shared memory, lets the caller write in
/// place, sends, and wakes the subscribers.
pub struct Outlet<H: Debug + ZeroCopySend + 'static> {
    publisher: Publisher<Ipc, [u8], H>,
    notifier: Notifier<Ipc>,
}

impl<H: Debug + Default + ZeroCopySend + Stamped + Copy + 'static> Outlet<H> {
    /// `max_payload` is the initial slice size; larger messages grow the pool.
    pub fn new(
        ctx: &RunContext,
        node: &Node<Ipc>,
        spec: &ServiceSpec,
        max_payload: usize,
    ) -> Result<Self, RuntimeError> {
        let service = open_pubsub::<H>(ctx, node, spec)?;
        let publisher = service
            .publisher_builder()
            .initial_max_slice_len(max_payload.max(8))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| RuntimeError::Iceoryx(format!("publisher on '{}': {e:?}", spec.name)))?;
        let notifier = open_event(ctx, node, spec)?
            .notifier_builder()
            .create()
            .map_err(|e| RuntimeError::Iceoryx(format!("notifier on '{}': {e:?}", spec.name)))?;
        Ok(Self {
            publisher,
            notifier,
        })
    }

    /// Loans `header.payload_len` bytes, lets `fill` write them in place, stamps
    /// `sent_ns`, sends and notifies. `fill` must write every byte.
    pub fn send(
        &self,
        mut header: H,
        fill: impl FnOnce(&H, &mut [MaybeUninit<u8>]) -> Result<(), SchemaError>,
    ) -> Result<(), RuntimeError> {
        let len = header.stamp().payload_len as usize;
        let mut sample = self
            .publisher
            .loan_slice_uninit(len)
            .map_err(|e| RuntimeError::Iceoryx(format!("loan of {len} bytes: {e:?}")))?;
        fill(&header, sample.payload_mut())?;
        header.stamp_mut().sent_ns = now_ns();
        *sample.user_header_mut() = header;
        // SAFETY: `fill` succeeded, and every encoder writes all `len` bytes (PayloadWriter::finish).
        let sample = unsafe { sample.assume_init() };
        sample
            .send()
            .map_err(|e| RuntimeError::Iceoryx(format!("send: {e:?}")))?;
        self.notifier
            .notify()
            .map_err(|e| RuntimeError::Iceoryx(format!("notify: {e:?}")))?;
        Ok(())
    }

    /// Sends a header-only message.
    pub fn send_header(&self, header: H) -> Result<(), RuntimeError> {
        self.send(header, |_, _| Ok(()))
    }

    /// Connects subscribers that appeared since the last send and hands them the service's
    /// history (a restarted stage gets the newest message without waiting for the next).
    pub fn update_connections(&self) -> Result<(), RuntimeError> {
        use iceoryx2::port::update_connections::UpdateConnections;
        self.publisher
            .update_connections()
            .map_err(|e| RuntimeError::Iceoryx(format!("update connections: {e:?}")))
    }
}

/// A received message: header plus payload, both in shared memory.
pub type Received<H> = Sample<Ipc, [u8], H>;

/// Subscribing end of a service, with the listener a WaitSet sleeps on.
pub struct Inlet<H: Debug + ZeroCopySend + 'static> {
    subscriber: Subscriber<Ipc, [u8], H>,
    listener: Listener<Ipc>,
    name: &'static str,
}

impl<H: Debug + ZeroCopySend + 'static> Inlet<H> {
    pub fn new(
        ctx: &RunContext,
        node: &Node<Ipc>,
        spec: &ServiceSpec,
    ) -> Result<Self, RuntimeError> {
        let service = open_pubsub::<H>(ctx, node, spec)?;
        let subscriber = service
            .subscriber_builder()
            .buffer_size(spec.subscriber_buffer)
            .create()
            .map_err(|e| RuntimeError::Iceoryx(format!("subscriber on '{}': {e:?}", spec.name)))?;
        // A subscriber is connected only after its first receive (iceoryx2 0.10): early samples
        // would be lost without this one.
        let _ = subscriber.receive();
        let listener = open_event(ctx, node, spec)?
            .listener_builder()
            .create()
            .map_err(|e| RuntimeError::Iceoryx(format!("listener on '{}': {e:?}", spec.name)))?;
        Ok(Self {
            subscriber,
            listener,
            name: spec.name,
        })
    }

    /// The listener to attach to a WaitSet.
    pub fn listener(&self) -> &Listener<Ipc> {
        &self.listener
    }

    /// Consumes pending wake-ups (call once per wake before draining samples).
    pub fn clear_wakeups(&self) {
        if let Err(e) = self.listener.try_wait(|_| {}) {
            tracing::warn!("listener on '{}': {e:?}", self.name);
        }
    }

    /// Next sample, if any.
    pub fn receive(&self) -> Result<Option<Received<H>>, RuntimeError> {
        self.subscriber
            .receive()
            .map_err(|e| RuntimeError::Iceoryx(format!("receive on '{}': {e:?}", self.name)))
    }

    /// Drains the queue and keeps only the newest sample; returns it and how many were skipped.
    pub fn receive_newest(&self) -> Result<(Option<Received<H>>, usize), RuntimeError> {
        let mut newest = None;
        let mut skipped = 0;
        while let Some(s) = self.receive()? {
            if newest.replace(s).is_some() {
                skipped += 1;
            }
        }
        Ok((newest, skipped))
    }

    pub fn name(&self) -> &'static str {
        self.name
    }
}
