//! Our messages as records of plain arrays: each `on_*` takes one decoded (validated) message
//! and returns what to log for it. The state between messages lives here: the global label
//! names, the labelled keyframes that colour the map, the trajectory so far, the last camera
//! model and tracking status, per-stage drop counts.

use std::collections::BTreeMap;

use opengs_ipc_schema::{
    ConsensusView, FrameView, KeyframeView, MapTargetView, PoseHeader, PoseStatus, RenderView,
    SegmentsView, Stamp, TelemetryEvent, TelemetryHeader,
};

use crate::labels::{class_ids, label_color, segment_classes, ClassTable};
use crate::map_labels::{KeyframeGeometry, LabelledViews, Pose};
use crate::paths::{self, LatencyPart};
use crate::record::{FrameTime, Item, Level, Record, Time};

/// The trajectory polyline is re-logged every this many verified poses (and at the end).
const TRAJECTORY_EVERY: usize = 10;
/// Length of the drawn camera frustums, metres.
const FRUSTUM_M: f32 = 0.15;
/// Trackable Gaussians are drawn as points of their geometric-mean scale, within these
/// bounds (metres), so a stray huge Gaussian does not hide the map.
const RADIUS_RANGE_M: (f32, f32) = (0.002, 0.05);

const TRAJECTORY_RGB: [u8; 3] = [255, 200, 40];

/// Turns decoded messages into records, keeping what spans messages.
#[derive(Debug, Default)]
pub struct Converter {
    classes: ClassTable,
    views: LabelledViews,
    trajectory: Vec<[f32; 3]>,
    trajectory_logged: usize,
    last_trajectory_time: Option<FrameTime>,
    camera_model: Option<([f64; 4], u32, u32)>,
    last_status: Option<PoseStatus>,
    dropped: BTreeMap<String, u64>,
    /// Label-map pixels whose label did not fit a class id (shown as none).
    pub overflowed_labels: usize,
}

fn at(stamp: &Stamp) -> Time {
    Time::Frame(FrameTime::of(stamp))
}

fn pinhole(intrinsics: [f64; 4], width: u32, height: u32) -> Item {
    let [fx, fy, cx, cy] = intrinsics;
    Item::Pinhole {
        focal: [fx as f32, fy as f32],
        principal: [cx as f32, cy as f32],
        resolution: [width as f32, height as f32],
        image_plane_distance: FRUSTUM_M,
    }
}

fn transform(pose: Pose) -> Item {
    let (translation, rotation_xyzw) = pose.to_f32();
    Item::Transform {
        translation,
        rotation_xyzw,
    }
}

/// The point radius of a Gaussian with these (linear) scales.
pub fn point_radius(scale: [f32; 3]) -> f32 {
    let (lo, hi) = RADIUS_RANGE_M;
    let product = scale.iter().map(|s| s.abs()).product::<f32>();
    let r = product.cbrt();
    if r.is_finite() {
        r.clamp(lo, hi)
    } else {
        lo
    }
}

/// Baseline JPEG of an RGB image (how camera images travel to the viewer: a tenth of the
/// raw size, which matters when streaming to a laptop).
pub fn jpeg_rgb(width: u32, height: u32, rgb: &[u8], quality: u8) -> anyhow::Result<Vec<u8>> {
    if rgb.len() != 3 * width as usize * height as usize {
        anyhow::bail!(
            "{width}x{height} RGB needs {} bytes, got {}",
            3 * width as usize * height as usize,
            rgb.len()
        );
    }
    let mut out = Vec::with_capacity(rgb.len() / 8);
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100)).encode(
        rgb,
        width,
        height,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(out)
}

impl Converter {
    /// What holds for the whole recording.
    pub fn start(&self) -> Vec<Record> {
        vec![Record::new(
            paths::WORLD,
            Time::Static,
            Item::WorldAxesRightHandYDown,
        )]
    }

    /// A sensor frame: the camera model when it changes, RGB and depth.
    pub fn on_frame(&mut self, v: &FrameView) -> Vec<Record> {
        let h = v.header;
        let time = at(&h.stamp);
        let mut out = Vec::with_capacity(3);
        let model = (h.intrinsics, h.width, h.height);
        if self.camera_model != Some(model) {
            self.camera_model = Some(model);
            out.push(Record::new(
                paths::CAMERA_IMAGE,
                time,
                pinhole(h.intrinsics, h.width, h.height),
            ));
        }
        out.push(Record::new(
            paths::CAMERA_RGB,
            time,
            Item::Rgb {
                width: h.width,
                height: h.height,
                rgb: v.rgb.to_vec(),
            },
        ));
        out.push(Record::new(
            paths::CAMERA_DEPTH,
            time,
            Item::Depth {
                width: h.width,
                height: h.height,
                depth: v.depth.to_vec(),
                units_per_metre: h.depth_scale,
            },
        ));
        out
    }

    /// A tracked pose: the camera's transform, tracking figures, status changes, and now
    /// and then the trajectory.
    pub fn on_pose(&mut self, h: &PoseHeader, status: PoseStatus) -> Vec<Record> {
        let time = at(&h.stamp);
        let mut out = Vec::new();
        let Some(pose) = Pose::from_tum(&h.pose) else {
            return out;
        };
        out.push(Record::new(paths::CAMERA, time, transform(pose)));
        out.push(Record::new(
            paths::TRACKING_OVERLAP,
            time,
            Item::Scalar(h.overlap as f64),
        ));
        out.push(Record::new(
            paths::TRACKING_INLIERS,
            time,
            Item::Scalar(h.inliers as f64),
        ));
        if self.last_status != Some(status) {
            let seq = h.stamp.seq;
            let (level, text) = match status {
                PoseStatus::Tracked if self.last_status.is_none() => {
                    (Level::Info, format!("frame {seq}: tracking"))
                }
                PoseStatus::Tracked => (Level::Info, format!("frame {seq}: tracked again")),
                PoseStatus::Initial => (Level::Info, format!("frame {seq}: first pose")),
                PoseStatus::Relocalised => (Level::Info, format!("frame {seq}: relocalised")),
                PoseStatus::Lost => (
                    Level::Warn,
                    format!("frame {seq}: lost (registration not verified)"),
                ),
                PoseStatus::TooFewPoints => (
                    Level::Warn,
                    format!("frame {seq}: lost (too few depth samples)"),
                ),
                PoseStatus::NoDepth => (Level::Warn, format!("frame {seq}: lost (no depth)")),
            };
            out.push(Record::new(
                paths::TRACKING_STATUS,
                time,
                Item::Text { level, text },
            ));
            self.last_status = Some(status);
        }
        if status.has_pose() {
            self.trajectory.push(pose.to_f32().0);
            self.last_trajectory_time = Some(FrameTime::of(&h.stamp));
            if self.trajectory.len() >= self.trajectory_logged + TRAJECTORY_EVERY {
                out.extend(self.trajectory_record());
            }
        }
        out
    }

    fn trajectory_record(&mut self) -> Option<Record> {
        let time = self.last_trajectory_time?;
        if self.trajectory.len() < 2 || self.trajectory.len() == self.trajectory_logged {
            return None;
        }
        self.trajectory_logged = self.trajectory.len();
        Some(Record::new(
            paths::TRAJECTORY,
            Time::Frame(time),
            Item::LineStrip {
                points: self.trajectory.clone(),
                color: TRAJECTORY_RGB,
            },
        ))
    }

    /// A keyframe: its pose, camera and RGB; the older keyframe's label maps are cleared;
    /// its geometry is kept for labelling the map once its consensus arrives.
    pub fn on_keyframe(&mut self, v: &KeyframeView) -> Vec<Record> {
        let h = v.header;
        let time = at(&h.stamp);
        let Some(pose) = Pose::from_tum(&h.pose) else {
            return Vec::new();
        };
        self.views.keyframe(KeyframeGeometry {
            seq: h.stamp.seq,
            pose,
            intrinsics: h.intrinsics,
            width: h.width,
            height: h.height,
            depth: v.depth.to_vec(),
            units_per_metre: h.depth_scale,
        });
        let mut out = vec![
            Record::new(paths::KEYFRAME, time, transform(pose)),
            Record::new(
                paths::KEYFRAME_IMAGE,
                time,
                pinhole(h.intrinsics, h.width, h.height),
            ),
            Record::new(
                paths::KEYFRAME_RGB,
                time,
                Item::Rgb {
                    width: h.width,
                    height: h.height,
                    rgb: v.rgb.to_vec(),
                },
            ),
        ];
        for p in [paths::SEGMENTS, paths::RENDER, paths::CONSENSUS] {
            out.push(Record::new(p, time, Item::Clear));
        }
        out
    }

    fn segmentation(&mut self, width: u32, height: u32, labels: &[u32]) -> Item {
        let (ids, overflow) = class_ids(labels);
        self.overflowed_labels += overflow;
        Item::Segmentation {
            width,
            height,
            class_ids: ids,
        }
    }

    /// A segmenter's label map, with its own labels' classes as its annotation context.
    pub fn on_segments(&mut self, v: &SegmentsView) -> Vec<Record> {
        let h = v.header;
        let time = at(&h.stamp);
        self.classes.segments(h.stamp.seq, v.labels);
        vec![
            Record::new(
                paths::SEGMENTS,
                time,
                Item::Annotations(segment_classes(v.labels)),
            ),
            Record::new(
                paths::SEGMENTS,
                time,
                self.segmentation(h.width, h.height, v.label_map),
            ),
        ]
    }

    /// The mapper's GS Voting render of a keyframe (global labels).
    pub fn on_render(&mut self, v: &RenderView) -> Vec<Record> {
        let h = v.header;
        vec![Record::new(
            paths::RENDER,
            at(&h.stamp),
            self.segmentation(h.width, h.height, v.label_map),
        )]
    }

    /// The consensus' consistent label map; the global names when they changed.
    pub fn on_consensus(&mut self, v: &ConsensusView) -> Vec<Record> {
        let h = v.header;
        let time = at(&h.stamp);
        let seq = h.stamp.seq;
        let map = v.result.label_map;
        let mut out = Vec::with_capacity(2);
        if self.classes.consensus(seq, v.result.mapping, map) {
            out.push(Record::new(
                paths::WORLD,
                time,
                Item::Annotations(self.classes.entries()),
            ));
        }
        self.views.consensus(seq, h.width, h.height, map);
        out.push(Record::new(
            paths::CONSENSUS,
            time,
            self.segmentation(h.width, h.height, map),
        ));
        out
    }

    /// The trackable Gaussians as points, coloured by the label the labelled keyframes give
    /// them (see [`crate::map_labels`]); Gaussians with a non-finite mean are left out.
    pub fn on_map_target(&mut self, v: &MapTargetView) -> Vec<Record> {
        let time = at(&v.header.stamp);
        let n = v.means.len();
        let mut positions = Vec::with_capacity(n);
        let mut radii = Vec::with_capacity(n);
        let mut colors = Vec::with_capacity(n);
        let mut ids = Vec::with_capacity(n);
        for (mean, scale) in v.means.iter().zip(v.scales) {
            if !mean.iter().all(|c| c.is_finite()) {
                continue;
            }
            let label = self.views.label(*mean);
            positions.push(*mean);
            radii.push(point_radius(*scale));
            colors.push(label_color(label));
            ids.push(u16::try_from(label).unwrap_or(0));
        }
        let count = positions.len();
        vec![
            Record::new(
                paths::GAUSSIANS,
                time,
                Item::Points {
                    positions,
                    radii,
                    colors,
                    class_ids: ids,
                },
            ),
            Record::new(paths::MAP_SIZE, time, Item::Scalar(count as f64)),
        ]
    }

    /// A stage's telemetry: its latency per processed message, its drops, its progress after
    /// the end of the data, its start and finish. Heartbeats log nothing.
    pub fn on_telemetry(&mut self, h: &TelemetryHeader, event: TelemetryEvent) -> Vec<Record> {
        let stage = h.stage_name();
        let ms = |ns: u64| ns as f64 / 1e6;
        match event {
            TelemetryEvent::Processed => {
                let time = at(&h.stamp);
                let wait = h.start_ns.saturating_sub(h.input_sent_ns);
                let work = h.end_ns.saturating_sub(h.start_ns);
                let mut out = vec![
                    Record::new(
                        paths::latency(stage, LatencyPart::Wait),
                        time,
                        Item::Scalar(ms(wait)),
                    ),
                    Record::new(
                        paths::latency(stage, LatencyPart::Process),
                        time,
                        Item::Scalar(ms(work)),
                    ),
                    Record::new(
                        paths::latency(stage, LatencyPart::Total),
                        time,
                        Item::Scalar(ms(wait + work)),
                    ),
                ];
                let origin = h.stamp.origin_ns;
                if origin > 0 && h.end_ns >= origin {
                    out.push(Record::new(
                        paths::latency(stage, LatencyPart::SinceSensor),
                        time,
                        Item::Scalar(ms(h.end_ns - origin)),
                    ));
                }
                out
            }
            TelemetryEvent::Dropped => {
                let count = self.dropped.entry(stage.to_string()).or_insert(0);
                *count += 1;
                vec![Record::new(
                    paths::dropped(stage),
                    at(&h.stamp),
                    Item::Scalar(*count as f64),
                )]
            }
            TelemetryEvent::Progress if h.work_total > 0 => vec![Record::new(
                paths::final_work(stage),
                Time::LogTime,
                Item::Scalar(h.work_done as f64 / h.work_total as f64),
            )],
            TelemetryEvent::Ready => vec![Record::new(
                paths::STAGE_EVENTS,
                Time::LogTime,
                Item::Text {
                    level: Level::Info,
                    text: format!("{stage} ready (pid {})", h.pid),
                },
            )],
            TelemetryEvent::Finished => vec![Record::new(
                paths::STAGE_EVENTS,
                Time::LogTime,
                Item::Text {
                    level: Level::Info,
                    text: format!("{stage} finished at frame {}", h.stamp.seq),
                },
            )],
            TelemetryEvent::Progress | TelemetryEvent::Heartbeat => Vec::new(),
        }
    }

    /// What is left to log at the end: the whole trajectory.
    pub fn finish(&mut self) -> Vec<Record> {
        self.trajectory_record().into_iter().collect()
    }

    /// Global labels known so far.
    pub fn global_labels(&self) -> usize {
        self.classes.len()
    }

    /// Keyframes with a consistent label map that colour the map.
    pub fn labelled_views(&self) -> usize {
        self.views.views()
    }
}

#[cfg(test)]
mod tests {
    use opengs_ipc_schema::{
        aligned_buffer, as_uninit_mut, ConsensusHeader, ConsensusResult, FrameHeader, FrameParts,
        KeyframeHeader, KeyframeParts, MapTargetHeader, MapTargetParts, MessageKind, RenderHeader,
        SegmentLabel, SegmentsHeader,
    };

    use super::*;

    const W: u32 = 8;
    const H: u32 = 6;
    const K: [f64; 4] = [10.0, 10.0, 3.5, 2.5];
    const N: usize = (W * H) as usize;

    fn buffer(len: usize) -> Vec<u64> {
        aligned_buffer(len.max(1))
    }

    fn bytes(buf: &mut [u64], len: usize) -> &mut [u8] {
        &mut bytemuck::cast_slice_mut(buf)[..len]
    }

    fn stamp(kind: MessageKind, seq: u64) -> Stamp {
        Stamp::new(kind, seq, seq * 33_333_333, 1_000 + seq)
    }

    fn frame_records(c: &mut Converter, seq: u64) -> Vec<Record> {
        let depth = vec![1500u16; N];
        let rgb: Vec<u8> = (0..3 * N).map(|i| i as u8).collect();
        let h = FrameHeader::new(
            stamp(MessageKind::Frame, seq),
            W,
            H,
            1000.0,
            K,
            None,
            false,
            seq,
        );
        let mut buf = buffer(h.payload_len());
        let parts = FrameParts {
            depth: &depth,
            labels: None,
            rgb: &rgb,
        };
        let payload = bytes(&mut buf, h.payload_len());
        h.encode(&parts, as_uninit_mut(payload)).expect("encode");
        let v = h.decode(payload).expect("decode");
        c.on_frame(&v)
    }

    #[test]
    fn a_frame_gives_its_camera_once_and_its_images_each_time() {
        let mut c = Converter::default();
        let first = frame_records(&mut c, 3);
        let paths: Vec<&str> = first.iter().map(|r| r.path.as_str()).collect();
        assert_eq!(
            paths,
            [paths::CAMERA_IMAGE, paths::CAMERA_RGB, paths::CAMERA_DEPTH]
        );
        assert_eq!(
            first[0].item,
            Item::Pinhole {
                focal: [10.0, 10.0],
                principal: [3.5, 2.5],
                resolution: [8.0, 6.0],
                image_plane_distance: FRUSTUM_M
            }
        );
        let Item::Depth {
            depth,
            units_per_metre,
            ..
        } = &first[2].item
        else {
            panic!("depth expected, got {:?}", first[2].item);
        };
        assert_eq!((depth.len(), *units_per_metre), (N, 1000.0));
        assert_eq!(
            first[1].time,
            Time::Frame(FrameTime {
                seq: 3,
                sensor: crate::record::SensorTime::SinceStart(99_999_999)
            })
        );
        let second = frame_records(&mut c, 4);
        assert_eq!(second.len(), 2, "same camera: no new pinhole");
    }

    fn pose_header(seq: u64, x: f64, status: PoseStatus) -> PoseHeader {
        let mut h = PoseHeader {
            stamp: stamp(MessageKind::Pose, seq),
            pose: [x, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            status: status as u32,
            inliers: 500,
            overlap: 0.8,
            ..PoseHeader::default()
        };
        h.stamp.payload_len = 0;
        h
    }

    #[test]
    fn poses_move_the_camera_and_grow_the_trajectory() {
        let mut c = Converter::default();
        let mut strips = 0;
        let mut texts = Vec::new();
        for seq in 0..25u64 {
            let status = match seq {
                0 => PoseStatus::Initial,
                12 | 13 => PoseStatus::Lost,
                _ => PoseStatus::Tracked,
            };
            let h = pose_header(seq, seq as f64 * 0.1, status);
            let decoded = h.decode(&[]).expect("valid pose");
            for r in c.on_pose(&h, decoded) {
                match (&r.path[..], &r.item) {
                    (paths::TRAJECTORY, Item::LineStrip { points, .. }) => {
                        strips += 1;
                        assert_eq!(points.len() % TRAJECTORY_EVERY, 0);
                    }
                    (paths::TRACKING_STATUS, Item::Text { text, .. }) => texts.push(text.clone()),
                    (paths::CAMERA, Item::Transform { translation, .. }) => {
                        assert!((translation[0] - seq as f32 * 0.1).abs() < 1e-6)
                    }
                    _ => {}
                }
            }
        }
        assert_eq!(strips, 2, "23 verified poses: strips at 10 and 20");
        assert_eq!(
            texts,
            [
                "frame 0: first pose",
                "frame 1: tracked again",
                "frame 12: lost (registration not verified)",
                "frame 14: tracked again"
            ]
        );
        let end = c.finish();
        let [Record {
            item: Item::LineStrip { points, .. },
            ..
        }] = &end[..]
        else {
            panic!("one final strip expected: {end:?}");
        };
        assert_eq!(points.len(), 23);
        assert!(c.finish().is_empty(), "nothing new to log");
    }

    fn keyframe_records(c: &mut Converter, seq: u64) -> Vec<Record> {
        let depth = vec![2000u16; N];
        let rgb = vec![7u8; 3 * N];
        let points = [[0.0f32, 0.0, 2.0]];
        let covariances = [[0.0f32; 6]];
        let h = KeyframeHeader::new(
            stamp(MessageKind::Keyframe, seq),
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            K,
            W,
            H,
            1000.0,
            1,
            false,
            seq,
        );
        let mut buf = buffer(h.payload_len());
        let payload = bytes(&mut buf, h.payload_len());
        let parts = KeyframeParts {
            points: &points,
            covariances: &covariances,
            depth: &depth,
            labels: None,
            rgb: &rgb,
        };
        h.encode(&parts, as_uninit_mut(payload)).expect("encode");
        c.on_keyframe(&h.decode(payload).expect("decode"))
    }

    fn segments_records(c: &mut Converter, seq: u64) -> Vec<Record> {
        let map: Vec<u32> = (0..N).map(|i| if i % 2 == 0 { 1 } else { 2 }).collect();
        let labels = [
            SegmentLabel::new(1, 0.9, Some("table"), 0.7),
            SegmentLabel::new(2, 0.8, None, 0.0),
        ];
        let h = SegmentsHeader::new(stamp(MessageKind::Segments, seq), W, H, 2, 0);
        let mut buf = buffer(h.payload_len());
        let payload = bytes(&mut buf, h.payload_len());
        h.encode(&map, &labels, as_uninit_mut(payload))
            .expect("encode");
        c.on_segments(&h.decode(payload).expect("decode"))
    }

    fn consensus_records(c: &mut Converter, seq: u64, map: &[u32]) -> Vec<Record> {
        let mapping = [[1u32, 5u32], [2, 70_000]];
        let parts = ConsensusResult {
            label_map: map,
            mapping: &mapping,
            relabels: &[],
            prunes: &[],
            pixels: &[],
        };
        let h = ConsensusHeader::new(stamp(MessageKind::Consensus, seq), W, H, 0.1, &parts);
        let mut buf = buffer(h.payload_len());
        let payload = bytes(&mut buf, h.payload_len());
        h.encode(&parts, as_uninit_mut(payload)).expect("encode");
        c.on_consensus(&h.decode(payload).expect("decode"))
    }

    fn map_records(c: &mut Converter, seq: u64, means: &[[f32; 3]]) -> Vec<Record> {
        let rotations = vec![[1.0f32, 0.0, 0.0, 0.0]; means.len()];
        let scales = vec![[0.01f32, 0.01, 0.01]; means.len()];
        let h = MapTargetHeader::new(stamp(MessageKind::MapTarget, seq), means.len() as u32, 1);
        let mut buf = buffer(h.payload_len());
        let payload = bytes(&mut buf, h.payload_len());
        let parts = MapTargetParts {
            means,
            rotations: &rotations,
            scales: &scales,
        };
        h.encode(&parts, as_uninit_mut(payload)).expect("encode");
        c.on_map_target(&h.decode(payload).expect("decode"))
    }

    #[test]
    fn the_semantic_loop_names_labels_and_colours_the_map() {
        let mut c = Converter::default();
        let kf = keyframe_records(&mut c, 10);
        let kf_paths: Vec<&str> = kf.iter().map(|r| r.path.as_str()).collect();
        assert_eq!(
            kf_paths,
            [
                paths::KEYFRAME,
                paths::KEYFRAME_IMAGE,
                paths::KEYFRAME_RGB,
                paths::SEGMENTS,
                paths::RENDER,
                paths::CONSENSUS
            ]
        );
        assert!(kf[3..].iter().all(|r| r.item == Item::Clear));

        let seg = segments_records(&mut c, 10);
        let Item::Annotations(entries) = &seg[0].item else {
            panic!("annotations first: {seg:?}");
        };
        assert_eq!(entries[1].label, "table (segment 1)");
        let Item::Segmentation { class_ids, .. } = &seg[1].item else {
            panic!("segmentation second: {seg:?}");
        };
        assert_eq!(&class_ids[..4], &[1, 2, 1, 2]);

        // Global label 5 on the left half of the image, 70000 (no class id) on the right.
        let map: Vec<u32> = (0..N)
            .map(|i| if (i % W as usize) < 4 { 5 } else { 70_000 })
            .collect();
        let cons = consensus_records(&mut c, 10, &map);
        assert_eq!(cons[0].path, paths::WORLD);
        let Item::Annotations(global) = &cons[0].item else {
            panic!("global annotations first: {cons:?}");
        };
        let names: Vec<&str> = global.iter().map(|e| e.label.as_str()).collect();
        assert_eq!(names, ["unlabelled", "table (5)"], "70000 has no class id");
        assert_eq!(c.global_labels(), 2);
        assert_eq!(c.overflowed_labels, N / 2);
        assert_eq!(c.labelled_views(), 1);
        // The same consensus again: no new names.
        let again = consensus_records(&mut c, 10, &map);
        assert_eq!(again.len(), 1);

        // Gaussians on the wall 2 m ahead: the left ones take label 5; one behind the wall,
        // one off to the side and one NaN are unlabelled or left out.
        let means = [
            [-0.2f32, 0.0, 2.0],
            [-0.5, 0.1, 2.0],
            [-0.2, 0.0, 3.0],
            [9.0, 0.0, 2.0],
            [f32::NAN, 0.0, 2.0],
        ];
        let m = map_records(&mut c, 12, &means);
        let Item::Points {
            positions,
            radii,
            colors,
            class_ids,
        } = &m[0].item
        else {
            panic!("points expected: {m:?}");
        };
        assert_eq!(positions.len(), 4, "the NaN mean is left out");
        assert_eq!(class_ids, &[5, 5, 0, 0]);
        assert_eq!(colors[0], label_color(5));
        assert_eq!(colors[2], crate::labels::UNLABELLED_RGB);
        assert!(radii.iter().all(|&r| (r - 0.01).abs() < 1e-6));
        assert_eq!(m[1].item, Item::Scalar(4.0));
    }

    #[test]
    fn rgb_travels_as_jpeg_of_the_same_size() {
        let (w, h) = (32u32, 24u32);
        let rgb: Vec<u8> = (0..3 * w * h).map(|i| (i % 251) as u8).collect();
        let jpeg = jpeg_rgb(w, h, &rgb, 85).expect("encode");
        assert_eq!(&jpeg[..2], &[0xFF, 0xD8], "JPEG start of image");
        let back = image::load_from_memory(&jpeg).expect("decode");
        assert_eq!((back.width(), back.height()), (w, h));
        let err = jpeg_rgb(w, h, &rgb[1..], 85).expect_err("short buffer");
        assert!(err.to_string().contains("needs 2304 bytes"), "{err}");
    }

    #[test]
    fn radii_are_the_mean_scale_within_bounds() {
        assert!((point_radius([0.01, 0.02, 0.04]) - 0.02).abs() < 1e-6);
        assert_eq!(point_radius([1.0, 1.0, 1.0]), RADIUS_RANGE_M.1);
        assert_eq!(point_radius([0.0, 0.0, 0.0]), RADIUS_RANGE_M.0);
        assert_eq!(point_radius([f32::NAN, 1.0, 1.0]), RADIUS_RANGE_M.0);
        assert_eq!(point_radius([f32::INFINITY, 1.0, 1.0]), RADIUS_RANGE_M.0);
    }

    #[test]
    fn a_render_is_a_segmentation_of_global_labels() {
        let mut c = Converter::default();
        let map = vec![4u32; N];
        let h = RenderHeader::new(stamp(MessageKind::Render, 10), W, H, 0);
        let mut buf = buffer(h.payload_len());
        let payload = bytes(&mut buf, h.payload_len());
        h.encode(&map, &[], as_uninit_mut(payload)).expect("encode");
        let r = c.on_render(&h.decode(payload).expect("decode"));
        assert_eq!(r[0].path, paths::RENDER);
        assert_eq!(
            r[0].item,
            Item::Segmentation {
                width: W,
                height: H,
                class_ids: vec![4; N]
            }
        );
    }

    #[test]
    fn telemetry_becomes_latency_series_drop_counts_and_events() {
        let mut c = Converter::default();
        let input = Stamp::new(MessageKind::Frame, 7, 7_000_000, 1_000_000);
        let h = TelemetryHeader::new(
            "tracker",
            TelemetryEvent::Processed,
            &input,
            2_000_000,
            5_000_000,
            17_000_000,
        );
        let ev = h.decode(&[]).expect("valid");
        let r = c.on_telemetry(&h, ev);
        let series: Vec<(&str, Item)> = r
            .iter()
            .map(|r| (r.path.as_str(), r.item.clone()))
            .collect();
        assert_eq!(
            series,
            [
                ("latency/tracker/wait_ms", Item::Scalar(3.0)),
                ("latency/tracker/process_ms", Item::Scalar(12.0)),
                ("latency/tracker/total_ms", Item::Scalar(15.0)),
                ("latency/tracker/since_sensor_ms", Item::Scalar(16.0)),
            ]
        );
        assert!(r
            .iter()
            .all(|r| r.time == Time::Frame(FrameTime::of(&input))));
        let drop = TelemetryHeader::new("segmenter", TelemetryEvent::Dropped, &input, 1, 1, 1);
        c.on_telemetry(&drop, TelemetryEvent::Dropped);
        let second = c.on_telemetry(&drop, TelemetryEvent::Dropped);
        assert_eq!(second[0].path, "dropped/segmenter");
        assert_eq!(second[0].item, Item::Scalar(2.0));
        let progress = TelemetryHeader::progress("mapper", 150, 600, 5);
        let p = c.on_telemetry(&progress, TelemetryEvent::Progress);
        assert_eq!(
            (p[0].path.as_str(), &p[0].item, p[0].time),
            ("final_work/mapper", &Item::Scalar(0.25), Time::LogTime)
        );
        let beat = TelemetryHeader::new("mapper", TelemetryEvent::Heartbeat, &input, 1, 1, 1);
        assert!(c.on_telemetry(&beat, TelemetryEvent::Heartbeat).is_empty());
        let ready = TelemetryHeader::new("mapper", TelemetryEvent::Ready, &input, 1, 1, 1);
        let Item::Text { text, .. } = &c.on_telemetry(&ready, TelemetryEvent::Ready)[0].item else {
            panic!("text expected");
        };
        assert!(text.starts_with("mapper ready (pid "), "{text}");
    }
}
