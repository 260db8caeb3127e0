//! Timing of the segmenters on synthetic 640×480 frames: the weight-free
//! ones, and (cargo feature `onnx`, ONNX Runtime available) the tiny-model
//! ensemble — MobileSAMv2-style box prompts plus tagger and detector on the
//! test fixtures, i.e. the pipeline's own overhead without real weights.

use std::time::Instant;

use opengs_datasets::{open_dataset, DatasetKind, DatasetSpec, RgbdFrame};

use crate::{PerceptionError, Segmenter, SegmenterInput, SegmenterKind};

/// Median and minimum wall time of one segmenter over the bench frames.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentTiming {
    /// Segmenter as printed (`classic`, `prior`, `tiny-ensemble`).
    pub name: String,
    pub frames: usize,
    pub median_ms: f64,
    pub min_ms: f64,
    /// Segments per frame, and of those the ones with a class name (means).
    pub segments: f64,
    pub classified: f64,
}

struct BenchFrames {
    frames: Vec<RgbdFrame>,
    intrinsics: opengs_geometry::Intrinsics,
    classes: Vec<opengs_datasets::InstanceClass>,
}

/// `frames` synthetic frames spread over the loop of the suite's `scene`
/// (0 = the fixed room).
fn bench_frames(frames: usize, scene: u64) -> Result<BenchFrames, PerceptionError> {
    let mut spec = DatasetSpec::new(DatasetKind::Synthetic);
    spec.synthetic.scene = scene;
    let mut source = open_dataset(&spec)?;
    let step = (source.len() / frames.max(1)).max(1);
    let list = (0..frames.max(1))
        .map(|i| source.frame((i * step) % source.len()))
        .collect::<Result<_, _>>()?;
    Ok(BenchFrames {
        frames: list,
        intrinsics: source.intrinsics(),
        classes: source.class_table(),
    })
}

/// Segments every frame `repeats` times after one warm-up run per frame.
fn time_one(
    name: &str,
    segmenter: &mut dyn Segmenter,
    bench: &BenchFrames,
    repeats: usize,
) -> Result<SegmentTiming, PerceptionError> {
    let mut times = Vec::new();
    let (mut segments, mut classified) = (0usize, 0usize);
    for frame in &bench.frames {
        let input = SegmenterInput::from_frame(frame, bench.intrinsics, &bench.classes);
        let warm = segmenter.segment(&input)?;
        segments += warm.labels.len();
        classified += warm.labels.iter().filter(|l| l.class.is_some()).count();
        for _ in 0..repeats.max(1) {
            let start = Instant::now();
            let out = segmenter.segment(&input)?;
            times.push(start.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box(out);
        }
    }
    times.sort_unstable_by(f64::total_cmp);
    Ok(SegmentTiming {
        name: name.to_string(),
        frames: bench.frames.len(),
        median_ms: times[times.len() / 2],
        min_ms: times[0],
        segments: segments as f64 / bench.frames.len() as f64,
        classified: classified as f64 / bench.frames.len() as f64,
    })
}

/// Times geometry, classic and prior on `frames` synthetic frames spread over the loop,
/// each segmented `repeats` times (the first run of each frame is a warm-up).
pub fn time_segmenters(
    frames: usize,
    repeats: usize,
) -> Result<Vec<SegmentTiming>, PerceptionError> {
    let bench = bench_frames(frames, 0)?;
    [
        SegmenterKind::Geometry,
        SegmenterKind::Classic,
        SegmenterKind::Prior,
    ]
    .into_iter()
    .map(|kind| time_one(kind.as_str(), kind.create()?.as_mut(), &bench, repeats))
    .collect()
}

/// Times the tiny-model ensemble (encoder, box proposals, box-prompted
/// decoder, tagger, detector, mask-box matching) on the same frames.
#[cfg(feature = "onnx")]
pub fn time_tiny_ensemble(frames: usize, repeats: usize) -> Result<SegmentTiming, PerceptionError> {
    let dir = tiny::write_fixtures()?;
    let result = (|| {
        let mut segmenter = SegmenterKind::MobileSamV2.create_with(&tiny::options(&dir.0))?;
        time_one(
            "tiny-ensemble",
            segmenter.as_mut(),
            &bench_frames(frames, 0)?,
            repeats,
        )
    })();
    drop(dir);
    result
}

/// Prints the median milliseconds per 640×480 frame of each segmenter; the
/// tiny-model ensemble too when built with `onnx` and ONNX Runtime loads
/// (otherwise a line says why it is left out).
pub fn print_segment_bench(frames: usize, repeats: usize) -> Result<(), PerceptionError> {
    let print = |t: &SegmentTiming| {
        println!(
            "segment/{:<13} median {:7.2} ms  min {:7.2} ms  per 640x480 frame ({:.1} segments, {:.1} with a class; {} frames x {} runs, {} cores available)",
            t.name,
            t.median_ms,
            t.min_ms,
            t.segments,
            t.classified,
            t.frames,
            repeats.max(1),
            available_cores(),
        )
    };
    for t in time_segmenters(frames, repeats)? {
        print(&t);
    }
    #[cfg(feature = "onnx")]
    match time_tiny_ensemble(frames, repeats) {
        Ok(t) => {
            print(&t);
            println!(
                "  (tiny-ensemble = MobileSAMv2 box prompts + RAM-style tagger + YOLO-World-style detector on the test fixtures: pipeline overhead, not model speed)"
            );
        }
        Err(PerceptionError::Unavailable { reason, .. }) => {
            println!("segment/tiny-ensemble skipped: {reason}")
        }
        Err(e) => return Err(e),
    }
    #[cfg(not(feature = "onnx"))]
    println!(
        "segment/tiny-ensemble skipped: built without the `onnx` feature (--features opengs-perception/onnx)"
    );
    Ok(())
}

/// Per-frame quality of one segmenter over the bench frames (means), and
/// its median time.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentQuality {
    pub name: String,
    pub frames: usize,
    pub miou: f64,
    pub split_share: f64,
    pub merge_share: f64,
    pub segments: f64,
    pub median_ms: f64,
}

/// Scores geometry, classic and prior on `frames` frames of `scene`
/// against the ground-truth instances ([`crate::quality`]).
pub fn segment_quality(frames: usize, scene: u64) -> Result<Vec<SegmentQuality>, PerceptionError> {
    let bench = bench_frames(frames, scene)?;
    let kinds = [
        SegmenterKind::Geometry,
        SegmenterKind::Classic,
        SegmenterKind::Prior,
    ];
    kinds
        .into_iter()
        .map(|kind| {
            let mut segmenter = kind.create()?;
            let mut times = Vec::new();
            let mut scores = Vec::new();
            for frame in &bench.frames {
                let input = SegmenterInput::from_frame(frame, bench.intrinsics, &bench.classes);
                let truth = input.gt_labels.ok_or(PerceptionError::MissingLabels)?;
                let start = Instant::now();
                let out = segmenter.segment(&input)?;
                times.push(start.elapsed().as_secs_f64() * 1e3);
                scores.extend(crate::quality::frame_quality(&out.label_map, truth));
            }
            times.sort_unstable_by(f64::total_cmp);
            let n = scores.len().max(1) as f64;
            let mean =
                |f: fn(&crate::quality::FrameQuality) -> f64| scores.iter().map(f).sum::<f64>() / n;
            Ok(SegmentQuality {
                name: kind.as_str().to_string(),
                frames: scores.len(),
                miou: mean(|q| q.miou),
                split_share: mean(|q| q.split_share),
                merge_share: mean(|q| q.merge_share),
                segments: mean(|q| q.segments as f64),
                median_ms: times.get(times.len() / 2).copied().unwrap_or(0.0),
            })
        })
        .collect()
}

/// Prints [`segment_quality`] as one line per segmenter.
pub fn print_segment_quality(frames: usize, scene: u64) -> Result<(), PerceptionError> {
    for q in segment_quality(frames, scene)? {
        println!(
            "quality/{:<9} scene {scene}: per-frame mIoU {:6.2}  objects split {:5.1} %  segments merging objects {:5.1} %  {:.1} segments  median {:6.2} ms  ({} frames with objects)",
            q.name,
            q.miou,
            100.0 * q.split_share,
            100.0 * q.merge_share,
            q.segments,
            q.median_ms,
            q.frames,
        );
    }
    Ok(())
}

fn available_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// The test fixtures, compiled in so the bench runs from any directory.
#[cfg(feature = "onnx")]
mod tiny {
    use std::path::{Path, PathBuf};

    use crate::{EnsembleModelPaths, PerceptionError, SamModelPaths, SegmenterOptions};

    const FILES: [(&str, &[u8]); 7] = [
        (
            "tiny_sam_encoder.onnx",
            include_bytes!("../tests/fixtures/tiny_sam_encoder.onnx"),
        ),
        (
            "tiny_sam_decoder.onnx",
            include_bytes!("../tests/fixtures/tiny_sam_decoder.onnx"),
        ),
        (
            "tiny_proposals.onnx",
            include_bytes!("../tests/fixtures/tiny_proposals.onnx"),
        ),
        (
            "tiny_tagger.onnx",
            include_bytes!("../tests/fixtures/tiny_tagger.onnx"),
        ),
        (
            "tiny_detector.onnx",
            include_bytes!("../tests/fixtures/tiny_detector.onnx"),
        ),
        (
            "tiny_tag_list.txt",
            include_bytes!("../tests/fixtures/tiny_tag_list.txt"),
        ),
        (
            "tiny_tag_embeddings.npy",
            include_bytes!("../tests/fixtures/tiny_tag_embeddings.npy"),
        ),
    ];

    /// A temporary directory removed on drop.
    pub struct Dir(pub PathBuf);

    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    pub fn write_fixtures() -> Result<Dir, PerceptionError> {
        let dir =
            Dir(std::env::temp_dir().join(format!("opengs-tiny-models-{}", std::process::id())));
        let io = |path: &Path, e: std::io::Error| PerceptionError::File {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        std::fs::create_dir_all(&dir.0).map_err(|e| io(&dir.0, e))?;
        for (name, bytes) in FILES {
            let path = dir.0.join(name);
            std::fs::write(&path, bytes).map_err(|e| io(&path, e))?;
        }
        Ok(dir)
    }

    pub fn options(dir: &Path) -> SegmenterOptions {
        SegmenterOptions {
            sam_models: Some(SamModelPaths {
                encoder: dir.join("tiny_sam_encoder.onnx"),
                decoder: dir.join("tiny_sam_decoder.onnx"),
            }),
            proposals: Some(dir.join("tiny_proposals.onnx")),
            ensemble: EnsembleModelPaths {
                tagger: Some(dir.join("tiny_tagger.onnx")),
                tag_list: Some(dir.join("tiny_tag_list.txt")),
                detector: Some(dir.join("tiny_detector.onnx")),
                text_embeddings: Some(dir.join("tiny_tag_embeddings.npy")),
            },
            threads: 2,
            ..SegmenterOptions::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quality_scores_truth_perfect_and_geometry_above_classic() {
        let q = segment_quality(3, 0).expect("synthetic room");
        let by_name = |name: &str| q.iter().find(|q| q.name == name).expect(name);
        let prior = by_name("prior");
        assert_eq!(prior.frames, 3);
        assert!((prior.miou - 100.0).abs() < 1e-9, "{prior:?}");
        assert_eq!((prior.split_share, prior.merge_share), (0.0, 0.0));
        // Classic cuts the room's textures into patches; geometry does not.
        let (geometry, classic) = (by_name("geometry"), by_name("classic"));
        assert!(
            geometry.miou > classic.miou + 10.0 && geometry.split_share < classic.split_share,
            "{geometry:?} vs {classic:?}"
        );
    }
}
