//! Property-based fuzz targets (stable Rust, seeded RNG) for the dataset text readers: TUM
//! `rgb.txt` / `depth.txt` / `labels.txt` ([`parse_file_list`]), `groundtruth.txt`
//! ([`parse_tum_trajectory`]), `intrinsics.txt` ([`parse_intrinsics`]); Replica `traj.txt`
//! ([`parse_replica_trajectory`]) and `cam_params.json` ([`parse_cam_params`]). Each parses
//! the text its file reader reads, so no files are written. And the ROS 2 bag reader
//! ([`Rosbag2Source`]): a small valid MCAP bag with its bytes mutated (flips, extreme
//! lengths and sizes, cuts, insertions, other encoding strings), written to a scratch file
//! and opened, every frame read; it must answer Ok or Err, never panic or hang.
//!
//! Inputs: valid files mutated at line, token and character level (extreme and malformed
//! numbers, comments, truncation, stray bytes), and random text. Properties: no parser panics
//! or hangs; a valid file parses to what was written; whatever is accepted is finite and
//! consistent (times sorted, rotations unit, cameras valid).
//!
//! Quick size (20,000 inputs a target) in `cargo test`; full size:
//! `OPENGS_FUZZ_CASES=1000000 cargo test --release -p opengs-datasets --test fuzz -- --nocapture`.
//! A failure names its seed: `OPENGS_FUZZ_SEED=<seed> OPENGS_FUZZ_CASES=1` replays it.

use std::path::Path;
use std::time::Duration;

use nalgebra::{UnitQuaternion, Vector3};
use opengs_datasets::replica::{parse_cam_params, parse_replica_trajectory};
use opengs_datasets::trajectory::parse_tum_trajectory;
use opengs_datasets::tum::{parse_file_list, parse_intrinsics};
use opengs_datasets::{
    write_rosbag2, ChunkCompression, DatasetError, InstanceClass, RgbdFrame, RgbdSource,
    Rosbag2Options, Rosbag2Source,
};
use opengs_geometry::Intrinsics;
use rand::Rng;

#[path = "../../../ipc_schema/tests/support/fuzz_driver.rs"]
mod fuzz_driver;
use fuzz_driver::{fuzz, pick, R};

// ---- Text mutations ----

/// Numbers a text reader must take or refuse: extremes, non-finite, malformed.
const NUMBERS: [&str; 34] = [
    "0",
    "-0",
    "1",
    "-1",
    "0.5",
    "1e308",
    "-1e308",
    "1.7976931348623157e308",
    "1e309",
    "-1e309",
    "1e200",
    "-1e200",
    "1e-320",
    "1e-200",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "infinity",
    "+1",
    "1.",
    ".5",
    "..",
    "1e",
    "0x10",
    "1_000",
    "\u{661}",
    "4294967296",
    "4294967295.5",
    "1e10",
    "640",
    "480.0",
    "-640",
    "1.0000001",
];

const JUNK: [&str; 14] = [
    "#", " # c", "\r", "\t", "\u{0}", "\u{feff}", "é", "🦀", "\n", "\n\n", " ", "x", "  \n#\n",
    "\u{2028}",
];

/// A huge number with a random sign: products of two overflow f64.
fn huge(rng: &mut R) -> String {
    let m = pick(rng, &["1e200", "1e300", "1e308", "1.5e154", "3e160"]);
    if rng.gen_bool(0.5) {
        format!("-{m}")
    } else {
        m.to_string()
    }
}

/// Replaces whitespace-separated tokens of one line (or of the whole text).
fn retoken(rng: &mut R, text: &str, with: &mut dyn FnMut(&mut R) -> String) -> String {
    let lines: Vec<&str> = text.split('\n').collect();
    let target = rng.gen_range(0..lines.len());
    let all = rng.gen_bool(0.2);
    let share = rng.gen_range(0.05..1.0);
    lines
        .iter()
        .enumerate()
        .map(|(i, line)| {
            if !all && i != target {
                return line.to_string();
            }
            line.split(' ')
                .map(|t| {
                    if !t.is_empty() && rng.gen_bool(share) {
                        with(rng)
                    } else {
                        t.to_string()
                    }
                })
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn mutate(rng: &mut R, text: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    let n = chars.len();
    let at = |rng: &mut R| rng.gen_range(0..=n);
    let s = |c: &[char]| c.iter().collect::<String>();
    match rng.gen_range(0..10) {
        0 => retoken(rng, text, &mut |rng| pick(rng, &NUMBERS).to_string()),
        // Many tokens of a line huge: overflow in products and determinants.
        1 => retoken(rng, text, &mut huge),
        2 => {
            let i = at(rng);
            s(&chars[..i])
        }
        3 => {
            let i = at(rng);
            let j = (i + rng.gen_range(0..8)).min(n);
            s(&chars[..i]) + &s(&chars[j..])
        }
        4 => {
            let i = at(rng);
            s(&chars[..i]) + pick(rng, &JUNK) + &s(&chars[i..])
        }
        5 => {
            let i = at(rng);
            s(&chars[..i]) + " " + pick(rng, &NUMBERS) + &s(&chars[i..])
        }
        6 => {
            let mut lines: Vec<&str> = text.split('\n').collect();
            let i = rng.gen_range(0..lines.len());
            match rng.gen_range(0..3) {
                0 => {
                    lines.remove(i);
                }
                1 => lines.insert(i, lines[i]),
                _ => {
                    let j = rng.gen_range(0..lines.len());
                    lines.swap(i, j);
                }
            }
            lines.join("\n")
        }
        7 if n > 0 => {
            let i = rng.gen_range(0..n);
            let c = char::from_u32(rng.gen_range(0..0x3000)).unwrap_or('?');
            s(&chars[..i]) + &c.to_string() + &s(&chars[i + 1..])
        }
        8 => text.replace('\n', "\r\n"),
        _ => random_text(rng),
    }
}

fn random_text(rng: &mut R) -> String {
    (0..rng.gen_range(0..40))
        .map(|_| match rng.gen_range(0..4) {
            0 => pick(rng, &NUMBERS).to_string(),
            1 => pick(rng, &JUNK).to_string(),
            2 => " ".into(),
            _ => char::from_u32(rng.gen_range(0..0x800))
                .unwrap_or('?')
                .to_string(),
        })
        .collect()
}

/// A valid text mutated 0–3 times (a quarter of the inputs unmutated).
fn mutated(rng: &mut R, valid: &str) -> (String, bool) {
    let k = if rng.gen_bool(0.25) {
        0
    } else {
        rng.gen_range(1..=3)
    };
    let mut text = valid.to_string();
    for _ in 0..k {
        text = mutate(rng, &text);
    }
    (text, k == 0)
}

/// Lines a reader reads: non-empty, not a comment.
fn data_lines(text: &str) -> usize {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .count()
}

fn comment_or_blank(rng: &mut R) -> &'static str {
    pick(rng, &["# a comment", "", "   ", "#", "# 1 2 3"])
}

fn number(rng: &mut R, lo: f64, hi: f64) -> f64 {
    rng.gen_range(lo..hi)
}

fn error_renders(e: &DatasetError) {
    assert!(!e.to_string().is_empty());
}

fn unit_rotation(q: &UnitQuaternion<f64>) -> bool {
    let v = q.quaternion().coords;
    v.iter().all(|x| x.is_finite()) && (v.norm() - 1.0).abs() < 1e-6
}

fn random_rotation(rng: &mut R) -> UnitQuaternion<f64> {
    UnitQuaternion::from_scaled_axis(Vector3::new(
        number(rng, -3.0, 3.0),
        number(rng, -3.0, 3.0),
        number(rng, -3.0, 3.0),
    ))
}

// ---- Targets ----

/// `rgb.txt` / `depth.txt` / `labels.txt`: `timestamp filename` lines.
fn file_list_case(rng: &mut R) -> bool {
    let mut valid = String::new();
    let mut expected = Vec::new();
    for _ in 0..rng.gen_range(0..8) {
        if rng.gen_bool(0.2) {
            valid += comment_or_blank(rng);
        } else {
            let t = number(rng, 0.0, 2e9);
            let name = pick(
                rng,
                &[
                    "rgb/1.png",
                    "depth/2.png",
                    "ä b.png",
                    "/abs/x.png",
                    "../up.png",
                ],
            );
            valid += &format!("{t:.6} {name}");
            expected.push(format!("{t:.6}").parse::<f64>().expect("formatted"));
        }
        valid.push('\n');
    }
    let (text, unmutated) = mutated(rng, &valid);
    let dir = Path::new("/data/tum");
    let r = parse_file_list(&text, dir, &dir.join("rgb.txt"));
    if unmutated {
        let list = r.as_ref().expect("valid list");
        expected.sort_by(f64::total_cmp);
        let times: Vec<f64> = list.iter().map(|(t, _)| *t).collect();
        assert_eq!(times, expected);
    }
    match r {
        Err(e) => {
            error_renders(&e);
            false
        }
        Ok(list) => {
            assert_eq!(list.len(), data_lines(&text));
            assert!(list.iter().all(|(t, _)| t.is_finite()));
            assert!(list.windows(2).all(|w| w[0].0 <= w[1].0), "sorted by time");
            true
        }
    }
}

/// `groundtruth.txt`: `timestamp tx ty tz qx qy qz qw` lines.
fn groundtruth_case(rng: &mut R) -> bool {
    let mut valid = String::new();
    let mut count = 0;
    for _ in 0..rng.gen_range(0..8) {
        if rng.gen_bool(0.2) {
            valid += comment_or_blank(rng);
        } else {
            let q = random_rotation(rng).into_inner().coords;
            // Quaternions need not be unit in the file: the reader normalises them.
            let s = number(rng, 0.5, 2.0);
            valid += &format!(
                "{:.6} {} {} {} {} {} {} {}",
                number(rng, 0.0, 2e9),
                number(rng, -10.0, 10.0),
                number(rng, -10.0, 10.0),
                number(rng, -10.0, 10.0),
                q.x * s,
                q.y * s,
                q.z * s,
                q.w * s
            );
            if rng.gen_bool(0.1) {
                valid += " # inline comment";
            }
            count += 1;
        }
        valid.push('\n');
    }
    let (text, unmutated) = mutated(rng, &valid);
    let r = parse_tum_trajectory(&text, Path::new("groundtruth.txt"));
    if unmutated {
        assert_eq!(r.as_ref().expect("valid trajectory").len(), count);
    }
    match r {
        Err(e) => {
            error_renders(&e);
            false
        }
        Ok(poses) => {
            assert!(poses.len() <= data_lines(&text));
            assert!(poses.windows(2).all(|w| w[0].0 <= w[1].0), "sorted by time");
            for (t, p) in &poses {
                assert!(t.is_finite());
                assert!(p.translation.vector.iter().all(|x| x.is_finite()));
                assert!(unit_rotation(&p.rotation), "rotation {:?}", p.rotation);
            }
            true
        }
    }
}

/// `intrinsics.txt`: `fx fy cx cy width height`.
fn intrinsics_case(rng: &mut R) -> bool {
    let mut valid = String::new();
    if rng.gen_bool(0.3) {
        valid += "# fx fy cx cy width height\n";
    }
    let (w, h) = (rng.gen_range(1..4000u32), rng.gen_range(1..4000u32));
    let (fx, fy) = (number(rng, 1.0, 2000.0), number(rng, 1.0, 2000.0));
    let (cx, cy) = (number(rng, -10.0, 4000.0), number(rng, -10.0, 4000.0));
    valid += &format!("{fx} {fy} {cx} {cy} {w} {h}\n");
    if rng.gen_bool(0.2) {
        valid += "\n# trailing\n";
    }
    let (text, unmutated) = mutated(rng, &valid);
    let r = parse_intrinsics(&text, Path::new("intrinsics.txt"));
    if unmutated {
        let k = r.as_ref().expect("valid intrinsics");
        assert_eq!(
            (k.fx, k.fy, k.cx, k.cy, k.width, k.height),
            (fx, fy, cx, cy, w, h)
        );
    }
    match r {
        Err(e) => {
            error_renders(&e);
            false
        }
        Ok(k) => {
            assert!(k.validate().is_ok(), "{k:?}");
            assert!(k.width >= 1 && k.height >= 1);
            true
        }
    }
}

/// Replica `traj.txt`: a row-major 4×4 camera-to-world matrix a line.
fn replica_trajectory_case(rng: &mut R) -> bool {
    let mut valid = String::new();
    let mut count = 0;
    for _ in 0..rng.gen_range(0..6) {
        if rng.gen_bool(0.1) {
            valid += comment_or_blank(rng);
        } else {
            let r = random_rotation(rng).to_rotation_matrix().into_inner();
            let t: [f64; 3] = std::array::from_fn(|_| number(rng, -10.0, 10.0));
            let mut v = Vec::with_capacity(16);
            for i in 0..3 {
                v.extend([r[(i, 0)], r[(i, 1)], r[(i, 2)], t[i]]);
            }
            v.extend([0.0, 0.0, 0.0, 1.0]);
            let toks: Vec<String> = v.iter().map(|x| x.to_string()).collect();
            valid += &toks.join(" ");
            count += 1;
        }
        valid.push('\n');
    }
    let (text, unmutated) = mutated(rng, &valid);
    let r = parse_replica_trajectory(&text, Path::new("traj.txt"));
    if unmutated {
        assert_eq!(r.as_ref().expect("valid traj.txt").len(), count);
    }
    match r {
        Err(e) => {
            error_renders(&e);
            false
        }
        Ok(poses) => {
            assert_eq!(poses.len(), data_lines(&text));
            for p in &poses {
                assert!(p.translation.vector.iter().all(|x| x.is_finite()));
                assert!(unit_rotation(&p.rotation), "rotation {:?}", p.rotation);
            }
            true
        }
    }
}

/// JSON values a `cam_params.json` field must take or refuse.
const JSON_VALUES: [&str; 22] = [
    "0",
    "-1",
    "1",
    "1.5",
    "600.0",
    "1e400",
    "-1e400",
    "1e39",
    "4294967296",
    "4294967295",
    "18446744073709551616",
    "null",
    "true",
    "\"600\"",
    "[]",
    "{}",
    "NaN",
    "Infinity",
    "-0",
    "1e-320",
    "6553.5",
    "0.000001",
];

const KEYS: [&str; 7] = ["w", "h", "fx", "fy", "cx", "cy", "scale"];

/// Replica `cam_params.json`: `{"camera": {w, h, fx, fy, cx, cy, scale}}`.
fn cam_params_case(rng: &mut R) -> bool {
    let (w, h) = (rng.gen_range(1..4000u32), rng.gen_range(1..4000u32));
    let mut fields: Vec<(String, String)> = vec![
        ("w".into(), w.to_string()),
        ("h".into(), h.to_string()),
        ("fx".into(), number(rng, 1.0, 2000.0).to_string()),
        ("fy".into(), number(rng, 1.0, 2000.0).to_string()),
        ("cx".into(), number(rng, 0.0, 4000.0).to_string()),
        ("cy".into(), number(rng, 0.0, 4000.0).to_string()),
        ("scale".into(), number(rng, 1.0, 10_000.0).to_string()),
    ];
    // Structured edits first (fields, values), then text edits.
    let mut edits = 0;
    for _ in 0..rng.gen_range(0..=2) {
        edits += 1;
        let i = rng.gen_range(0..fields.len());
        match rng.gen_range(0..4) {
            0 => fields[i].1 = pick(rng, &JSON_VALUES).to_string(),
            1 => {
                fields.remove(i);
            }
            2 => fields.push((pick(rng, &KEYS).into(), pick(rng, &JSON_VALUES).into())),
            _ => fields.insert(i, ("extra".into(), "[1, {\"a\": null}]".into())),
        }
    }
    let body: Vec<String> = fields
        .iter()
        .map(|(k, v)| format!("\"{k}\": {v}"))
        .collect();
    let valid = format!(
        "{{\n  \"camera\": {{\n    {}\n  }}\n}}\n",
        body.join(",\n    ")
    );
    let (text, unmutated) = if rng.gen_bool(0.5) {
        (valid, true)
    } else {
        mutated(rng, &valid)
    };
    let r = parse_cam_params(&text, Path::new("cam_params.json"));
    if unmutated && edits == 0 {
        let (k, _) = r.as_ref().expect("valid cam_params.json");
        assert_eq!((k.width, k.height), (w, h));
    }
    match r {
        Err(e) => {
            error_renders(&e);
            false
        }
        Ok((k, scale)) => {
            assert!(k.validate().is_ok(), "{k:?}");
            assert!(scale.is_finite() && scale > 0.0);
            true
        }
    }
}

/// Runs `f` on a thread; fails if it takes longer than `limit` (a hang).
fn within<T: Send + 'static>(limit: Duration, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || tx.send(f()));
    rx.recv_timeout(limit).expect("finishes (does not hang)")
}

/// Found by `fuzz_replica_trajectory`: huge entries made the check NaN, and from_matrix hung.
#[test]
fn replica_trajectory_with_overflowing_rotation_is_refused() {
    let line =
        "-1e200 1e200 -1e200 -2.37 -0.26 0.87 -0.42 -3.32 -0.41 -3e160 -3e160 1e308 0 0 -3e160 1";
    let r = within(Duration::from_secs(10), move || {
        parse_replica_trajectory(line, Path::new("traj.txt")).map_err(|e| e.to_string())
    });
    let e = r.expect_err("not a rotation");
    assert!(
        e.contains("traj.txt:1: rotation part is not orthonormal"),
        "{e}"
    );
}

#[test]
fn fuzz_tum_file_list() {
    fuzz("tum::parse_file_list (rgb.txt, depth.txt)", file_list_case);
}

#[test]
fn fuzz_tum_groundtruth() {
    fuzz(
        "trajectory::parse_tum_trajectory (groundtruth.txt)",
        groundtruth_case,
    );
}

#[test]
fn fuzz_tum_intrinsics() {
    fuzz("tum::parse_intrinsics (intrinsics.txt)", intrinsics_case);
}

#[test]
fn fuzz_replica_trajectory() {
    fuzz(
        "replica::parse_replica_trajectory (traj.txt)",
        replica_trajectory_case,
    );
}

#[test]
fn fuzz_replica_cam_params() {
    fuzz(
        "replica::parse_cam_params (cam_params.json)",
        cam_params_case,
    );
}

// ---- ROS 2 bags ----

/// Three 8x6 frames with ground truth: a small valid bag.
struct TinySource;

impl RgbdSource for TinySource {
    fn name(&self) -> String {
        "tiny".into()
    }
    fn intrinsics(&self) -> Intrinsics {
        Intrinsics::new(6.0, 6.5, 3.5, 2.5, 8, 6)
    }
    fn len(&self) -> usize {
        3
    }
    fn frame_rate(&self) -> f64 {
        30.0
    }
    fn frame(&mut self, index: usize) -> Result<RgbdFrame, DatasetError> {
        Ok(RgbdFrame {
            index,
            timestamp: 1.0 + index as f64 / 30.0,
            width: 8,
            height: 6,
            rgb: (0..144).map(|i| (i * 7 + index) as u8).collect(),
            depth: (0..48).map(|i| (i * 100 + index) as u16).collect(),
            depth_scale: 1000.0,
            gt_pose: Some(opengs_geometry::Pose::translation(index as f64, 0.5, -1.0)),
            labels: None,
        })
    }
    fn class_table(&self) -> Vec<InstanceClass> {
        Vec::new()
    }
}

/// The bytes of TinySource's bag (uncompressed chunks, so mutations reach the messages),
/// and a scratch directory the mutated bags are written to.
fn valid_bag() -> &'static (Vec<u8>, tempfile::TempDir) {
    static BAG: std::sync::OnceLock<(Vec<u8>, tempfile::TempDir)> = std::sync::OnceLock::new();
    BAG.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir");
        let bag = dir.path().join("tiny");
        write_rosbag2(
            &mut TinySource,
            &bag,
            ChunkCompression::None,
            &mut |_, _| {},
        )
        .expect("tiny bag");
        let bytes = std::fs::read(bag.join("tiny_0.mcap")).expect("read bag");
        (bytes, dir)
    })
}

const EXTREME_U64: [u64; 8] = [0, 1, 9, 255, u32::MAX as u64, 1 << 40, 1 << 63, u64::MAX];
const EXTREME_U32: [u32; 8] = [0, 1, 3, 7, 8, 0x8000_0000, 0xffff_fff0, u32::MAX];
const ENCODINGS: [&str; 10] = [
    "rgb8",
    "bgr8",
    "rgba8",
    "bgra8",
    "mono8",
    "16UC1",
    "32FC1",
    "yuv422",
    "",
    "16UC1\0junk",
];

fn mutate_bytes(rng: &mut R, b: &mut Vec<u8>) {
    let n = b.len();
    if n == 0 {
        b.extend((0..rng.gen_range(0..64)).map(|_| rng.gen::<u8>()));
        return;
    }
    let at = rng.gen_range(0..n);
    match rng.gen_range(0..9) {
        0 => {
            for _ in 0..rng.gen_range(1..8) {
                let i = rng.gen_range(0..n);
                b[i] ^= 1 << rng.gen_range(0..8);
            }
        }
        1 => b[at] = pick(rng, &[0u8, 0xff, 0x7f, 0x80, 1]),
        2 if at + 8 <= n => b[at..at + 8].copy_from_slice(&pick(rng, &EXTREME_U64).to_le_bytes()),
        3 if at + 4 <= n => b[at..at + 4].copy_from_slice(&pick(rng, &EXTREME_U32).to_le_bytes()),
        4 => b.truncate(at),
        5 => {
            let end = (at + rng.gen_range(1..64)).min(n);
            b.drain(at..end);
        }
        6 => {
            let end = (at + rng.gen_range(1..64)).min(n);
            let copy = b[at..end].to_vec();
            let to = rng.gen_range(0..=n);
            b.splice(to..to, copy);
        }
        7 => {
            let from = pick(rng, &["rgb8", "16UC1"]);
            let to = pick(rng, &ENCODINGS);
            if let Some(i) = b.windows(from.len()).position(|w| w == from.as_bytes()) {
                b.splice(i..i + from.len(), to.bytes());
            }
        }
        _ => {
            let i = rng.gen_range(0..n);
            b[i] = rng.gen();
        }
    }
}

/// A mutated tiny bag opened and every frame read: Ok or Err, never a panic; what is
/// accepted has buffers of the camera's size.
fn rosbag2_case(rng: &mut R) -> bool {
    let (valid, dir) = valid_bag();
    let mut bytes = valid.clone();
    for _ in 0..rng.gen_range(1..=3) {
        mutate_bytes(rng, &mut bytes);
    }
    let path = dir.path().join("fuzz.mcap");
    std::fs::write(&path, &bytes).expect("scratch file");
    let Ok(mut src) = Rosbag2Source::open(&path, Rosbag2Options::default()) else {
        return false;
    };
    let k = src.intrinsics();
    assert!(k.validate().is_ok(), "{k:?}");
    for i in 0..src.len() {
        if let Ok(f) = src.frame(i) {
            assert!(
                f.check_buffers(&k).is_ok(),
                "frame {i}: {:?}",
                f.check_buffers(&k)
            );
            assert!(f.timestamp.is_finite());
        }
    }
    true
}

#[test]
fn the_tiny_bag_reads_back() {
    let (valid, dir) = valid_bag();
    let path = dir.path().join("valid.mcap");
    std::fs::write(&path, valid).expect("write");
    let mut src = Rosbag2Source::open(&path, Rosbag2Options::default()).expect("valid bag");
    assert_eq!(src.len(), 3);
    let f = src.frame(2).expect("frame");
    let want = TinySource.frame(2).expect("frame");
    assert_eq!((f.rgb, f.depth), (want.rgb, want.depth));
}

#[test]
fn fuzz_rosbag2() {
    fuzz("rosbag2::Rosbag2Source (MCAP bag bytes)", rosbag2_case);
}
