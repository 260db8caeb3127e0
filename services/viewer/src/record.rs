//! What the viewer logs, as plain data: one [`Record`] is an entity path, the time it belongs
//! to, and an [`Item`] of plain arrays (no Rerun types), so everything up to the last step
//! compiles and is tested without the Rerun SDK; the `rerun` feature's sink turns each item
//! into its Rerun archetype.

/// Seconds since 1970 from which a capture time is taken for wall-clock time (1 Jan 2000):
/// TUM stamps are Unix times, the synthetic room and Replica count from 0.
const EPOCH_CUTOFF_NS: u64 = 946_684_800 * 1_000_000_000;

/// A capture time on the `sensor_time` timeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorTime {
    /// Nanoseconds since the Unix epoch (recorded data: TUM).
    SinceEpoch(i64),
    /// Nanoseconds since the start of the data (synthetic, Replica).
    SinceStart(i64),
}

impl SensorTime {
    /// The timeline value of a stamp's `capture_ns`.
    pub fn from_capture_ns(ns: u64) -> Self {
        let clamped = i64::try_from(ns).unwrap_or(i64::MAX);
        if ns >= EPOCH_CUTOFF_NS {
            Self::SinceEpoch(clamped)
        } else {
            Self::SinceStart(clamped)
        }
    }
}

/// The frame a record belongs to: its `frame` sequence number and its `sensor_time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameTime {
    pub seq: i64,
    pub sensor: SensorTime,
}

impl FrameTime {
    /// The time of the source frame a message stamp names.
    pub fn of(stamp: &opengs_ipc_schema::Stamp) -> Self {
        Self {
            seq: i64::try_from(stamp.seq).unwrap_or(i64::MAX),
            sensor: SensorTime::from_capture_ns(stamp.capture_ns),
        }
    }
}

/// When a record holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Time {
    /// For the whole recording (coordinate conventions).
    Static,
    /// At a source frame.
    Frame(FrameTime),
    /// Only on the logging clock (events with no frame: the mapper's final work).
    LogTime,
}

/// Severity of a text record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    Info,
    Warn,
}

/// One class of an annotation context: id, display name, colour.
#[derive(Debug, Clone, PartialEq)]
pub struct ClassEntry {
    pub id: u16,
    pub label: String,
    /// Straight RGBA.
    pub rgba: [u8; 4],
}

/// What is logged, in plain arrays.
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    /// The world's axes: right-handed, y down, z forward (the first camera's frame).
    WorldAxesRightHandYDown,
    /// Camera-to-parent transform.
    Transform {
        translation: [f32; 3],
        /// Unit quaternion x, y, z, w.
        rotation_xyzw: [f32; 4],
    },
    /// Pinhole camera (OpenCV convention: x right, y down, z forward), drawn as a frustum.
    Pinhole {
        focal: [f32; 2],
        principal: [f32; 2],
        resolution: [f32; 2],
        /// Length of the drawn frustum, metres.
        image_plane_distance: f32,
    },
    /// 8-bit RGB, row-major, 3 bytes a pixel.
    Rgb {
        width: u32,
        height: u32,
        rgb: Vec<u8>,
    },
    /// 16-bit depth, row-major; `units_per_metre` of them make a metre, 0 is missing.
    Depth {
        width: u32,
        height: u32,
        depth: Vec<u16>,
        units_per_metre: f32,
    },
    /// Class ids per pixel (0: none), coloured and named by the annotation context in force.
    Segmentation {
        width: u32,
        height: u32,
        class_ids: Vec<u16>,
    },
    /// Class names and colours for the class ids at this path and below.
    Annotations(Vec<ClassEntry>),
    /// Points with a radius, a colour and a class each.
    Points {
        positions: Vec<[f32; 3]>,
        radii: Vec<f32>,
        colors: Vec<[u8; 3]>,
        class_ids: Vec<u16>,
    },
    /// One polyline.
    LineStrip {
        points: Vec<[f32; 3]>,
        color: [u8; 3],
    },
    /// One sample of a time series.
    Scalar(f64),
    Text {
        level: Level,
        text: String,
    },
    /// Nothing here from now on (a new keyframe's label maps have not arrived yet).
    Clear,
}

impl Item {
    /// Big items (images, point clouds) are dropped when the logging side falls behind;
    /// small ones (poses, scalars, text) wait for it.
    pub fn droppable(&self) -> bool {
        matches!(
            self,
            Self::Rgb { .. }
                | Self::Depth { .. }
                | Self::Segmentation { .. }
                | Self::Points { .. }
                | Self::LineStrip { .. }
        )
    }
}

/// One thing to log at one entity path at one time.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    pub path: String,
    pub time: Time,
    pub item: Item,
}

impl Record {
    pub fn new(path: impl Into<String>, time: Time, item: Item) -> Self {
        Self {
            path: path.into(),
            time,
            item,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recorded_stamps_are_wall_clock_and_generated_ones_relative() {
        // fr1/xyz's first frame: 1305031102.175304 s.
        let tum = 1_305_031_102_175_304_000;
        assert_eq!(
            SensorTime::from_capture_ns(tum),
            SensorTime::SinceEpoch(tum as i64)
        );
        assert_eq!(
            SensorTime::from_capture_ns(33_333_333),
            SensorTime::SinceStart(33_333_333)
        );
        assert_eq!(SensorTime::from_capture_ns(0), SensorTime::SinceStart(0));
        assert_eq!(
            SensorTime::from_capture_ns(u64::MAX),
            SensorTime::SinceEpoch(i64::MAX)
        );
    }

    #[test]
    fn only_bulk_items_are_droppable() {
        assert!(Item::Rgb {
            width: 1,
            height: 1,
            rgb: vec![0; 3]
        }
        .droppable());
        assert!(!Item::Scalar(1.0).droppable());
        assert!(!Item::Transform {
            translation: [0.0; 3],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0]
        }
        .droppable());
        assert!(!Item::Annotations(Vec::new()).droppable());
    }
}
