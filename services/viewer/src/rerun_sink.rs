//! The Rerun end of the viewer (cargo feature `rerun`): a recording stream to an .rrd file,
//! to a Rerun viewer over gRPC, or both, and each plain-data [`Record`] as its Rerun
//! archetype. Timelines: `frame` (the source frame's sequence number) and `sensor_time` (its
//! capture time: wall-clock for recorded data, time since the start for generated data);
//! Rerun adds its own `log_time`.

use std::path::Path;
use std::time::Duration;

use anyhow::Context;
use opengs_pipeline::viewer_args::ViewerArgs;
use rerun::external::re_uri::{ProxyUri, RedapUri};
use rerun::RecordingStream;

use crate::convert::jpeg_rgb;
use crate::outbox::RecordSink;
use crate::record::{Item, Level, Record, SensorTime, Time};

/// The application id Rerun groups recordings by.
pub const APPLICATION_ID: &str = "opengs";
/// Timeline names.
pub const FRAME_TIMELINE: &str = "frame";
pub const SENSOR_TIMELINE: &str = "sensor_time";
/// JPEG quality of camera images.
const JPEG_QUALITY: u8 = 85;

/// Logs records into a Rerun recording stream.
pub struct RerunSink {
    rec: RecordingStream,
}

fn proxy_uri(url: &str) -> anyhow::Result<ProxyUri> {
    match url.parse::<RedapUri>() {
        Ok(RedapUri::Proxy(uri)) => Ok(uri),
        Ok(_) => anyhow::bail!("{url} is not a viewer's proxy address (…/proxy)"),
        Err(e) => anyhow::bail!("{url}: {e}"),
    }
}

fn grpc_sink(url: &str) -> anyhow::Result<rerun::sink::GrpcSink> {
    proxy_uri(url).map(rerun::sink::GrpcSink::new)
}

fn file_sink(file: &Path) -> anyhow::Result<rerun::sink::FileSink> {
    rerun::sink::FileSink::new(file).with_context(|| format!("--rerun {}", file.display()))
}

impl RerunSink {
    /// A recording of run `run_id` (its recording id, so a file and a live stream of the same
    /// run are one recording in the viewer) to where `args` say.
    pub fn new(run_id: &str, args: &ViewerArgs) -> anyhow::Result<Self> {
        let builder =
            rerun::RecordingStreamBuilder::new(APPLICATION_ID).recording_id(run_id.to_string());
        let rec = match (&args.rerun, &args.rerun_connect) {
            (Some(file), None) => builder.set_sinks((file_sink(file)?,))?,
            (None, Some(url)) => builder.set_sinks((grpc_sink(url)?,))?,
            (Some(file), Some(url)) => builder.set_sinks((file_sink(file)?, grpc_sink(url)?))?,
            (None, None) => anyhow::bail!("nothing to record to: give --rerun or --rerun-connect"),
        };
        if let Some(file) = &args.rerun {
            tracing::info!("recording to {}", file.display());
        }
        if let Some(url) = &args.rerun_connect {
            tracing::info!("streaming to the Rerun viewer at {url}");
        }
        Ok(Self { rec })
    }

    fn set_time(&self, time: &Time) {
        self.rec.reset_time();
        if let Time::Frame(t) = time {
            self.rec.set_time_sequence(FRAME_TIMELINE, t.seq);
            match t.sensor {
                SensorTime::SinceEpoch(ns) => self
                    .rec
                    .set_timestamp_nanos_since_epoch(SENSOR_TIMELINE, ns),
                SensorTime::SinceStart(ns) => self
                    .rec
                    .set_duration_secs(SENSOR_TIMELINE, ns as f64 * 1e-9),
            }
        }
    }

    fn log_item(&self, path: &str, time: &Time, item: &Item) -> anyhow::Result<()> {
        let rec = &self.rec;
        let r = match item {
            Item::WorldAxesRightHandYDown => {
                rec.log_static(path, &rerun::ViewCoordinates::RIGHT_HAND_Y_DOWN())
            }
            Item::Transform {
                translation,
                rotation_xyzw,
            } => rec.log(
                path,
                &rerun::Transform3D::from_translation_rotation(
                    *translation,
                    rerun::Quaternion::from_xyzw(*rotation_xyzw),
                ),
            ),
            Item::Pinhole {
                focal,
                principal,
                resolution,
                image_plane_distance,
            } => rec.log(
                path,
                &rerun::Pinhole::from_focal_length_and_resolution(*focal, *resolution)
                    .with_principal_point(*principal)
                    .with_camera_xyz(rerun::components::ViewCoordinates::RDF)
                    .with_image_plane_distance(*image_plane_distance),
            ),
            Item::Rgb { width, height, rgb } => {
                match jpeg_rgb(*width, *height, rgb, JPEG_QUALITY) {
                    Ok(jpeg) => rec.log(
                        path,
                        &rerun::EncodedImage::new(jpeg).with_media_type(rerun::MediaType::jpeg()),
                    ),
                    Err(e) => {
                        tracing::debug!("{path}: JPEG failed ({e}); logged raw");
                        rec.log(
                            path,
                            &rerun::Image::from_rgb24(rgb.clone(), [*width, *height]),
                        )
                    }
                }
            }
            Item::Depth {
                width,
                height,
                depth,
                units_per_metre,
            } => {
                let bytes: Vec<u8> = depth.iter().flat_map(|d| d.to_le_bytes()).collect();
                rec.log(
                    path,
                    &rerun::DepthImage::from_gray16(bytes, [*width, *height])
                        .with_meter(*units_per_metre),
                )
            }
            Item::Segmentation {
                width,
                height,
                class_ids,
            } => {
                let bytes: Vec<u8> = class_ids.iter().flat_map(|c| c.to_le_bytes()).collect();
                rec.log(
                    path,
                    &rerun::SegmentationImage::new(
                        bytes,
                        rerun::ImageFormat::segmentation(
                            [*width, *height],
                            rerun::ChannelDatatype::U16,
                        ),
                    ),
                )
            }
            Item::Annotations(entries) => {
                let classes: Vec<rerun::ClassDescription> = entries
                    .iter()
                    .map(|e| {
                        let [r, g, b, a] = e.rgba;
                        let color = rerun::Rgba32::from_unmultiplied_rgba(r, g, b, a);
                        (e.id, e.label.as_str(), color).into()
                    })
                    .collect();
                rec.log(path, &rerun::AnnotationContext::new(classes))
            }
            Item::Points {
                positions,
                radii,
                colors,
                class_ids,
            } => rec.log(
                path,
                &rerun::Points3D::new(positions.iter().copied())
                    .with_radii(radii.iter().copied())
                    .with_colors(
                        colors
                            .iter()
                            .map(|&[r, g, b]| rerun::Color::from_rgb(r, g, b)),
                    )
                    .with_class_ids(class_ids.iter().copied()),
            ),
            Item::LineStrip { points, color } => {
                let [r, g, b] = *color;
                rec.log(
                    path,
                    &rerun::LineStrips3D::new([points.iter().copied()])
                        .with_colors([rerun::Color::from_rgb(r, g, b)]),
                )
            }
            Item::Scalar(v) => rec.log(path, &rerun::Scalars::single(*v)),
            Item::Text { level, text } => {
                let level = match level {
                    Level::Info => rerun::TextLogLevel::INFO,
                    Level::Warn => rerun::TextLogLevel::WARN,
                };
                rec.log(path, &rerun::TextLog::new(text.as_str()).with_level(level))
            }
            Item::Clear => rec.log(path, &rerun::Clear::flat()),
        };
        r.with_context(|| format!("{path} at {time:?}"))
    }
}

impl RecordSink for RerunSink {
    fn log(&mut self, record: &Record) -> anyhow::Result<()> {
        self.set_time(&record.time);
        self.log_item(&record.path, &record.time, &record.item)
    }

    fn flush(&mut self, timeout: Duration) -> anyhow::Result<()> {
        self.rec
            .flush_with_timeout(timeout)
            .map_err(|e| anyhow::anyhow!("{e}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{ClassEntry, FrameTime};

    fn every_item() -> Vec<Record> {
        let t = Time::Frame(FrameTime {
            seq: 3,
            sensor: SensorTime::SinceStart(100_000_000),
        });
        let epoch = Time::Frame(FrameTime {
            seq: 4,
            sensor: SensorTime::SinceEpoch(1_305_031_102_175_304_000),
        });
        let (w, h) = (4u32, 3u32);
        let n = (w * h) as usize;
        [
            (Time::Static, Item::WorldAxesRightHandYDown),
            (
                t,
                Item::Transform {
                    translation: [0.1, 0.2, 0.3],
                    rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
                },
            ),
            (
                t,
                Item::Pinhole {
                    focal: [5.0, 5.0],
                    principal: [1.5, 1.0],
                    resolution: [4.0, 3.0],
                    image_plane_distance: 0.1,
                },
            ),
            (
                epoch,
                Item::Rgb {
                    width: w,
                    height: h,
                    rgb: vec![200; 3 * n],
                },
            ),
            (
                t,
                Item::Depth {
                    width: w,
                    height: h,
                    depth: vec![1500; n],
                    units_per_metre: 1000.0,
                },
            ),
            (
                t,
                Item::Segmentation {
                    width: w,
                    height: h,
                    class_ids: vec![2; n],
                },
            ),
            (
                t,
                Item::Annotations(vec![ClassEntry {
                    id: 2,
                    label: "chair (2)".into(),
                    rgba: [1, 2, 3, 255],
                }]),
            ),
            (
                t,
                Item::Points {
                    positions: vec![[0.0, 0.0, 1.0]],
                    radii: vec![0.01],
                    colors: vec![[9, 9, 9]],
                    class_ids: vec![2],
                },
            ),
            (
                t,
                Item::LineStrip {
                    points: vec![[0.0; 3], [1.0; 3]],
                    color: [1, 1, 1],
                },
            ),
            (Time::LogTime, Item::Scalar(2.5)),
            (
                t,
                Item::Text {
                    level: Level::Warn,
                    text: "lost".into(),
                },
            ),
            (t, Item::Clear),
        ]
        .into_iter()
        .map(|(time, item)| Record::new("world/x", time, item))
        .collect()
    }

    #[test]
    fn every_item_is_logged_into_a_file() {
        let dir = tempfile::tempdir().expect("tmp");
        let file = dir.path().join("run.rrd");
        let args = ViewerArgs {
            rerun: Some(file.clone()),
            rerun_connect: None,
        };
        let mut sink = RerunSink::new("test-run", &args).expect("sink");
        for r in every_item() {
            sink.log(&r)
                .unwrap_or_else(|e| panic!("{:?}: {e:#}", r.item));
        }
        sink.flush(Duration::from_secs(5)).expect("flush");
        drop(sink);
        let len = std::fs::metadata(&file).expect("written").len();
        assert!(len > 1000, "{len} bytes");
    }

    #[test]
    fn bad_destinations_are_refused_by_name() {
        let err = RerunSink::new("r", &ViewerArgs::default())
            .err()
            .expect("nothing to record to");
        assert!(err.to_string().contains("--rerun"), "{err}");
        let err = proxy_uri("rerun+http://host:9876/other").expect_err("not a proxy");
        assert!(err.to_string().contains("host"), "{err}");
        // What `--rerun-connect` makes of its short forms is what the SDK accepts.
        for short in ["laptop", "10.0.0.5:9000", "rerun+https://viewer.lan/proxy"] {
            let url = opengs_pipeline::viewer_args::connect_url(short).expect("valid");
            assert!(proxy_uri(&url).is_ok(), "{short} → {url}");
        }
        let err = file_sink(Path::new("/nonexistent-dir/run.rrd")).expect_err("no such directory");
        assert!(
            err.to_string().contains("/nonexistent-dir/run.rrd"),
            "{err}"
        );
    }
}
