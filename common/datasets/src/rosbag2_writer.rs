//! Writes any source as a ROS 2 bag directory (`opengs synth --format rosbag2`): one MCAP
//! file with zstd chunks and the `metadata.yaml` rosbag2 keeps beside it, so `ros2 bag info`,
//! the Python `rosbags` reader and [`crate::Rosbag2Source`] open it.
//!
//! Per frame, stamped with the frame's time (header stamp = log time = publish time):
//! `sensor_msgs/msg/Image` rgb8 on [`RGB_TOPIC`]; `sensor_msgs/msg/Image` 16UC1 depth in
//! millimetres (the frame's depth rescaled, rounded) on [`DEPTH_TOPIC`], registered to the
//! colour camera; `sensor_msgs/msg/CameraInfo` (plumb_bob, no distortion, K and P from the
//! intrinsics) on [`CAMERA_INFO_TOPIC`]; the ground truth as `geometry_msgs/msg/PoseStamped`
//! (camera-to-world) on [`POSE_TOPIC`] when the frame has one. MCAP profile `ros2`, schemas
//! `ros2msg`, messages `cdr`; the MCAP also carries rosbag2's `rosbag2` metadata record.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use mcap::records::{MessageHeader, Metadata};
use opengs_geometry::{Intrinsics, Pose};

use crate::bag_metadata::{bagfile_information, metadata_yaml, TopicRecord, SENSOR_QOS};
use crate::cdr::{self, Bytes};
use crate::ros_msgs::{
    definition, CameraInfo, Header, Image, Point, PoseMsg, PoseStamped, Quaternion,
    RegionOfInterest, Time, CAMERA_INFO, IMAGE, POSE_STAMPED,
};
use crate::writer::rescale_depth;
use crate::{DatasetError, RgbdFrame, RgbdSource};

pub const RGB_TOPIC: &str = "/camera/color/image_raw";
pub const DEPTH_TOPIC: &str = "/camera/depth/image_rect_raw";
pub const CAMERA_INFO_TOPIC: &str = "/camera/color/camera_info";
pub const POSE_TOPIC: &str = "/groundtruth/pose";
const CAMERA_FRAME: &str = "camera_color_optical_frame";
const WORLD_FRAME: &str = "world";
/// Frames between progress reports.
const REPORT_EVERY: usize = 8;

/// The bag's storage file name: rosbag2's `<bag name>_0.mcap`.
fn mcap_name(out: &Path) -> String {
    let bag = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .filter(|n| !n.is_empty() && n != "." && n != "..")
        .unwrap_or_else(|| "bag".to_string());
    format!("{bag}_0.mcap")
}

struct Channel {
    id: u16,
    topic: &'static str,
    type_name: &'static str,
    count: u64,
}

/// The open MCAP file and its channels.
struct BagWriter {
    path: std::path::PathBuf,
    mcap: mcap::Writer<BufWriter<File>>,
    channels: Vec<Channel>,
    first_ns: Option<u64>,
    last_ns: u64,
}

impl BagWriter {
    fn create(path: &Path, chunks: ChunkCompression) -> Result<Self, DatasetError> {
        let file = File::create(path).map_err(|e| DatasetError::io(path, e))?;
        let mcap = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("opengs ", env!("CARGO_PKG_VERSION")))
            .compression(match chunks {
                ChunkCompression::Zstd => Some(mcap::Compression::Zstd),
                ChunkCompression::None => None,
            })
            .create(BufWriter::new(file))
            .map_err(|e| DatasetError::invalid(path, format!("cannot start the MCAP file: {e}")))?;
        let mut w = Self {
            path: path.to_path_buf(),
            mcap,
            channels: Vec::new(),
            first_ns: None,
            last_ns: 0,
        };
        for (topic, type_name) in [
            (RGB_TOPIC, IMAGE),
            (DEPTH_TOPIC, IMAGE),
            (CAMERA_INFO_TOPIC, CAMERA_INFO),
            (POSE_TOPIC, POSE_STAMPED),
        ] {
            w.add_channel(topic, type_name)?;
        }
        Ok(w)
    }

    fn err(&self, what: impl std::fmt::Display) -> DatasetError {
        DatasetError::invalid(&self.path, what.to_string())
    }

    fn add_channel(
        &mut self,
        topic: &'static str,
        type_name: &'static str,
    ) -> Result<(), DatasetError> {
        let text = definition(type_name)
            .ok_or_else(|| self.err(format!("no definition of {type_name}")))?;
        let schema = self
            .mcap
            .add_schema(type_name, "ros2msg", text.as_bytes())
            .map_err(|e| self.err(e))?;
        let mut metadata = BTreeMap::new();
        metadata.insert("offered_qos_profiles".to_string(), SENSOR_QOS.to_string());
        let id = self
            .mcap
            .add_channel(schema, topic, "cdr", &metadata)
            .map_err(|e| self.err(e))?;
        self.channels.push(Channel {
            id,
            topic,
            type_name,
            count: 0,
        });
        Ok(())
    }

    /// Writes one serialized message on the channel of `topic`.
    fn write<T: serde::Serialize>(
        &mut self,
        topic: &str,
        stamp_ns: u64,
        message: &T,
    ) -> Result<(), DatasetError> {
        let data = cdr::encode(message).map_err(|e| self.err(format!("{topic}: {e}")))?;
        let Some(channel) = self.channels.iter_mut().find(|c| c.topic == topic) else {
            return Err(self.err(format!("no channel for {topic}")));
        };
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: channel.count as u32,
            log_time: stamp_ns,
            publish_time: stamp_ns,
        };
        channel.count += 1;
        self.first_ns = Some(self.first_ns.map_or(stamp_ns, |f| f.min(stamp_ns)));
        self.last_ns = self.last_ns.max(stamp_ns);
        let result = self.mcap.write_to_known_channel(&header, &data);
        result.map_err(|e| self.err(format!("{topic}: {e}")))
    }

    fn write_frame(&mut self, f: &RgbdFrame, k: &Intrinsics) -> Result<(), DatasetError> {
        let ns = (f.timestamp * 1e9).round();
        let stamp = (ns.is_finite() && ns >= 0.0)
            .then_some(ns as i64)
            .and_then(Time::from_nanos)
            .ok_or_else(|| {
                self.err(format!(
                    "frame {} has time {} s, which a ROS stamp cannot hold",
                    f.index, f.timestamp
                ))
            })?;
        let stamp_ns = ns as u64;
        let header = Header {
            stamp,
            frame_id: CAMERA_FRAME.to_string(),
        };
        let (w, h) = (f.width, f.height);
        self.write(
            RGB_TOPIC,
            stamp_ns,
            &Image {
                header: header.clone(),
                height: h,
                width: w,
                encoding: "rgb8".into(),
                is_bigendian: 0,
                step: 3 * w,
                data: Bytes(&f.rgb),
            },
        )?;
        let mm = rescale_depth(&f.depth, f.depth_scale, 1000.0);
        let depth_bytes: Vec<u8> = mm.iter().flat_map(|d| d.to_le_bytes()).collect();
        self.write(
            DEPTH_TOPIC,
            stamp_ns,
            &Image {
                header: header.clone(),
                height: h,
                width: w,
                encoding: "16UC1".into(),
                is_bigendian: 0,
                step: 2 * w,
                data: Bytes(&depth_bytes),
            },
        )?;
        self.write(CAMERA_INFO_TOPIC, stamp_ns, &camera_info(header, k))?;
        if let Some(pose) = &f.gt_pose {
            self.write(
                POSE_TOPIC,
                stamp_ns,
                &PoseStamped {
                    header: Header {
                        stamp,
                        frame_id: WORLD_FRAME.to_string(),
                    },
                    pose: pose_msg(pose),
                },
            )?;
        }
        Ok(())
    }

    /// Closes the MCAP file (with rosbag2's metadata record) and writes `metadata.yaml`.
    fn finish(mut self, out: &Path, file_name: &str) -> Result<(), DatasetError> {
        let topics: Vec<TopicRecord> = self
            .channels
            .iter()
            .map(|c| TopicRecord {
                name: c.topic,
                type_name: c.type_name,
                message_count: c.count,
            })
            .collect();
        let start = self.first_ns.unwrap_or(0);
        let information = bagfile_information(file_name, &topics, start, self.last_ns - start);
        let mut record = BTreeMap::new();
        record.insert("serialized_metadata".to_string(), information.clone());
        record.insert("ROS_DISTRO".to_string(), "humble".to_string());
        self.mcap
            .write_metadata(&Metadata {
                name: "rosbag2".to_string(),
                metadata: record,
            })
            .map_err(|e| self.err(e))?;
        self.mcap.finish().map_err(|e| self.err(e))?;
        let yaml = out.join("metadata.yaml");
        std::fs::write(&yaml, metadata_yaml(&information)).map_err(|e| DatasetError::io(&yaml, e))
    }
}

/// A pinhole CameraInfo of the intrinsics: no distortion, identity rectification.
fn camera_info(header: Header, k: &Intrinsics) -> CameraInfo {
    CameraInfo {
        header,
        height: k.height,
        width: k.width,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: [k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0],
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [
            k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
        ],
        binning_x: 0,
        binning_y: 0,
        roi: RegionOfInterest::default(),
    }
}

fn pose_msg(p: &Pose) -> PoseMsg {
    let t = p.translation.vector;
    let q = p.rotation.coords; // i, j, k, w
    PoseMsg {
        position: Point {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        orientation: Quaternion {
            x: q[0],
            y: q[1],
            z: q[2],
            w: q[3],
        },
    }
}

/// How the MCAP file's chunks are compressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChunkCompression {
    /// What `opengs synth --format rosbag2` writes.
    Zstd,
    None,
}

/// Writes all frames of `source` as a bag directory `out` (`<out name>_0.mcap` and
/// `metadata.yaml`); `progress(done, total)` is called every few frames.
pub fn write_rosbag2(
    source: &mut dyn RgbdSource,
    out: &Path,
    chunks: ChunkCompression,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), DatasetError> {
    std::fs::create_dir_all(out).map_err(|e| DatasetError::io(out, e))?;
    let file_name = mcap_name(out);
    let mut bag = BagWriter::create(&out.join(&file_name), chunks)?;
    let k = source.intrinsics();
    let total = source.len();
    for i in 0..total {
        let f = source.frame(i)?;
        if let Err(e) = f.check_buffers(&k) {
            return Err(bag.err(format!("frame {i}: {e}")));
        }
        bag.write_frame(&f, &k)?;
        if (i + 1) % REPORT_EVERY == 0 || i + 1 == total {
            progress(i + 1, total);
        }
    }
    bag.finish(out, &file_name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn storage_file_is_named_after_the_bag() {
        assert_eq!(mcap_name(Path::new("/tmp/run_7")), "run_7_0.mcap");
        assert_eq!(mcap_name(Path::new("/")), "bag_0.mcap");
    }
}
