//! synth → write → read: depth and labels identical, poses within 1e-6.

use approx::assert_relative_eq;
use opengs_datasets::replica::REPLICA_DEPTH_SCALE;
use opengs_datasets::{
    open_dataset, write_dataset, DatasetFormat, DatasetKind, DatasetSpec, DepthNoise, RgbdSource,
    SyntheticOptions, SyntheticSource,
};

const FRAMES: usize = 6;

fn synthetic(depth_scale: f32, noise: bool) -> SyntheticSource {
    SyntheticSource::new(SyntheticOptions {
        frames: Some(FRAMES),
        seed: 3,
        noise: noise.then(DepthNoise::default),
        depth_scale,
        ..SyntheticOptions::default()
    })
    .expect("synthetic source")
}

fn assert_same_dataset(
    expected: &mut dyn RgbdSource,
    loaded: &mut dyn RgbdSource,
    exact_rgb: bool,
) {
    assert_eq!(loaded.len(), expected.len());
    assert_eq!(loaded.intrinsics(), expected.intrinsics());
    assert_eq!(loaded.class_table(), expected.class_table());
    for i in 0..expected.len() {
        let a = expected.frame(i).expect("expected frame");
        let b = loaded.frame(i).expect("loaded frame");
        assert_eq!((b.width, b.height), (a.width, a.height));
        assert_eq!(b.depth_scale, a.depth_scale);
        assert!(a.depth == b.depth, "frame {i}: depth differs");
        assert!(a.labels == b.labels, "frame {i}: labels differ");
        let (pa, pb) = (a.gt_pose.expect("gt"), b.gt_pose.expect("gt"));
        assert_relative_eq!(pa.to_homogeneous(), pb.to_homogeneous(), epsilon = 1e-6);
        assert_relative_eq!(a.timestamp, b.timestamp, epsilon = 1e-6);
        if exact_rgb {
            assert!(a.rgb == b.rgb, "frame {i}: colour differs");
        } else {
            // JPEG: small mean error only.
            let err: f64 = a
                .rgb
                .iter()
                .zip(&b.rgb)
                .map(|(x, y)| (*x as f64 - *y as f64).abs())
                .sum::<f64>()
                / a.rgb.len() as f64;
            assert!(err < 4.0, "frame {i}: mean JPEG error {err}");
        }
    }
}

#[test]
fn tum_round_trip() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut calls = 0;
    write_dataset(
        &mut synthetic(5000.0, true),
        dir.path(),
        DatasetFormat::Tum,
        &mut |done, total| {
            calls += 1;
            assert!(done <= total);
        },
    )
    .expect("write");
    assert!(calls >= 1);
    let spec = DatasetSpec::new(DatasetKind::Tum(dir.path().to_path_buf()));
    let mut loaded = open_dataset(&spec).expect("open");
    assert_same_dataset(&mut synthetic(5000.0, true), loaded.as_mut(), true);
}

#[test]
fn replica_round_trip() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_dataset(
        &mut synthetic(REPLICA_DEPTH_SCALE, false),
        dir.path(),
        DatasetFormat::Replica,
        &mut |_, _| {},
    )
    .expect("write");
    let spec: DatasetSpec = format!("replica:{}", dir.path().display())
        .parse()
        .expect("spec");
    let mut loaded = open_dataset(&spec).expect("open");
    assert_same_dataset(
        &mut synthetic(REPLICA_DEPTH_SCALE, false),
        loaded.as_mut(),
        false,
    );
}

#[test]
fn replica_writer_rescales_tum_units() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_dataset(
        &mut synthetic(5000.0, false),
        dir.path(),
        DatasetFormat::Replica,
        &mut |_, _| {},
    )
    .expect("write");
    let spec = DatasetSpec::new(DatasetKind::Replica(dir.path().to_path_buf()));
    let mut loaded = open_dataset(&spec).expect("open");
    let a = synthetic(5000.0, false).frame(2).expect("frame");
    let b = loaded.frame(2).expect("frame");
    assert_eq!(b.depth_scale, REPLICA_DEPTH_SCALE);
    for (x, y) in a.depth.iter().zip(&b.depth) {
        let (mx, my) = (*x as f32 / 5000.0, *y as f32 / REPLICA_DEPTH_SCALE);
        assert!((mx - my).abs() < 2e-4, "{mx} vs {my}");
    }
}

#[test]
fn tum_reader_associates_by_timestamp() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_dataset(
        &mut synthetic(5000.0, false),
        dir.path(),
        DatasetFormat::Tum,
        &mut |_, _| {},
    )
    .expect("write");
    // Shift depth stamps by 20 ms and drop one depth frame: frame 3's colour then has no partner
    // within 10 ms, but all frames do within the default 80 ms.
    let depth_txt = dir.path().join("depth.txt");
    let shifted: String = std::fs::read_to_string(&depth_txt)
        .expect("depth.txt")
        .lines()
        .filter(|l| !l.contains("000003.png"))
        .map(|l| match l.split_once(' ') {
            Some((t, f)) if !l.starts_with('#') => {
                format!("{:.6} {f}\n", t.parse::<f64>().expect("t") + 0.02)
            }
            _ => format!("{l}\n"),
        })
        .collect();
    std::fs::write(&depth_txt, shifted).expect("write depth.txt");
    let spec = DatasetSpec::new(DatasetKind::Tum(dir.path().to_path_buf()));
    let mut src = open_dataset(&spec).expect("open");
    assert_eq!(src.len(), FRAMES);
    // Frame 3's colour pairs with the nearest remaining depth (frame 2's, 13 ms away).
    let f3 = src.frame(3).expect("frame");
    let expected = synthetic(5000.0, false).frame(2).expect("frame").depth;
    assert!(f3.depth == expected);
    let mut strict = spec.clone();
    strict.tum.max_time_diff = 0.01;
    // Every colour frame is ≥ 13 ms from any depth frame: nothing associates.
    let err = open_dataset(&strict)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(err.contains("rgb.txt") && err.contains("depth"), "{err}");
}

#[test]
fn plain_tum_sequence_without_extras() {
    let root = tempfile::tempdir().expect("tempdir");
    let dir = root.path().join("rgbd_dataset_freiburg1_synthetic");
    write_dataset(
        &mut synthetic(5000.0, false),
        &dir,
        DatasetFormat::Tum,
        &mut |_, _| {},
    )
    .expect("write");
    for extra in [
        "labels.txt",
        "groundtruth.txt",
        "intrinsics.txt",
        "classes.json",
    ] {
        std::fs::remove_file(dir.join(extra)).expect("rm");
    }
    let mut src = open_dataset(&DatasetSpec::new(DatasetKind::Tum(dir))).expect("open");
    let k = src.intrinsics();
    assert_eq!(
        (k.fx, k.fy, k.cx, k.cy, k.width, k.height),
        (517.3, 516.5, 318.6, 255.3, 640, 480)
    );
    assert!(src.class_table().is_empty());
    let f = src.frame(1).expect("frame");
    assert!(f.labels.is_none() && f.gt_pose.is_none());
    assert_eq!(
        f.depth,
        synthetic(5000.0, false).frame(1).expect("frame").depth
    );
}
