//! Bad input gives a `DatasetError` naming the file (and line where there is one).

use std::path::Path;

use opengs_datasets::{
    open_dataset, write_dataset, DatasetError, DatasetFormat, DatasetKind, DatasetSpec, RgbdSource,
    SyntheticOptions, SyntheticSource,
};

fn write_small(dir: &Path, format: DatasetFormat) {
    let mut src = SyntheticSource::new(SyntheticOptions {
        frames: Some(2),
        ..SyntheticOptions::default()
    })
    .expect("source");
    write_dataset(&mut src, dir, format, &mut |_, _| {}).expect("write");
}

fn tum(dir: &Path) -> Result<Box<dyn RgbdSource>, DatasetError> {
    open_dataset(&DatasetSpec::new(DatasetKind::Tum(dir.to_path_buf())))
}

fn replica(dir: &Path) -> Result<Box<dyn RgbdSource>, DatasetError> {
    open_dataset(&DatasetSpec::new(DatasetKind::Replica(dir.to_path_buf())))
}

fn message<T>(r: Result<T, DatasetError>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

/// Replaces line `n` (1-based, counting comments) of a text file.
fn replace_line(path: &Path, n: usize, text: &str) {
    let body = std::fs::read_to_string(path).expect("read");
    let lines: Vec<String> = body
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i + 1 == n {
                text.to_string()
            } else {
                l.to_string()
            }
        })
        .collect();
    std::fs::write(path, lines.join("\n") + "\n").expect("write");
}

#[test]
fn missing_directory() {
    let m = message(tum(Path::new("/nonexistent/opengs-tum")));
    assert!(
        m.contains("/nonexistent/opengs-tum") && m.contains("not found"),
        "{m}"
    );
    let m = message(replica(Path::new("/nonexistent/opengs-replica")));
    assert!(m.contains("/nonexistent/opengs-replica"), "{m}");
}

#[test]
fn missing_index_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Tum);
    std::fs::remove_file(dir.path().join("depth.txt")).expect("rm");
    let m = message(tum(dir.path()));
    assert!(m.contains("depth.txt") && m.contains("not found"), "{m}");

    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Replica);
    std::fs::remove_file(dir.path().join("traj.txt")).expect("rm");
    let m = message(replica(dir.path()));
    assert!(m.contains("traj.txt"), "{m}");
}

#[test]
fn missing_image_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Tum);
    std::fs::remove_file(dir.path().join("rgb/000001.png")).expect("rm");
    // Found when the dataset is opened, so a run fails before any stage starts.
    let m = message(tum(dir.path()));
    assert!(
        m.contains("rgb/000001.png") && m.contains("not found (listed in rgb.txt)"),
        "{m}"
    );

    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Replica);
    std::fs::remove_file(dir.path().join("results/depth000001.png")).expect("rm");
    let m = message(replica(dir.path()));
    assert!(
        m.contains("depth000001.png") && m.contains("not found"),
        "{m}"
    );
}

#[test]
fn empty_lists_and_impossible_cameras_are_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Tum);
    std::fs::write(dir.path().join("rgb.txt"), "# timestamp filename\n").expect("write");
    let m = message(tum(dir.path()));
    assert!(
        m.contains("rgb.txt") && m.contains("lists no images"),
        "{m}"
    );

    for bad in ["0 525 319.5 239.5 640 480", "525 inf 319.5 239.5 640 480"] {
        let dir = tempfile::tempdir().expect("tempdir");
        write_small(dir.path(), DatasetFormat::Tum);
        replace_line(&dir.path().join("intrinsics.txt"), 2, bad);
        let m = message(tum(dir.path()));
        assert!(m.contains("intrinsics.txt:2:"), "{bad}: {m}");
    }
    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Tum);
    replace_line(
        &dir.path().join("intrinsics.txt"),
        2,
        "525 525 319.5 239.5 320 240",
    );
    let m = message(tum(dir.path()));
    assert!(
        m.contains("640x480") && m.contains("intrinsics.txt is 320x240"),
        "{m}"
    );

    // Replica without cam_params.json: the default camera is named, not a label image.
    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Replica);
    std::fs::remove_file(dir.path().join("cam_params.json")).expect("rm");
    let m = message(replica(dir.path()));
    assert!(
        m.contains("frame000000.jpg") && m.contains("no cam_params.json"),
        "{m}"
    );
    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Replica);
    let params = dir.path().join("cam_params.json");
    let text = std::fs::read_to_string(&params).expect("read");
    let text = text.replacen("\"fx\": 525.0", "\"fx\": 0.0", 1);
    std::fs::write(&params, text).expect("write");
    let m = message(replica(dir.path()));
    assert!(m.contains("cam_params.json") && m.contains("fx = 0"), "{m}");
}

#[test]
fn corrupt_png_and_jpeg() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Tum);
    std::fs::write(
        dir.path().join("depth/000000.png"),
        b"\x89PNG\r\n\x1a\nnot really",
    )
    .expect("write");
    let m = message(tum(dir.path()).expect("open").frame(0));
    assert!(
        m.contains("depth/000000.png") && m.contains("decode"),
        "{m}"
    );

    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Replica);
    std::fs::write(
        dir.path().join("results/frame000001.jpg"),
        b"\xff\xd8\xff\xe0garbage",
    )
    .expect("write");
    let m = message(replica(dir.path()).expect("open").frame(1));
    assert!(m.contains("frame000001.jpg"), "{m}");
}

#[test]
fn inconsistent_image_sizes() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Tum);
    let small = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(320, 240);
    small
        .save(dir.path().join("depth/000001.png"))
        .expect("save");
    let m = message(tum(dir.path()).expect("open").frame(1));
    assert!(
        m.contains("depth/000001.png") && m.contains("320x240") && m.contains("640x480"),
        "{m}"
    );

    // An 8-bit depth image is not silently rescaled.
    let eight = image::ImageBuffer::<image::Luma<u8>, Vec<u8>>::new(640, 480);
    eight
        .save(dir.path().join("depth/000000.png"))
        .expect("save");
    let m = message(tum(dir.path()).expect("open").frame(0));
    assert!(
        m.contains("depth/000000.png") && m.contains("16-bit"),
        "{m}"
    );
}

#[test]
fn unparsable_lines_name_file_and_line() {
    for (file, line, text) in [
        ("rgb.txt", 3, "0.033333"),
        ("depth.txt", 2, "zero depth/000000.png"),
        ("groundtruth.txt", 3, "0.033 1 2 3 0 0 0"),
        ("groundtruth.txt", 2, "0.0 1 2 x 0 0 0 1"),
    ] {
        let dir = tempfile::tempdir().expect("tempdir");
        write_small(dir.path(), DatasetFormat::Tum);
        replace_line(&dir.path().join(file), line, text);
        let m = message(tum(dir.path()));
        assert!(m.contains(&format!("{file}:{line}:")), "{file}: {m}");
    }
    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Replica);
    replace_line(&dir.path().join("traj.txt"), 2, "1 0 0 0 0 1 0 0 0 0 1");
    let m = message(replica(dir.path()));
    assert!(m.contains("traj.txt:2:") && m.contains("16 numbers"), "{m}");
    replace_line(
        &dir.path().join("traj.txt"),
        1,
        "2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1",
    );
    let m = message(replica(dir.path()));
    assert!(
        m.contains("traj.txt:1:") && m.contains("orthonormal"),
        "{m}"
    );
}

#[test]
fn bad_intrinsics_and_classes_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Tum);
    replace_line(
        &dir.path().join("intrinsics.txt"),
        2,
        "525 525 319.5 239.5 640",
    );
    let m = message(tum(dir.path()));
    assert!(m.contains("intrinsics.txt:2:"), "{m}");

    let dir = tempfile::tempdir().expect("tempdir");
    write_small(dir.path(), DatasetFormat::Tum);
    std::fs::write(
        dir.path().join("classes.json"),
        "{\"1\": \"floor\",\n \"x\": 3}",
    )
    .expect("write");
    let m = message(tum(dir.path()));
    assert!(m.contains("classes.json:2:"), "{m}");
}

#[test]
fn missing_trajectory_for_synthetic() {
    let spec = DatasetSpec {
        synthetic: SyntheticOptions {
            trajectory: Some("/nonexistent/traj.txt".into()),
            ..SyntheticOptions::default()
        },
        ..DatasetSpec::default()
    };
    let m = message(open_dataset(&spec));
    assert!(m.contains("/nonexistent/traj.txt"), "{m}");
}

#[test]
fn bad_spec_strings() {
    let m = message("webcam".parse::<DatasetSpec>());
    assert!(m.contains("synthetic") && m.contains("replica:DIR"), "{m}");
    let m = message("replica:".parse::<DatasetSpec>());
    assert!(m.contains("replica:DIR"), "{m}");
    let m = message("jpeg".parse::<DatasetFormat>());
    assert!(m.contains("tum") && m.contains("replica"), "{m}");
}
