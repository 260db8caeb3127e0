//! ROS 2 bags against an independent implementation: the Python `rosbags` package
//! (`$OPENGS_PYTHON`, set by scripts/test.sh from scripts/setup-python.sh) writes bags in
//! every encoding we read (fixtures/write_rosbag2.py) and reads the bags we write
//! (fixtures/read_rosbag2.py). Without such a Python the tests that need it say why and pass,
//! unless `OPENGS_REQUIRE_PYTHON=1`. Our writer's bag read back by our reader, and truncated
//! bags, need no Python.

use std::path::{Path, PathBuf};
use std::process::Command;

use opengs_datasets::rosbag2::{METRIC_DEPTH_SCALE, MM_DEPTH_SCALE};
use opengs_datasets::rosbag2_writer::{CAMERA_INFO_TOPIC, DEPTH_TOPIC, POSE_TOPIC, RGB_TOPIC};
use opengs_datasets::{
    open_dataset, write_dataset, write_rosbag2, ChunkCompression, DatasetError, DatasetFormat,
    DatasetKind, DatasetSpec, RgbdSource, Rosbag2Options, Rosbag2Source, SyntheticOptions,
    SyntheticSource,
};
use serde_json::Value;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// The Python with `rosbags` and `PIL`, or `None` (said why) when there is none and it is
/// not required.
fn python() -> Option<PathBuf> {
    let required = std::env::var("OPENGS_REQUIRE_PYTHON").is_ok_and(|v| v == "1");
    let why = match std::env::var_os("OPENGS_PYTHON") {
        None => "OPENGS_PYTHON is not set (scripts/setup-python.sh prints one)".to_string(),
        Some(p) => {
            let p = PathBuf::from(p);
            match Command::new(&p)
                .args(["-c", "import rosbags, PIL"])
                .output()
            {
                Ok(o) if o.status.success() => return Some(p),
                Ok(o) => format!(
                    "{} lacks rosbags or pillow: {}",
                    p.display(),
                    String::from_utf8_lossy(&o.stderr).trim()
                ),
                Err(e) => format!("{} does not run: {e}", p.display()),
            }
        }
    };
    assert!(!required, "OPENGS_REQUIRE_PYTHON=1 but {why}");
    eprintln!("skipped: {why}");
    None
}

/// Runs `write_rosbag2.py` for `cases` into a new temporary directory.
fn python_bags(python: &Path, cases: &[&str]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = Command::new(python)
        .arg(fixture("write_rosbag2.py"))
        .arg(dir.path())
        .args(cases)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "write_rosbag2.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    dir
}

fn case(dir: &Path, name: &str) -> Value {
    let text = std::fs::read_to_string(dir.join(format!("{name}.json"))).expect("case json");
    serde_json::from_str(&text).expect("case json parses")
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn open(path: &Path, options: Rosbag2Options) -> Result<Rosbag2Source, DatasetError> {
    Rosbag2Source::open(path, options)
}

fn err_text<T>(r: Result<T, DatasetError>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

/// What our reader makes of a 32FC1 depth in metres at `scale` units per metre.
fn metric_units(m: f32, scale: f32) -> u16 {
    let v = (m as f64 * scale as f64).round();
    if m.is_finite() && m > 0.0 && v <= u16::MAX as f64 {
        v as u16
    } else {
        0
    }
}

/// Mean and largest absolute difference of two equally long byte images.
fn differences(a: &[u8], b: &[u8]) -> (f64, u8) {
    assert_eq!(a.len(), b.len());
    let d: Vec<u8> = a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).collect();
    let mean = d.iter().map(|&v| v as f64).sum::<f64>() / d.len().max(1) as f64;
    (mean, d.iter().copied().max().unwrap_or(0))
}

const PYTHON_CASES: [&str; 13] = [
    "colour_rgb8",
    "colour_bgr8",
    "colour_rgba8",
    "colour_bgra8",
    "colour_mono8",
    "colour_jpeg",
    "colour_png",
    "depth_16_big_endian",
    "depth_32_big_endian",
    "odometry",
    "no_pose",
    "zstd_chunks",
    "zstd_messages",
];

#[test]
fn every_encoding_written_by_rosbags_decodes_bit_for_bit() {
    let Some(python) = python() else { return };
    let dir = python_bags(&python, &PYTHON_CASES);
    for name in PYTHON_CASES {
        let c = case(dir.path(), name);
        let bag = dir.path().join(name);
        let mut src =
            open(&bag, Rosbag2Options::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let frames = c["frames"].as_array().expect("frames");
        let (w, h) = (
            c["width"].as_u64().unwrap_or(0),
            c["height"].as_u64().unwrap_or(0),
        );
        // The last colour image has no depth within 20 ms: dropped.
        assert_eq!(src.len(), frames.len(), "{name}");
        let k = src.intrinsics();
        let cam: Vec<f64> = serde_json::from_value(c["camera"].clone()).expect("camera");
        assert_eq!(
            (k.fx, k.fy, k.cx, k.cy, k.width as u64, k.height as u64),
            (cam[0], cam[1], cam[2], cam[3], w, h),
            "{name}"
        );
        let expected = dir.path().join(format!("{name}.expected"));
        let colour = c["colour"].as_str().unwrap_or_default();
        let metric = c["depth"] == "32FC1";
        for (i, fc) in frames.iter().enumerate() {
            let f = src
                .frame(i)
                .unwrap_or_else(|e| panic!("{name} frame {i}: {e}"));
            let stamp = fc["stamp_ns"].as_u64().expect("stamp");
            let t = (stamp / 1_000_000_000) as f64 + (stamp % 1_000_000_000) as f64 * 1e-9;
            assert_eq!(
                f.timestamp, t,
                "{name} frame {i}: header stamp, not log time"
            );
            let rgb = read(&expected.join(format!("rgb_{i}.bin")));
            match colour {
                "mono8" => {
                    let grey: Vec<u8> = rgb.chunks(3).flat_map(|p| [p[0]; 3]).collect();
                    assert!(f.rgb == grey, "{name} frame {i}: grey differs");
                }
                "jpeg" => {
                    // Another decoder (Pillow's libjpeg) differs by rounding only; the
                    // original pixels by JPEG's loss.
                    let pillow = read(&expected.join(format!("jpeg_{i}.bin")));
                    let (mean, max) = differences(&f.rgb, &pillow);
                    assert!(
                        mean < 1.0 && max <= 16,
                        "{name} frame {i}: vs Pillow {mean} {max}"
                    );
                    let (mean, _) = differences(&f.rgb, &rgb);
                    assert!(mean < 12.0, "{name} frame {i}: JPEG mean error {mean}");
                }
                _ => assert!(f.rgb == rgb, "{name} frame {i}: colour differs"),
            }
            let raw = read(&expected.join(format!("depth_{i}.bin")));
            let want: Vec<u16> = if metric {
                raw.chunks_exact(4)
                    .map(|b| {
                        metric_units(
                            f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                            METRIC_DEPTH_SCALE,
                        )
                    })
                    .collect()
            } else {
                raw.chunks_exact(2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]))
                    .collect()
            };
            assert_eq!(
                f.depth_scale,
                if metric {
                    METRIC_DEPTH_SCALE
                } else {
                    MM_DEPTH_SCALE
                },
                "{name}"
            );
            assert!(f.depth == want, "{name} frame {i}: depth differs");
            if metric && i == 0 {
                // NaN, inf, -inf, -1, 0 and 20 m (past 13.1 m) are no depth.
                assert_eq!(&f.depth[..6], &[0; 6], "{name}");
            }
            match (&f.gt_pose, fc["pose"].as_array()) {
                (Some(p), Some(v)) => {
                    let v: Vec<f64> = v.iter().filter_map(Value::as_f64).collect();
                    let t = p.translation.vector;
                    let q = p.rotation.coords;
                    let got = [t.x, t.y, t.z, q[0], q[1], q[2], q[3]];
                    for (a, b) in got.iter().zip(&v) {
                        assert!(
                            (a - b).abs() < 1e-12,
                            "{name} frame {i}: pose {got:?} vs {v:?}"
                        );
                    }
                }
                (None, None) => {}
                (p, v) => panic!("{name} frame {i}: pose {p:?}, expected {v:?}"),
            }
            assert!(f.labels.is_none());
        }
    }
    // The same bag as one .mcap file, and through open_dataset.
    let mcap = dir.path().join("colour_rgb8/colour_rgb8.mcap");
    let by_file = open(&mcap, Rosbag2Options::default()).expect("single .mcap");
    assert_eq!(by_file.len(), 5);
    let spec: DatasetSpec = format!("rosbag2:{}", dir.path().join("colour_rgb8").display())
        .parse()
        .expect("spec");
    let mut src = open_dataset(&spec.with_max_frames(Some(2))).expect("open_dataset");
    assert_eq!(
        (src.len(), src.frame(1).map(|f| f.index).ok()),
        (2, Some(1))
    );
    assert!(src.name().starts_with("rosbag2:"));
}

#[test]
fn topic_flags_resolve_an_ambiguous_bag() {
    let Some(python) = python() else { return };
    let dir = python_bags(&python, &["ambiguous"]);
    let bag = dir.path().join("ambiguous");
    let e = err_text(open(&bag, Rosbag2Options::default()));
    for part in [
        "--rgb-topic",
        "/camera/color/image_raw",
        "/camera2/color/image_raw",
        "/camera/infra1/image_rect_raw  sensor_msgs/msg/Image mono8  6 messages",
        "/camera/aligned_depth_to_color/image_raw  sensor_msgs/msg/Image 16UC1  5 messages",
    ] {
        assert!(e.contains(part), "missing '{part}' in: {e}");
    }
    let rgb = |t: &str| Rosbag2Options {
        rgb_topic: Some(t.to_string()),
        ..Rosbag2Options::default()
    };
    // The CameraInfo beside the colour topic, not the 7x5 depth one.
    let src = open(&bag, rgb("/camera/color/image_raw")).expect("with --rgb-topic");
    assert_eq!((src.len(), src.intrinsics().width), (5, 33));
    let e = err_text(open(&bag, rgb("/camera2/color/image_raw")));
    assert!(
        e.contains("--camera-info-topic") && e.contains("/camera/depth/camera_info"),
        "{e}"
    );
    let src = open(
        &bag,
        Rosbag2Options {
            camera_info_topic: Some("/camera/color/camera_info".into()),
            ..rgb("/camera2/color/image_raw")
        },
    )
    .expect("with --camera-info-topic");
    assert_eq!(src.topics().0, "/camera2/color/image_raw");
    let e = err_text(open(&bag, rgb("/nope")));
    assert!(
        e.contains("--rgb-topic /nope") && e.contains("6 messages"),
        "{e}"
    );
    let e = err_text(open(&bag, rgb("/camera/aligned_depth_to_color/image_raw")));
    assert!(e.contains("not a colour image topic"), "{e}");
    let mut src = open(
        &bag,
        Rosbag2Options {
            pose_topic: Some("none".into()),
            ..rgb("/camera/color/image_raw")
        },
    )
    .expect("--pose-topic none");
    assert!(src.frame(0).expect("frame").gt_pose.is_none());
    let e = err_text(open(
        &bag,
        Rosbag2Options {
            pose_topic: Some("/camera/color/camera_info".into()),
            ..rgb("/camera/color/image_raw")
        },
    ));
    assert!(
        e.contains("--pose-topic") && e.contains("CameraInfo"),
        "{e}"
    );
}

#[test]
fn malformed_bags_name_the_topic_and_message() {
    let Some(python) = python() else { return };
    let dir = python_bags(
        &python,
        &["bad_encoding", "bad_size", "bad_camera_info", "sqlite"],
    );
    let d = dir.path();
    let e = err_text(open(&d.join("bad_encoding"), Rosbag2Options::default()));
    assert!(
        e.contains("bad_encoding.mcap: topic /camera/color/image_raw, message 2:")
            && e.contains("unknown image encoding 'yuv9'"),
        "{e}"
    );
    let e = err_text(open(&d.join("bad_size"), Rosbag2Options::default()));
    assert!(
        e.contains("topic /camera/color/image_raw, message 3:") && e.contains("height × step"),
        "{e}"
    );
    let e = err_text(open(&d.join("bad_camera_info"), Rosbag2Options::default()));
    assert!(
        e.contains("topic /camera/color/image_raw, message 0:")
            && e.contains(
                "image is 33x17, but CameraInfo (/camera/color/camera_info message 0) is 34x17"
            ),
        "{e}"
    );
    let e = err_text(open(&d.join("sqlite"), Rosbag2Options::default()));
    assert!(
        e.contains("SQLite3") && e.contains("only MCAP") && e.contains("rosbags-convert"),
        "{e}"
    );
    let e = err_text(open(
        &d.join("sqlite/sqlite.db3"),
        Rosbag2Options::default(),
    ));
    assert!(e.contains("only MCAP"), "{e}");
}

/// The synthetic room's first frames at `depth_scale` units per metre.
fn synthetic(frames: usize, depth_scale: f32) -> SyntheticSource {
    SyntheticSource::new(SyntheticOptions {
        frames: Some(frames),
        depth_scale,
        ..SyntheticOptions::default()
    })
    .expect("synthetic")
}

#[test]
fn our_bag_reads_back_as_the_synthetic_frames() {
    for (scale, chunks) in [
        (MM_DEPTH_SCALE, ChunkCompression::Zstd),
        (5000.0, ChunkCompression::None),
    ] {
        let dir = tempfile::tempdir().expect("tempdir");
        let bag = dir.path().join("synth");
        let mut calls = 0;
        write_rosbag2(
            &mut synthetic(4, scale),
            &bag,
            chunks,
            &mut |done, total| {
                calls += 1;
                assert!(done <= total);
            },
        )
        .expect("write");
        assert!(calls >= 1);
        assert!(bag.join("synth_0.mcap").is_file() && bag.join("metadata.yaml").is_file());
        let mut expected = synthetic(4, scale);
        let mut loaded =
            open_dataset(&DatasetSpec::new(DatasetKind::Rosbag2(bag.clone()))).expect("open");
        assert_eq!(loaded.len(), expected.len());
        assert_eq!(loaded.intrinsics(), expected.intrinsics());
        for i in 0..expected.len() {
            let a = expected.frame(i).expect("synthetic frame");
            let b = loaded.frame(i).expect("bag frame");
            assert!(a.rgb == b.rgb, "frame {i}: colour differs");
            assert_eq!(b.depth_scale, MM_DEPTH_SCALE);
            // Depth to the millimetre: the synthetic depth rounded to mm.
            let mm: Vec<u16> = a
                .depth
                .iter()
                .map(|&d| ((d as f64 * 1000.0 / scale as f64).round()) as u16)
                .collect();
            assert!(b.depth == mm, "frame {i}: depth differs");
            assert!((a.timestamp - b.timestamp).abs() < 1e-9, "frame {i}: time");
            let (pa, pb) = (a.gt_pose.expect("gt"), b.gt_pose.expect("gt"));
            assert!(
                (pa.to_homogeneous() - pb.to_homogeneous()).abs().max() < 1e-12,
                "frame {i}: pose"
            );
            assert!(b.labels.is_none());
        }
    }
    // `opengs synth --format rosbag2`'s path: write_dataset.
    let dir = tempfile::tempdir().expect("tempdir");
    write_dataset(
        &mut synthetic(2, MM_DEPTH_SCALE),
        dir.path(),
        DatasetFormat::Rosbag2,
        &mut |_, _| {},
    )
    .expect("write_dataset");
    let src = open(dir.path(), Rosbag2Options::default()).expect("open");
    assert_eq!(src.topics(), (RGB_TOPIC, DEPTH_TOPIC));
}

#[test]
fn our_bag_reads_in_python_rosbags() {
    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    let bag = dir.path().join("ours");
    let frames = 3;
    write_rosbag2(
        &mut synthetic(frames, MM_DEPTH_SCALE),
        &bag,
        ChunkCompression::Zstd,
        &mut |_, _| {},
    )
    .expect("write");
    let out = Command::new(&python)
        .arg(fixture("read_rosbag2.py"))
        .arg(&bag)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "rosbags cannot read our bag: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).expect("json");
    for (topic, ty) in [
        (RGB_TOPIC, "sensor_msgs/msg/Image"),
        (DEPTH_TOPIC, "sensor_msgs/msg/Image"),
        (CAMERA_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
        (POSE_TOPIC, "geometry_msgs/msg/PoseStamped"),
    ] {
        assert_eq!(v["topics"][topic]["type"], ty, "{topic}");
        assert_eq!(v["topics"][topic]["count"], frames, "{topic}");
    }
    let messages = v["messages"].as_array().expect("messages");
    let topics: Vec<&str> = messages
        .iter()
        .filter_map(|m| m["topic"].as_str())
        .collect();
    assert_eq!(messages.len(), 4 * frames, "rosbags read {topics:?}");
    let mut src = synthetic(frames, MM_DEPTH_SCALE);
    let k = src.intrinsics();
    for i in 0..frames {
        let f = src.frame(i).expect("frame");
        let ns = (f.timestamp * 1e9).round() as u64;
        let of = |topic: &str| {
            messages
                .iter()
                .filter(|m| m["topic"] == topic)
                .nth(i)
                .unwrap_or_else(|| panic!("{topic} message {i}"))
        };
        for topic in [RGB_TOPIC, DEPTH_TOPIC, CAMERA_INFO_TOPIC, POSE_TOPIC] {
            let m = of(topic);
            assert_eq!(
                (m["stamp_ns"].as_u64(), m["log_ns"].as_u64()),
                (Some(ns), Some(ns)),
                "{topic} {i}"
            );
        }
        let rgb = of(RGB_TOPIC);
        assert_eq!(
            (
                rgb["encoding"].as_str(),
                rgb["width"].as_u64(),
                rgb["step"].as_u64()
            ),
            (Some("rgb8"), Some(k.width as u64), Some(3 * k.width as u64))
        );
        assert_eq!(
            rgb["crc"].as_u64(),
            Some(crc32fast::hash(&f.rgb) as u64),
            "rgb {i}"
        );
        let depth = of(DEPTH_TOPIC);
        assert_eq!(depth["encoding"], "16UC1");
        let bytes: Vec<u8> = f.depth.iter().flat_map(|d| d.to_le_bytes()).collect();
        assert_eq!(
            depth["crc"].as_u64(),
            Some(crc32fast::hash(&bytes) as u64),
            "depth {i}"
        );
        let info = of(CAMERA_INFO_TOPIC);
        let kk: Vec<f64> = serde_json::from_value(info["k"].clone()).expect("k");
        assert_eq!((kk[0], kk[2], kk[4], kk[5]), (k.fx, k.cx, k.fy, k.cy));
        let pose: Vec<f64> = serde_json::from_value(of(POSE_TOPIC)["pose"].clone()).expect("pose");
        let p = f.gt_pose.expect("gt");
        let q = p.rotation.coords;
        let want = [
            p.translation.x,
            p.translation.y,
            p.translation.z,
            q[0],
            q[1],
            q[2],
            q[3],
        ];
        // serde_json's float parsing may be one ulp off Python's shortest repr.
        for (a, b) in pose.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "pose {i}: {pose:?} vs {want:?}");
        }
    }
}

#[test]
fn truncated_bags_name_the_topic_read_so_far() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bag = dir.path().join("cut");
    write_rosbag2(
        &mut synthetic(3, MM_DEPTH_SCALE),
        &bag,
        ChunkCompression::None,
        &mut |_, _| {},
    )
    .expect("write");
    let file = bag.join("cut_0.mcap");
    let bytes = read(&file);
    for keep in [bytes.len() / 2, bytes.len() * 9 / 10, 20] {
        std::fs::write(&file, &bytes[..keep]).expect("truncate");
        let e = err_text(open(&bag, Rosbag2Options::default()));
        assert!(
            e.contains("cut_0.mcap") && e.contains("truncated"),
            "{keep}: {e}"
        );
        if keep > 1000 {
            assert!(
                e.contains(&format!("{RGB_TOPIC} after message")),
                "{keep}: {e}"
            );
        }
    }
    std::fs::write(&file, b"not a bag").expect("write");
    let e = err_text(open(&file, Rosbag2Options::default()));
    assert!(e.contains("not an MCAP file"), "{e}");
    let e = err_text(open(&dir.path().join("missing"), Rosbag2Options::default()));
    assert!(e.contains("not found"), "{e}");
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).expect("dir");
    let e = err_text(open(&empty, Rosbag2Options::default()));
    assert!(e.contains("not a ROS 2 bag"), "{e}");
}

#[test]
fn a_tum_folder_converted_by_the_script_reads_as_the_tum_frames() {
    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    let tum = dir.path().join("tum");
    write_dataset(
        &mut synthetic(4, 5000.0),
        &tum,
        DatasetFormat::Tum,
        &mut |_, _| {},
    )
    .expect("write TUM");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/tum_to_rosbag2.py");
    for encoding in ["32FC1", "16UC1"] {
        let bag = dir.path().join(format!("bag_{encoding}"));
        let out = Command::new(&python)
            .arg(&script)
            .arg(&tum)
            .arg(&bag)
            .args(["--depth-encoding", encoding])
            .output()
            .expect("python runs");
        assert!(
            out.status.success(),
            "tum_to_rosbag2.py: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let mut a = open_dataset(&DatasetSpec::new(DatasetKind::Tum(tum.clone()))).expect("TUM");
        let mut b = open(&bag, Rosbag2Options::default()).expect("bag");
        assert_eq!((b.len(), b.intrinsics()), (a.len(), a.intrinsics()));
        for i in 0..a.len() {
            let (fa, fb) = (
                a.frame(i).expect("TUM frame"),
                b.frame(i).expect("bag frame"),
            );
            assert!(fa.rgb == fb.rgb, "{encoding} frame {i}: colour differs");
            // 32FC1 metres keep TUM's 5000 units/m exactly; 16UC1 rounds to the mm.
            let want: Vec<u16> = match encoding {
                "32FC1" => fa.depth.clone(),
                _ => fa
                    .depth
                    .iter()
                    .map(|&d| (d as f64 / 5.0).round() as u16)
                    .collect(),
            };
            assert!(fb.depth == want, "{encoding} frame {i}: depth differs");
            assert!((fa.timestamp - fb.timestamp).abs() < 1e-9, "frame {i}");
            let (pa, pb) = (fa.gt_pose.expect("gt"), fb.gt_pose.expect("gt"));
            assert!((pa.to_homogeneous() - pb.to_homogeneous()).abs().max() < 1e-12);
        }
    }
}
