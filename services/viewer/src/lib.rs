//! The optional Rerun viewer stage (`opengs run --rerun FILE.rrd` / `--rerun-connect ADDR`):
//! a sink process that subscribes to every pipeline service and logs camera poses and
//! frustums, RGB and depth, keyframes with the segmenter's, the mapper's and the consensus'
//! label maps (stable colours per label, class names as annotation contexts), the trackable
//! Gaussians coloured by label, and per-stage latency as time series.
//!
//! Everything but the last step is plain Rust that compiles and is tested without the Rerun
//! SDK: the entity paths ([`paths`]), the records of plain arrays ([`record`]), messages to
//! records ([`convert`]), label colours and names ([`labels`]), labels for the map
//! ([`map_labels`]), the non-blocking hand-over to a logging thread ([`outbox`]) and the IPC
//! loop ([`stage`]). The cargo feature `rerun` adds [`rerun_sink`] and the `opengs-viewer`
//! binary; without it (the default and edge builds, CI) Rerun is not compiled at all.

pub mod convert;
pub mod labels;
pub mod map_labels;
pub mod outbox;
pub mod paths;
pub mod record;
#[cfg(feature = "rerun")]
pub mod rerun_sink;
pub mod stage;
