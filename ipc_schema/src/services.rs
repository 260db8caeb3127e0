//! Service names and QoS: one table, so publishers and subscribers agree.

/// Name and QoS of one pipeline service (publish-subscribe plus its wake-up event).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServiceSpec {
    /// Service name below the run's namespace, e.g. `frames`.
    pub name: &'static str,
    /// Room for a hot swap: old and new producer publish at once.
    pub max_publishers: usize,
    pub max_subscribers: usize,
    /// Samples a subscriber buffers before the oldest is dropped (safe overflow).
    pub subscriber_buffer: usize,
    /// Samples a late subscriber receives on connect.
    pub history: usize,
}

const fn spec(
    name: &'static str,
    max_publishers: usize,
    subscriber_buffer: usize,
    history: usize,
) -> ServiceSpec {
    ServiceSpec {
        name,
        max_publishers,
        max_subscribers: 8,
        subscriber_buffer,
        history,
    }
}

pub const FRAMES: ServiceSpec = spec("frames", 2, 8, 0);
pub const POSES: ServiceSpec = spec("poses", 2, 64, 0);
/// History serves a restarted mapper the keyframes sent while it was dead or hung (as many
/// as a stopped mapper's own buffer would have held; 16 × ~2 MB of shared memory).
/// Subscribers: the mapper, the viewer and up to 6 segmenter replicas.
pub const KEYFRAMES: ServiceSpec = spec("keyframes", 2, 16, 16);
/// History serves a restarted consensus (or mapper) the segmentations and the render it was
/// waiting for, so the keyframe in flight is answered instead of timing out. Publishers:
/// up to 6 segmenter replicas, one more while a swap or a scale starts a process beside them.
pub const SEGMENTS: ServiceSpec = spec("segments", 8, 8, 4);
pub const RENDERS: ServiceSpec = spec("renders", 2, 8, 2);
pub const CONSENSUS: ServiceSpec = spec("consensus", 2, 16, 0);
/// The newest map target is all the tracker needs; history 1 serves a restarted tracker.
pub const MAP_TARGET: ServiceSpec = spec("map_target", 2, 2, 1);
pub const TELEMETRY: ServiceSpec = ServiceSpec {
    name: "telemetry",
    max_publishers: 16,
    max_subscribers: 4,
    subscriber_buffer: 1024,
    history: 0,
};
pub const CONTROL_REQUESTS: ServiceSpec = ServiceSpec {
    name: "control/requests",
    max_publishers: 8,
    max_subscribers: 2,
    subscriber_buffer: 16,
    history: 0,
};
pub const CONTROL_REPLIES: ServiceSpec = ServiceSpec {
    name: "control/replies",
    max_publishers: 2,
    max_subscribers: 8,
    subscriber_buffer: 16,
    history: 0,
};

/// Every service of the pipeline.
pub const SERVICES: [ServiceSpec; 10] = [
    FRAMES,
    POSES,
    KEYFRAMES,
    SEGMENTS,
    RENDERS,
    CONSENSUS,
    MAP_TARGET,
    TELEMETRY,
    CONTROL_REQUESTS,
    CONTROL_REPLIES,
];
