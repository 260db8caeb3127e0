//! A TUM folder a recorder is still writing (`opengs run --live`): `refresh` takes the frames
//! appended since the folder was opened, in order, and only complete ones: a colour frame
//! waits for a depth frame at or after its time, for its image files, and for the newline
//! that ends its line.

use std::io::Write;
use std::path::Path;

use opengs_datasets::{
    write_dataset, DatasetFormat, RgbdSource, SyntheticOptions, SyntheticSource, TumOptions,
    TumSource,
};

const FRAMES: usize = 6;

fn data_lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .expect("list")
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(String::from)
        .collect()
}

fn write_list(path: &Path, lines: &[String], partial: Option<&str>) {
    let mut f = std::fs::File::create(path).expect("create");
    for l in lines {
        writeln!(f, "{l}").expect("write");
    }
    if let Some(p) = partial {
        write!(f, "{p}").expect("write");
    }
}

#[test]
fn refresh_takes_appended_frames_once_they_are_complete() {
    let full = tempfile::tempdir().expect("tmp");
    let mut synthetic = SyntheticSource::new(SyntheticOptions {
        frames: Some(FRAMES),
        seed: 5,
        ..SyntheticOptions::default()
    })
    .expect("synthetic");
    write_dataset(
        &mut synthetic,
        full.path(),
        DatasetFormat::Tum,
        &mut |_, _| {},
    )
    .expect("write");
    let rgb = data_lines(&full.path().join("rgb.txt"));
    let depth = data_lines(&full.path().join("depth.txt"));
    let dir = full.path();
    let (rgb_txt, depth_txt) = (dir.join("rgb.txt"), dir.join("depth.txt"));

    // The recorder has written two frames.
    write_list(&rgb_txt, &rgb[..2], None);
    write_list(&depth_txt, &depth[..2], None);
    let mut source = TumSource::open(dir, TumOptions::default()).expect("open");
    assert_eq!(source.len(), 2);
    assert_eq!(source.refresh().expect("refresh"), 0, "nothing new");

    // Frame 2's colour line is there, its depth line not yet: it waits.
    write_list(&rgb_txt, &rgb[..3], None);
    assert_eq!(source.refresh().expect("refresh"), 0);
    // Its depth line is half written (no newline): still waits.
    write_list(
        &depth_txt,
        &depth[..2],
        Some(&depth[2][..depth[2].len() / 2]),
    );
    assert_eq!(source.refresh().expect("refresh"), 0);
    // Complete now.
    write_list(&depth_txt, &depth[..3], None);
    assert_eq!(source.refresh().expect("refresh"), 1);
    assert_eq!(source.len(), 3);

    // Frames 3 and 4 listed, but frame 3's colour image is not on disk yet: both wait,
    // so frames are never taken out of order.
    let image_3 = dir.join(rgb[3].split_whitespace().nth(1).expect("file"));
    let hidden = dir.join("hidden.png");
    std::fs::rename(&image_3, &hidden).expect("hide");
    write_list(&rgb_txt, &rgb[..5], None);
    write_list(&depth_txt, &depth[..5], None);
    assert_eq!(source.refresh().expect("refresh"), 0);
    std::fs::rename(&hidden, &image_3).expect("restore");
    assert_eq!(source.refresh().expect("refresh"), 2);

    // The rest; the frames read back are the synthetic ones, in order.
    write_list(&rgb_txt, &rgb, None);
    write_list(&depth_txt, &depth, None);
    assert_eq!(source.refresh().expect("refresh"), 1);
    assert_eq!(source.len(), FRAMES);
    for i in 0..FRAMES {
        let (a, b) = (
            synthetic.frame(i).expect("synthetic"),
            source.frame(i).expect("tum"),
        );
        assert!((a.timestamp - b.timestamp).abs() < 1e-6, "frame {i}");
        assert!(a.depth == b.depth, "frame {i}: depth differs");
    }
    assert_eq!(source.refresh().expect("refresh"), 0);
}

#[test]
fn a_list_that_becomes_unreadable_is_an_error_naming_it() {
    let dir = tempfile::tempdir().expect("tmp");
    let mut synthetic = SyntheticSource::new(SyntheticOptions {
        frames: Some(2),
        ..SyntheticOptions::default()
    })
    .expect("synthetic");
    write_dataset(
        &mut synthetic,
        dir.path(),
        DatasetFormat::Tum,
        &mut |_, _| {},
    )
    .expect("write");
    let mut source = TumSource::open(dir.path(), TumOptions::default()).expect("open");
    std::fs::write(
        dir.path().join("rgb.txt"),
        "12.5 rgb/a.png\nnot-a-time rgb/b.png\n",
    )
    .expect("write");
    let e = source.refresh().expect_err("a broken line").to_string();
    assert!(e.contains("rgb.txt:2") && e.contains("not-a-time"), "{e}");
}
