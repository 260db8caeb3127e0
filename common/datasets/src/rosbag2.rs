//! ROS 2 bags (`rosbag2:PATH`): RGB-D frames from the colour, depth, camera-info and
//! (optional) ground-truth topics of an MCAP bag.
//!
//! PATH is a bag directory (`metadata.yaml` and its `.mcap` files) or one `.mcap` file.
//! Read, without a ROS install: `sensor_msgs/msg/Image` (colour rgb8, bgr8, rgba8, bgra8,
//! mono8; depth 16UC1 in mm or 32FC1 in m), `sensor_msgs/msg/CompressedImage` (jpeg, png)
//! for colour, `sensor_msgs/msg/CameraInfo` (K = [fx 0 cx; 0 fy cy; 0 0 1]; binning and ROI
//! are taken as off), and `geometry_msgs/msg/PoseStamped` or `nav_msgs/msg/Odometry`
//! (`pose.pose`) as camera-to-world ground truth. Messages are CDR ([`crate::cdr`]).
//!
//! Steps of [`Rosbag2Source::open`]:
//! 1. locate the storage files (`metadata.yaml`'s `relative_file_paths`, else the
//!    directory's `*.mcap`); an SQLite3 bag is refused with how to convert it;
//! 2. one pass over the files ([`crate::mcap_file`]) decodes every message of the image,
//!    camera-info and pose topics, keeping only its header stamp, where it lies, and for
//!    images encoding and size (no pixels): the index;
//! 3. topics: each flag (`--rgb-topic` ...) or else the bag's only topic of the right type
//!    (colour: an Image with a colour encoding or a CompressedImage; depth: an Image with a
//!    depth encoding; camera info: the one beside the colour topic; pose: the only
//!    PoseStamped/Odometry topic, or none); an ambiguous or missing one is an error listing
//!    the bag's image topics;
//! 4. checks: every message of the chosen topics parses, has a known encoding and
//!    `height × step` bytes, and has the camera's size (the first CameraInfo);
//! 5. association by header stamp: each colour image takes the nearest depth image within
//!    `max_time_diff` (none: the image is dropped) and the nearest pose within it.
//!
//! [`RgbdSource::frame`] then reads the two images of a frame ([`crate::ros_image`]): colour
//! as RGB8, depth as u16 at 1000 units/m from 16UC1 (copied) or 5000 units/m from 32FC1
//! (NaN, inf, ≤ 0 or beyond 13.1 m: no depth). Errors name the file, topic and message
//! index (0-based, in recording order within the topic).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use opengs_geometry::{Intrinsics, Pose};

use crate::bag_metadata::{BagMetadata, CONVERT_HINT};
use crate::cdr;
use crate::mcap_file::{ChannelInfo, McapFile, MessageLocation};
use crate::ros_image::{
    check_layout, compressed_codec, compressed_size, decode_colour, decode_compressed_colour,
    decode_depth, PixelFormat,
};
use crate::ros_msgs::{
    CameraInfo, CompressedImage, Image, OdometryPose, PoseMsg, PoseStamped, Time, CAMERA_INFO,
    COMPRESSED_IMAGE, IMAGE, ODOMETRY, POSE_STAMPED,
};
use crate::text::nearest_within;
use crate::{DatasetError, InstanceClass, RgbdFrame, RgbdSource};

/// Depth units per metre of frames whose depth topic is in millimetres (16UC1).
pub const MM_DEPTH_SCALE: f32 = 1000.0;
/// Depth units per metre of frames whose depth topic is in metres (32FC1): 0.2 mm steps up
/// to 13.1 m.
pub const METRIC_DEPTH_SCALE: f32 = 5000.0;

/// `--pose-topic none`: no ground truth even when the bag has a pose topic.
pub const NO_POSE_TOPIC: &str = "none";

#[derive(Debug, Clone, PartialEq)]
pub struct Rosbag2Options {
    /// Colour topic (Image or CompressedImage); `None`: the bag's only colour topic.
    pub rgb_topic: Option<String>,
    /// Depth topic (Image 16UC1 / 32FC1); `None`: the bag's only depth topic.
    pub depth_topic: Option<String>,
    /// CameraInfo topic; `None`: the only one, or the one beside the colour topic.
    pub camera_info_topic: Option<String>,
    /// Ground truth (PoseStamped or Odometry); `None`: the only such topic, if any;
    /// [`NO_POSE_TOPIC`]: none.
    pub pose_topic: Option<String>,
    /// Largest colour↔depth (and colour↔pose) header-stamp gap to associate, seconds.
    pub max_time_diff: f64,
    /// Overrides the CameraInfo topic.
    pub intrinsics: Option<Intrinsics>,
}

impl Default for Rosbag2Options {
    fn default() -> Self {
        Self {
            rgb_topic: None,
            depth_topic: None,
            camera_info_topic: None,
            pose_topic: None,
            max_time_diff: 0.02,
            intrinsics: None,
        }
    }
}

/// What a message of an indexed topic holds, beyond its stamp.
#[derive(Debug, Clone, Copy)]
enum Content {
    Image {
        format: PixelFormat,
        width: u32,
        height: u32,
    },
    Compressed {
        width: u32,
        height: u32,
    },
    Camera(Intrinsics),
    Pose(Pose),
}

/// One indexed message.
#[derive(Debug, Clone, Copy)]
struct Indexed {
    file: usize,
    location: MessageLocation,
    stamp_ns: i64,
    content: Content,
}

/// A message that does not parse or cannot be used: where and why.
#[derive(Debug, Clone)]
struct Problem {
    file: usize,
    index: usize,
    message: String,
}

/// Everything the index pass learnt about one topic.
#[derive(Debug, Clone)]
struct TopicIndex {
    topic: String,
    type_name: String,
    /// Messages in recording order; `messages[i]` is not message `i` when some had problems.
    messages: Vec<(usize, Indexed)>,
    count: usize,
    first_problem: Option<Problem>,
}

impl TopicIndex {
    /// The role an image topic can play, from its first usable message.
    fn first_content(&self) -> Option<Content> {
        self.messages.first().map(|(_, m)| m.content)
    }

    fn is_colour(&self) -> bool {
        match self.first_content() {
            Some(Content::Image { format, .. }) => !format.is_depth(),
            Some(Content::Compressed { .. }) => true,
            _ => self.type_name == COMPRESSED_IMAGE,
        }
    }

    fn is_true_colour(&self) -> bool {
        self.is_colour()
            && !matches!(
                self.first_content(),
                Some(Content::Image {
                    format: PixelFormat::Mono8,
                    ..
                })
            )
    }

    fn is_depth(&self) -> bool {
        matches!(self.first_content(), Some(Content::Image { format, .. }) if format.is_depth())
    }

    /// `type (encoding)` for listings.
    fn describe(&self) -> String {
        let encoding = match self.first_content() {
            Some(Content::Image { format, .. }) => format!(" {}", encoding_name(format)),
            Some(Content::Compressed { .. }) => " compressed".to_string(),
            _ => match &self.first_problem {
                Some(p) => format!(" (unreadable: message {}: {})", p.index, p.message),
                None => String::new(),
            },
        };
        format!("{}{encoding}", self.type_name)
    }
}

fn encoding_name(format: PixelFormat) -> &'static str {
    match format {
        PixelFormat::Rgb8 => "rgb8",
        PixelFormat::Bgr8 => "bgr8",
        PixelFormat::Rgba8 => "rgba8",
        PixelFormat::Bgra8 => "bgra8",
        PixelFormat::Mono8 => "mono8",
        PixelFormat::DepthMm16 => "16UC1",
        PixelFormat::DepthM32 => "32FC1",
    }
}

fn is_indexed_type(type_name: &str) -> bool {
    matches!(
        type_name,
        IMAGE | COMPRESSED_IMAGE | CAMERA_INFO | POSE_STAMPED | ODOMETRY
    )
}

/// A reference to one message of a chosen topic.
#[derive(Debug, Clone, Copy)]
struct MessageRef {
    file: usize,
    location: MessageLocation,
    index: usize,
}

#[derive(Debug, Clone)]
struct FrameEntry {
    timestamp: f64,
    rgb: MessageRef,
    depth: MessageRef,
    gt_pose: Option<Pose>,
}

pub struct Rosbag2Source {
    bag: PathBuf,
    files: Vec<McapFile>,
    /// Every message zstd-compressed on its own (`compression_mode: message`).
    message_compression: bool,
    rgb_topic: String,
    rgb_compressed: bool,
    depth_topic: String,
    intrinsics: Intrinsics,
    depth_scale: f32,
    frame_rate: f64,
    frames: Vec<FrameEntry>,
}

/// The storage files of a bag and how its messages are compressed.
struct BagLayout {
    files: Vec<PathBuf>,
    message_compression: bool,
}

fn sqlite_error(path: &Path) -> DatasetError {
    DatasetError::invalid(
        path,
        format!("an SQLite3 (.db3) bag: only MCAP bags are read; {CONVERT_HINT}"),
    )
}

fn is_db3(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("db3"))
}

/// Sort key of `name_12.mcap`: the text, then the trailing number, so `_10` follows `_9`.
fn split_number_key(path: &Path) -> (String, u64) {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let digits = stem.len() - stem.trim_end_matches(|c: char| c.is_ascii_digit()).len();
    let (text, number) = stem.split_at(stem.len() - digits);
    (text.to_string(), number.parse().unwrap_or(0))
}

/// Step 1: the storage files of the bag at `path`.
fn locate(path: &Path) -> Result<BagLayout, DatasetError> {
    if !path.exists() {
        return Err(DatasetError::Missing {
            path: path.to_path_buf(),
        });
    }
    let dir = if path.is_file() {
        if path.file_name().is_some_and(|n| n == "metadata.yaml") {
            path.parent().unwrap_or(Path::new(".")).to_path_buf()
        } else if is_db3(path) {
            return Err(sqlite_error(path));
        } else {
            return Ok(BagLayout {
                files: vec![path.to_path_buf()],
                message_compression: false,
            });
        }
    } else {
        path.to_path_buf()
    };
    let metadata_file = dir.join("metadata.yaml");
    let metadata = match metadata_file.is_file() {
        true => Some(BagMetadata::read(&metadata_file)?),
        false => None,
    };
    let mut message_compression = false;
    if let Some(m) = &metadata {
        if m.storage_identifier
            .as_deref()
            .is_some_and(|s| s.eq_ignore_ascii_case("sqlite3"))
        {
            return Err(sqlite_error(&metadata_file));
        }
        match m.compression_mode.to_ascii_lowercase().as_str() {
            "" | "none" => {}
            "message" if m.compression_format.eq_ignore_ascii_case("zstd") => {
                message_compression = true
            }
            mode => {
                return Err(DatasetError::invalid(
                    &metadata_file,
                    format!(
                        "compression_mode '{mode}' with format '{}' is not read (only \
                         uncompressed bags, MCAP chunk compression, or zstd per message): \
                         decompress it, e.g. `rosbags-convert --src BAG --dst NEW \
                         --dst-storage mcap`",
                        m.compression_format
                    ),
                ))
            }
        }
    }
    let files: Vec<PathBuf> = match metadata.filter(|m| !m.relative_file_paths.is_empty()) {
        Some(m) => {
            let files: Vec<PathBuf> = m
                .relative_file_paths
                .iter()
                .map(|f| {
                    // rosbag2 once stored paths with the bag's directory; the name is enough.
                    let name = Path::new(f).file_name().unwrap_or(f.as_ref());
                    dir.join(name)
                })
                .collect();
            if let Some(db) = files.iter().find(|f| is_db3(f)) {
                return Err(sqlite_error(db));
            }
            if let Some(missing) = files.iter().find(|f| !f.is_file()) {
                return Err(DatasetError::invalid(
                    missing,
                    "not found (listed in metadata.yaml's relative_file_paths)",
                ));
            }
            files
        }
        None => {
            let entries = std::fs::read_dir(&dir).map_err(|e| DatasetError::io(&dir, e))?;
            let all: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
            let mut mcaps: Vec<PathBuf> = all
                .iter()
                .filter(|p| {
                    p.extension()
                        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
                })
                .cloned()
                .collect();
            if mcaps.is_empty() {
                if let Some(db) = all.iter().find(|p| is_db3(p)) {
                    return Err(sqlite_error(db));
                }
                return Err(DatasetError::invalid(
                    &dir,
                    "not a ROS 2 bag: no .mcap file and no metadata.yaml listing one",
                ));
            }
            mcaps.sort_by_key(|p| split_number_key(p));
            mcaps
        }
    };
    Ok(BagLayout {
        files,
        message_compression,
    })
}

/// A message's serialized bytes as CDR: unchanged, or zstd-decompressed per message.
fn cdr_bytes(data: &[u8], message_compression: bool) -> Result<std::borrow::Cow<'_, [u8]>, String> {
    if !message_compression {
        return Ok(std::borrow::Cow::Borrowed(data));
    }
    zstd::stream::decode_all(data)
        .map(std::borrow::Cow::Owned)
        .map_err(|e| format!("the zstd-compressed message does not decompress: {e}"))
}

fn stamp_of(t: Time) -> Result<i64, String> {
    t.nanos()
        .ok_or_else(|| format!("header stamp nanosec {} is not below 1e9", t.nanosec))
}

/// A ROS pose as camera-to-world; refused when not finite or not a rotation.
fn pose_of(p: &PoseMsg) -> Result<Pose, String> {
    let (t, q) = (p.position, p.orientation);
    let values = [t.x, t.y, t.z, q.x, q.y, q.z, q.w];
    if values.iter().any(|v| !v.is_finite()) {
        return Err(format!("pose {values:?} is not finite"));
    }
    let q = Quaternion::new(q.w, q.x, q.y, q.z);
    let norm = q.norm();
    if !(norm.is_finite() && norm > 1e-9) {
        return Err(format!(
            "orientation {:?} is not a rotation (norm {norm})",
            q.coords
        ));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(t.x, t.y, t.z),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// Step 2: decodes what the index keeps of one message of an indexed topic.
fn index_message(type_name: &str, data: &[u8]) -> Result<(i64, Content), String> {
    match type_name {
        IMAGE => {
            let img: Image = cdr::decode(data)?;
            let format = check_layout(&img)?;
            Ok((
                stamp_of(img.header.stamp)?,
                Content::Image {
                    format,
                    width: img.width,
                    height: img.height,
                },
            ))
        }
        COMPRESSED_IMAGE => {
            let img: CompressedImage = cdr::decode(data)?;
            compressed_codec(&img.format)?;
            let (width, height) = compressed_size(&img)?;
            Ok((
                stamp_of(img.header.stamp)?,
                Content::Compressed { width, height },
            ))
        }
        CAMERA_INFO => {
            let info: CameraInfo = cdr::decode(data)?;
            let k = Intrinsics::new(
                info.k[0],
                info.k[4],
                info.k[2],
                info.k[5],
                info.width,
                info.height,
            );
            k.validate()
                .map_err(|e| format!("camera matrix K {:?}: {e}", info.k))?;
            Ok((stamp_of(info.header.stamp)?, Content::Camera(k)))
        }
        POSE_STAMPED => {
            let p: PoseStamped = cdr::decode(data)?;
            Ok((stamp_of(p.header.stamp)?, Content::Pose(pose_of(&p.pose)?)))
        }
        ODOMETRY => {
            let p: OdometryPose = cdr::decode(data)?;
            Ok((stamp_of(p.header.stamp)?, Content::Pose(pose_of(&p.pose)?)))
        }
        other => Err(format!("type {other} is not read")),
    }
}

/// Step 2: the index of every image, camera-info and pose topic of the bag's files.
fn build_index(
    files: &mut [McapFile],
    message_compression: bool,
) -> Result<BTreeMap<String, TopicIndex>, DatasetError> {
    let mut topics: BTreeMap<String, TopicIndex> = BTreeMap::new();
    let wanted = |c: &ChannelInfo| is_indexed_type(&c.type_name);
    for (file_index, file) in files.iter_mut().enumerate() {
        let path = file.path().to_path_buf();
        file.scan(&wanted, &mut |m| {
            let t = topics
                .entry(m.channel.topic.clone())
                .or_insert_with(|| TopicIndex {
                    topic: m.channel.topic.clone(),
                    type_name: m.channel.type_name.clone(),
                    messages: Vec::new(),
                    count: 0,
                    first_problem: None,
                });
            let index = t.count;
            t.count += 1;
            let result = if t.type_name != m.channel.type_name {
                Err(format!(
                    "type {} here, {} in an earlier file",
                    m.channel.type_name, t.type_name
                ))
            } else if m.channel.message_encoding != "cdr" {
                Err(format!(
                    "message encoding '{}', expected cdr",
                    m.channel.message_encoding
                ))
            } else {
                cdr_bytes(m.data, message_compression)
                    .and_then(|bytes| index_message(&t.type_name, &bytes))
            };
            match result {
                Ok((stamp_ns, content)) => t.messages.push((
                    index,
                    Indexed {
                        file: file_index,
                        location: m.location,
                        stamp_ns,
                        content,
                    },
                )),
                Err(message) => {
                    t.first_problem.get_or_insert(Problem {
                        file: file_index,
                        index,
                        message,
                    });
                }
            }
            Ok(())
        })
        .map_err(|e| match e {
            // Name the messages read so far, so a truncated bag says how far it got.
            DatasetError::Invalid { path: p, message } if p == path => {
                let so_far: Vec<String> = topics
                    .values()
                    .filter(|t| t.type_name == IMAGE || t.type_name == COMPRESSED_IMAGE)
                    .map(|t| format!("{} after message {}", t.topic, t.count.saturating_sub(1)))
                    .collect();
                let at = if so_far.is_empty() {
                    String::new()
                } else {
                    format!(" (read so far: {})", so_far.join(", "))
                };
                DatasetError::Invalid {
                    path: p,
                    message: format!("{message}{at}"),
                }
            }
            other => other,
        })?;
    }
    Ok(topics)
}

/// The bag's image topics, one per line, for errors that ask for a topic flag.
fn listing(topics: &BTreeMap<String, TopicIndex>) -> String {
    let images: Vec<String> = topics
        .values()
        .filter(|t| matches!(t.type_name.as_str(), IMAGE | COMPRESSED_IMAGE))
        .map(|t| format!("\n  {}  {}  {} messages", t.topic, t.describe(), t.count))
        .collect();
    match images.is_empty() {
        true => " The bag has no sensor_msgs/msg/Image or CompressedImage topic.".to_string(),
        false => format!(" Image topics in the bag:{}", images.concat()),
    }
}

/// Names of topics for errors.
fn names(ts: &[&TopicIndex]) -> String {
    ts.iter()
        .map(|t| t.topic.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Step 3: the topic a flag names (checked by `fits`), or the only candidate.
fn choose<'a>(
    bag: &Path,
    topics: &'a BTreeMap<String, TopicIndex>,
    flag: &str,
    role: &str,
    given: Option<&str>,
    fits: &dyn Fn(&TopicIndex) -> bool,
    candidates: Vec<&'a TopicIndex>,
) -> Result<&'a TopicIndex, DatasetError> {
    if let Some(name) = given {
        let Some(t) = topics.get(name) else {
            return Err(DatasetError::invalid(
                bag,
                format!(
                    "{flag} {name}: the bag has no such {role} topic.{}",
                    listing(topics)
                ),
            ));
        };
        if !fits(t) {
            return Err(DatasetError::invalid(
                bag,
                format!(
                    "{flag} {name}: the topic is {}, not a {role} topic.{}",
                    t.describe(),
                    listing(topics)
                ),
            ));
        }
        return Ok(t);
    }
    match candidates.as_slice() {
        [one] => Ok(one),
        [] => Err(DatasetError::invalid(
            bag,
            format!(
                "no {role} topic found; pass {flag} TOPIC.{}",
                listing(topics)
            ),
        )),
        several => Err(DatasetError::invalid(
            bag,
            format!(
                "{} {role} topics ({}); pass {flag} TOPIC to pick one.{}",
                several.len(),
                names(several),
                listing(topics)
            ),
        )),
    }
}

/// Step 3, camera info: the one CameraInfo topic, or the one in the nearest namespace
/// above the colour topic (`/camera/color/image_raw` → `/camera/color/camera_info`).
fn camera_info_candidates<'a>(
    topics: &'a BTreeMap<String, TopicIndex>,
    rgb_topic: &str,
) -> Vec<&'a TopicIndex> {
    let infos: Vec<&TopicIndex> = topics
        .values()
        .filter(|t| t.type_name == CAMERA_INFO)
        .collect();
    if infos.len() <= 1 {
        return infos;
    }
    let mut ns = rgb_topic;
    while let Some((parent, _)) = ns.rsplit_once('/') {
        let beside = format!("{parent}/camera_info");
        if let Some(t) = infos.iter().find(|t| t.topic == beside) {
            return vec![t];
        }
        ns = parent;
    }
    infos
}

/// The first problem of a chosen topic as an error.
fn check_problems(files: &[McapFile], t: &TopicIndex) -> Result<(), DatasetError> {
    match &t.first_problem {
        Some(p) => Err(bag_error(
            files,
            p.file,
            &t.topic,
            p.index,
            p.message.clone(),
        )),
        None => Ok(()),
    }
}

fn bag_error(
    files: &[McapFile],
    file: usize,
    topic: &str,
    index: usize,
    message: String,
) -> DatasetError {
    DatasetError::BagMessage {
        path: files
            .get(file)
            .map(|f| f.path().to_path_buf())
            .unwrap_or_default(),
        topic: topic.to_string(),
        index,
        message,
    }
}

fn seconds(ns: i64) -> f64 {
    ns.div_euclid(1_000_000_000) as f64 + ns.rem_euclid(1_000_000_000) as f64 * 1e-9
}

impl Rosbag2Source {
    pub fn open(path: &Path, options: Rosbag2Options) -> Result<Self, DatasetError> {
        let layout = locate(path)?;
        let mut files = layout
            .files
            .iter()
            .map(|f| McapFile::open(f))
            .collect::<Result<Vec<_>, _>>()?;
        let topics = build_index(&mut files, layout.message_compression)?;

        // Step 3: topics.
        let colour: Vec<&TopicIndex> = topics.values().filter(|t| t.is_true_colour()).collect();
        let colour = if colour.is_empty() {
            topics.values().filter(|t| t.is_colour()).collect()
        } else {
            colour
        };
        let rgb = choose(
            path,
            &topics,
            "--rgb-topic",
            "colour image",
            options.rgb_topic.as_deref(),
            &|t| t.is_colour() || (t.first_content().is_none() && t.type_name == IMAGE),
            colour,
        )?;
        let depth = choose(
            path,
            &topics,
            "--depth-topic",
            "depth image (16UC1 or 32FC1)",
            options.depth_topic.as_deref(),
            &|t| t.is_depth() || (t.first_content().is_none() && t.type_name == IMAGE),
            topics.values().filter(|t| t.is_depth()).collect(),
        )?;
        check_problems(&files, rgb)?;
        check_problems(&files, depth)?;
        let pose_topic = match options.pose_topic.as_deref() {
            Some(NO_POSE_TOPIC) => None,
            given => {
                let poses: Vec<&TopicIndex> = topics
                    .values()
                    .filter(|t| matches!(t.type_name.as_str(), POSE_STAMPED | ODOMETRY))
                    .collect();
                if given.is_none() && poses.is_empty() {
                    None
                } else {
                    Some(choose(
                        path,
                        &topics,
                        "--pose-topic",
                        "ground-truth pose (geometry_msgs/msg/PoseStamped or \
                         nav_msgs/msg/Odometry; `--pose-topic none` for none)",
                        given,
                        &|t| matches!(t.type_name.as_str(), POSE_STAMPED | ODOMETRY),
                        poses,
                    )?)
                }
            }
        };

        // Step 4: the camera, and every image against it.
        let (intrinsics, camera_name) = match options.intrinsics {
            Some(k) => (k, "the camera given".to_string()),
            None => {
                let t = choose(
                    path,
                    &topics,
                    "--camera-info-topic",
                    "sensor_msgs/msg/CameraInfo",
                    options.camera_info_topic.as_deref(),
                    &|t| t.type_name == CAMERA_INFO,
                    camera_info_candidates(&topics, &rgb.topic),
                )?;
                check_problems(&files, t)?;
                let Some((
                    _,
                    Indexed {
                        content: Content::Camera(k),
                        ..
                    },
                )) = t.messages.first()
                else {
                    return Err(DatasetError::invalid(
                        path,
                        format!("camera info topic {} has no messages", t.topic),
                    ));
                };
                (*k, format!("CameraInfo ({} message 0)", t.topic))
            }
        };
        for t in [rgb, depth] {
            for (index, m) in &t.messages {
                let (w, h) = match m.content {
                    Content::Image { width, height, .. }
                    | Content::Compressed { width, height } => (width, height),
                    _ => continue,
                };
                if (w, h) != (intrinsics.width, intrinsics.height) {
                    let what = if t.topic == depth.topic && t.topic != rgb.topic {
                        " (depth must be registered to the colour camera, e.g. an \
                         aligned_depth_to_color topic)"
                    } else {
                        ""
                    };
                    return Err(bag_error(
                        &files,
                        m.file,
                        &t.topic,
                        *index,
                        format!(
                            "image is {w}x{h}, but {camera_name} is {}x{}{what}",
                            intrinsics.width, intrinsics.height
                        ),
                    ));
                }
            }
        }
        let depth_scale = match depth.first_content() {
            Some(Content::Image {
                format: PixelFormat::DepthM32,
                ..
            }) => METRIC_DEPTH_SCALE,
            _ => MM_DEPTH_SCALE,
        };

        // Step 5: association by header stamp.
        let max_dt = options.max_time_diff;
        let sorted = |t: &TopicIndex| {
            let mut v: Vec<(f64, usize, Indexed)> = t
                .messages
                .iter()
                .map(|(i, m)| (seconds(m.stamp_ns), *i, *m))
                .collect();
            v.sort_by(|a, b| a.0.total_cmp(&b.0));
            v
        };
        let depth_msgs = sorted(depth);
        let depth_times: Vec<f64> = depth_msgs.iter().map(|m| m.0).collect();
        let pose_msgs = pose_topic.map(sorted).unwrap_or_default();
        let pose_times: Vec<f64> = pose_msgs.iter().map(|m| m.0).collect();
        let frames: Vec<FrameEntry> = sorted(rgb)
            .into_iter()
            .filter_map(|(t, index, m)| {
                let d = nearest_within(&depth_times, t, max_dt)?;
                let (_, d_index, d_msg) = depth_msgs[d];
                Some(FrameEntry {
                    timestamp: t,
                    rgb: MessageRef {
                        file: m.file,
                        location: m.location,
                        index,
                    },
                    depth: MessageRef {
                        file: d_msg.file,
                        location: d_msg.location,
                        index: d_index,
                    },
                    gt_pose: nearest_within(&pose_times, t, max_dt).and_then(|p| {
                        match pose_msgs[p].2.content {
                            Content::Pose(pose) => Some(pose),
                            _ => None,
                        }
                    }),
                })
            })
            .collect();
        if frames.is_empty() {
            return Err(DatasetError::invalid(
                path,
                format!(
                    "no colour image on {} ({} messages) has a depth image on {} ({} messages) \
                     within {max_dt} s of its header stamp",
                    rgb.topic, rgb.count, depth.topic, depth.count
                ),
            ));
        }
        let mut gaps: Vec<f64> = frames
            .windows(2)
            .map(|w| w[1].timestamp - w[0].timestamp)
            .filter(|d| *d > 0.0)
            .collect();
        gaps.sort_by(f64::total_cmp);
        let frame_rate = match gaps.get(gaps.len() / 2) {
            Some(&median) => 1.0 / median,
            None => 30.0,
        };
        Ok(Self {
            bag: path.to_path_buf(),
            files,
            message_compression: layout.message_compression,
            rgb_topic: rgb.topic.clone(),
            rgb_compressed: rgb.type_name == COMPRESSED_IMAGE,
            depth_topic: depth.topic.clone(),
            intrinsics,
            depth_scale,
            frame_rate,
            frames,
        })
    }

    /// The colour and depth topics read.
    pub fn topics(&self) -> (&str, &str) {
        (&self.rgb_topic, &self.depth_topic)
    }

    /// Reads one message of a chosen topic and decodes it with `decode`; errors name the
    /// file, topic and message.
    fn read<T>(
        &mut self,
        topic_is_rgb: bool,
        m: MessageRef,
        decode: impl FnOnce(&[u8]) -> Result<T, String>,
    ) -> Result<T, DatasetError> {
        let message_compression = self.message_compression;
        let result = match self.files.get_mut(m.file) {
            Some(file) => file.message(m.location).and_then(|data| {
                let bytes = cdr_bytes(&data, message_compression)?;
                decode(&bytes)
            }),
            None => Err("no such file".to_string()),
        };
        result.map_err(|message| {
            let topic = match topic_is_rgb {
                true => &self.rgb_topic,
                false => &self.depth_topic,
            };
            bag_error(&self.files, m.file, topic, m.index, message)
        })
    }
}

impl RgbdSource for Rosbag2Source {
    fn name(&self) -> String {
        format!("rosbag2:{}", self.bag.display())
    }

    fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    fn len(&self) -> usize {
        self.frames.len()
    }

    fn frame_rate(&self) -> f64 {
        self.frame_rate
    }

    fn frame(&mut self, index: usize) -> Result<RgbdFrame, DatasetError> {
        let e = self
            .frames
            .get(index)
            .cloned()
            .ok_or(DatasetError::OutOfRange {
                index,
                len: self.frames.len(),
            })?;
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        let compressed = self.rgb_compressed;
        let rgb = self.read(true, e.rgb, |bytes| {
            let rgb = if compressed {
                decode_compressed_colour(&cdr::decode::<CompressedImage>(bytes)?, w, h)?
            } else {
                let img: Image = cdr::decode(bytes)?;
                if (img.width, img.height) != (w, h) {
                    return Err(format!(
                        "image is {}x{}, expected {w}x{h}",
                        img.width, img.height
                    ));
                }
                decode_colour(&img)?
            };
            Ok(rgb)
        })?;
        let scale = self.depth_scale;
        let depth = self.read(false, e.depth, |bytes| {
            let img: Image = cdr::decode(bytes)?;
            if (img.width, img.height) != (w, h) {
                return Err(format!(
                    "image is {}x{}, expected {w}x{h}",
                    img.width, img.height
                ));
            }
            decode_depth(&img, scale)
        })?;
        Ok(RgbdFrame {
            index,
            timestamp: e.timestamp,
            width: w,
            height: h,
            rgb,
            depth,
            depth_scale: self.depth_scale,
            gt_pose: e.gt_pose,
            labels: None,
        })
    }

    fn class_table(&self) -> Vec<InstanceClass> {
        Vec::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_files_sort_by_number() {
        let mut v: Vec<PathBuf> = ["b_10.mcap", "b_9.mcap", "b_0.mcap"]
            .iter()
            .map(PathBuf::from)
            .collect();
        v.sort_by_key(|p| split_number_key(p));
        assert_eq!(v, ["b_0.mcap", "b_9.mcap", "b_10.mcap"].map(PathBuf::from));
    }

    #[test]
    fn poses_must_be_rotations() {
        let mut p = PoseMsg::default();
        assert!(pose_of(&p).is_err());
        p.orientation.w = 2.0;
        let pose = pose_of(&p).expect("normalised");
        assert!((pose.rotation.w - 1.0).abs() < 1e-15);
        p.position.x = f64::NAN;
        assert!(pose_of(&p).is_err());
    }

    #[test]
    fn stamps_to_seconds() {
        assert_eq!(seconds(1_500_000_000), 1.5);
        assert_eq!(seconds(-500_000_000), -0.5);
    }
}
