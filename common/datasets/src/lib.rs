//! RGB-D datasets: TUM, Replica, ROS 2 bags (MCAP), and the embedded synthetic room.
//!
//! Every dataset is an [`RgbdSource`] producing plain owned [`RgbdFrame`]s;
//! [`open_dataset`] picks the reader from a [`DatasetSpec`].

mod bag_metadata;
mod cdr;
mod classes;
mod error;
mod frame;
mod image_io;
mod limit;
mod mcap_file;
pub mod replica;
mod ros_image;
mod ros_msgs;
pub mod rosbag2;
pub mod rosbag2_writer;
mod spec;
pub mod synthetic;
mod text;
pub mod trajectory;
pub mod tum;
mod writer;

pub use error::DatasetError;
pub use frame::{InstanceClass, RgbdFrame, RgbdSource};
pub use limit::FrameLimit;
pub use replica::{ReplicaOptions, ReplicaSource};
pub use rosbag2::{Rosbag2Options, Rosbag2Source};
pub use rosbag2_writer::{write_rosbag2, ChunkCompression};
pub use spec::{DatasetKind, DatasetSpec};
pub use synthetic::noise::DepthNoise;
pub use synthetic::{SyntheticOptions, SyntheticSource};
pub use tum::{TumOptions, TumSource};
pub use writer::{write_dataset, DatasetFormat};

/// Opens the dataset a spec names, capped at `spec.max_frames`.
pub fn open_dataset(spec: &DatasetSpec) -> Result<Box<dyn RgbdSource>, DatasetError> {
    let source: Box<dyn RgbdSource> = match &spec.kind {
        DatasetKind::Synthetic => Box::new(SyntheticSource::new(spec.synthetic.clone())?),
        DatasetKind::Tum(dir) => Box::new(TumSource::open(dir, spec.tum.clone())?),
        DatasetKind::Replica(dir) => Box::new(ReplicaSource::open(dir, spec.replica.clone())?),
        DatasetKind::Rosbag2(path) => Box::new(Rosbag2Source::open(path, spec.rosbag2.clone())?),
    };
    Ok(match spec.max_frames {
        Some(n) => Box::new(FrameLimit::new(source, n)),
        None => source,
    })
}
