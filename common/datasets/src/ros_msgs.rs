//! The ROS 2 message types a camera bag carries, as serde structs in field order (CDR is
//! positional), and their `ros2msg` definitions (what a bag's MCAP schema records hold).
//!
//! Read: `sensor_msgs/msg/Image`, `sensor_msgs/msg/CompressedImage`,
//! `sensor_msgs/msg/CameraInfo`, `geometry_msgs/msg/PoseStamped`, `nav_msgs/msg/Odometry`
//! (its header, child frame and pose; the covariances and twist after them are not read).
//! Written: Image, CameraInfo, PoseStamped.

use serde::{Deserialize, Serialize};

use crate::cdr::Bytes;

pub(crate) const IMAGE: &str = "sensor_msgs/msg/Image";
pub(crate) const COMPRESSED_IMAGE: &str = "sensor_msgs/msg/CompressedImage";
pub(crate) const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
pub(crate) const POSE_STAMPED: &str = "geometry_msgs/msg/PoseStamped";
pub(crate) const ODOMETRY: &str = "nav_msgs/msg/Odometry";

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub(crate) struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// Nanoseconds since the epoch; `None` for a nanosecond field of a second or more.
    pub fn nanos(&self) -> Option<i64> {
        (self.nanosec < 1_000_000_000)
            .then(|| self.sec as i64 * 1_000_000_000 + self.nanosec as i64)
    }

    /// The time of `ns` nanoseconds; `None` outside the i32 seconds a stamp can hold.
    pub fn from_nanos(ns: i64) -> Option<Self> {
        Some(Self {
            sec: i32::try_from(ns.div_euclid(1_000_000_000)).ok()?,
            nanosec: ns.rem_euclid(1_000_000_000) as u32,
        })
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `sensor_msgs/msg/Image`: `height` rows of `step` bytes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Image<'a> {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub encoding: String,
    pub is_bigendian: u8,
    pub step: u32,
    #[serde(borrow)]
    pub data: Bytes<'a>,
}

/// `sensor_msgs/msg/CompressedImage`: `format` names the codec (`jpeg`, `png`, ...).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct CompressedImage<'a> {
    pub header: Header,
    pub format: String,
    #[serde(borrow)]
    pub data: Bytes<'a>,
}

/// `sensor_msgs/RegionOfInterest`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct RegionOfInterest {
    pub x_offset: u32,
    pub y_offset: u32,
    pub height: u32,
    pub width: u32,
    pub do_rectify: bool,
}

/// `sensor_msgs/msg/CameraInfo`: `k` is the row-major 3x3 camera matrix
/// `[fx 0 cx; 0 fy cy; 0 0 1]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct CameraInfo {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    pub k: [f64; 9],
    pub r: [f64; 9],
    pub p: [f64; 12],
    pub binning_x: u32,
    pub binning_y: u32,
    pub roi: RegionOfInterest,
}

/// `geometry_msgs/Point`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

/// `geometry_msgs/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct PoseMsg {
    pub position: Point,
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct PoseStamped {
    pub header: Header,
    pub pose: PoseMsg,
}

/// `nav_msgs/msg/Odometry` up to its pose (`pose.pose`); the covariance and twist that
/// follow are not read.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub(crate) struct OdometryPose {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseMsg,
}

const SEPARATOR: &str =
    "================================================================================\n";

const HEADER_DEFS: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const TIME_DEFS: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";

/// The `ros2msg` schema text of a type we write: its fields, then each type it uses after a
/// separator line, as rosbag2 records them.
pub(crate) fn definition(type_name: &str) -> Option<String> {
    let (fields, uses): (&str, Vec<&str>) = match type_name {
        IMAGE => (
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n\
             uint8 is_bigendian\nuint32 step\nuint8[] data\n",
            vec![HEADER_DEFS, TIME_DEFS],
        ),
        CAMERA_INFO => (
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n\
             float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n\
             uint32 binning_y\nsensor_msgs/RegionOfInterest roi\n",
            vec![
                HEADER_DEFS,
                TIME_DEFS,
                "MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\n\
                 uint32 height\nuint32 width\nbool do_rectify\n",
            ],
        ),
        POSE_STAMPED => (
            "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
            vec![
                HEADER_DEFS,
                TIME_DEFS,
                "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\n\
                 geometry_msgs/Quaternion orientation\n",
                "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n",
                "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
            ],
        ),
        _ => return None,
    };
    let mut text = fields.to_string();
    for u in uses {
        text.push_str(SEPARATOR);
        text.push_str(u);
    }
    Some(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_convert_both_ways() {
        for ns in [
            0i64,
            1,
            999_999_999,
            1_700_000_000_123_456_789,
            -1,
            -1_500_000_000,
        ] {
            let t = Time::from_nanos(ns).expect("in range");
            assert!(t.nanosec < 1_000_000_000);
            assert_eq!(t.nanos(), Some(ns));
        }
        assert_eq!(
            Time {
                sec: 1,
                nanosec: 1_000_000_000
            }
            .nanos(),
            None
        );
        assert_eq!(Time::from_nanos(i64::MAX), None);
    }

    #[test]
    fn definitions_name_every_used_type() {
        let image = definition(IMAGE).expect("image");
        assert!(image.starts_with("std_msgs/Header header\n"));
        assert!(image.contains("MSG: builtin_interfaces/Time\n"));
        let info = definition(CAMERA_INFO).expect("camera info");
        assert!(info.contains("MSG: sensor_msgs/RegionOfInterest\n"));
        assert_eq!(
            definition(POSE_STAMPED).map(|d| d.matches(SEPARATOR).count()),
            Some(5)
        );
        assert_eq!(definition("std_msgs/msg/String"), None);
    }
}
