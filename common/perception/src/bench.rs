//! Timing of the segmenters on synthetic 640×480 frames: the weight-free
//! ones, and (cargo feature `onnx`, ONNX Runtime available) both SAM-family
//! paths on the test fixtures — grid point prompts and MobileSAMv2-style box
//! prompts, each without and with the tagger/detector ensemble — split into
//! model time and our own (the pipeline's overhead without real weights).

use std::time::Instant;

use opengs_datasets::{open_dataset, DatasetKind, DatasetSpec, RgbdFrame};

use crate::{PerceptionError, Segmenter, SegmenterInput, SegmenterKind};

/// Median and minimum wall time of one segmenter over the bench frames.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentTiming {
    /// Segmenter as printed (`geometry`, `classic`, `prior`).
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
    frames_of(frames, &spec)
}

/// `frames` frames spread evenly over the dataset of `spec`.
fn frames_of(frames: usize, spec: &DatasetSpec) -> Result<BenchFrames, PerceptionError> {
    let mut source = open_dataset(spec)?;
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

/// One SAM-family path on the tiny fixtures: medians per 640×480 frame of
/// the whole `segment` call, of the model runs in it, and of the rest (ours).
#[derive(Debug, Clone, PartialEq)]
pub struct SamPathTiming {
    /// `sam grid`, `sam grid + ensemble`, `mobilesamv2 boxes`, `mobilesamv2 boxes + ensemble`.
    pub name: String,
    /// How the decoder is prompted (`16x16 points`, `proposed boxes`).
    pub prompts: String,
    pub frames: usize,
    pub runs: usize,
    pub total_ms: f64,
    /// Encoder + decoder + proposal runs (timed around each run), plus
    /// tagger + detector (bare runs on inputs of the same shapes).
    pub model_ms: f64,
    /// Pre-processing, prompting, post-processing, painting, class matching.
    pub ours_ms: f64,
    /// Segments per frame, and of those the ones with a class name (means).
    pub segments: f64,
    pub classified: f64,
}

/// Times both SAM paths (grid points, proposed boxes), each without and with
/// the tagger/detector ensemble, on the tiny fixtures with one ORT thread;
/// `points_per_side` overrides the grid density ([`crate::sam::AmgParams`]).
#[cfg(feature = "onnx")]
pub fn time_sam_paths(
    frames: usize,
    repeats: usize,
    points_per_side: Option<u32>,
) -> Result<Vec<SamPathTiming>, PerceptionError> {
    let dir = tiny::write_fixtures()?;
    let result = (|| {
        let bench = bench_frames(frames, 0)?;
        let options = tiny::options(&dir.0);
        let mut params = crate::sam::AmgParams::default();
        if let Some(n) = points_per_side {
            params.points_per_side = n;
        }
        let mut out = Vec::new();
        for (boxes, ensemble) in [(false, false), (false, true), (true, false), (true, true)] {
            out.push(tiny::time_sam_path(
                &bench, &options, params, boxes, ensemble, repeats,
            )?);
        }
        Ok(out)
    })();
    drop(dir);
    result
}

/// Prints the median milliseconds per 640×480 frame of each segmenter, then
/// (with `onnx` and ONNX Runtime) the SAM paths' table (otherwise a line says
/// why it is left out).
pub fn print_segment_bench(frames: usize, repeats: usize) -> Result<(), PerceptionError> {
    print_segment_bench_with(frames, repeats, None)
}

/// [`print_segment_bench`] with the SAM grid density set (`None`: the default).
pub fn print_segment_bench_with(
    frames: usize,
    repeats: usize,
    points_per_side: Option<u32>,
) -> Result<(), PerceptionError> {
    for t in time_segmenters(frames, repeats)? {
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
        );
    }
    #[cfg(feature = "onnx")]
    match time_sam_paths(frames, repeats, points_per_side) {
        Ok(rows) => print_sam_table(&rows),
        Err(PerceptionError::Unavailable { reason, .. }) => {
            println!("segment/sam paths skipped: {reason}")
        }
        Err(e) => return Err(e),
    }
    #[cfg(not(feature = "onnx"))]
    {
        let _ = points_per_side;
        println!(
            "segment/sam paths skipped: built without the `onnx` feature (--features opengs-perception/onnx)"
        );
    }
    Ok(())
}

/// The SAM paths as a table: medians per frame, model time vs ours.
pub fn print_sam_table(rows: &[SamPathTiming]) {
    let Some(first) = rows.first() else { return };
    println!(
        "SAM paths on the tiny fixture models, per 640x480 frame, medians of {} frames x {} runs (ONNX Runtime 1 thread, {} cores available):",
        first.frames,
        first.runs / first.frames.max(1),
        available_cores(),
    );
    println!(
        "  {:<30} {:<16} {:>10} {:>10} {:>10} {:>9} {:>11}",
        "path", "prompts", "total ms", "model ms", "ours ms", "segments", "with class"
    );
    for r in rows {
        println!(
            "  {:<30} {:<16} {:>10.1} {:>10.1} {:>10.1} {:>9.1} {:>11.1}",
            r.name, r.prompts, r.total_ms, r.model_ms, r.ours_ms, r.segments, r.classified
        );
    }
    println!(
        "  (model = encoder + decoder + box-proposal runs, timed around each run, + tagger + detector, bare runs of the same input shapes; ours = the rest: pre-processing, prompting, mask post-processing, painting, class matching. The last row is what segment/tiny-ensemble printed before. Tiny models: pipeline overhead, not model speed.)"
    );
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
    /// Mean IoU of each object class over the frames showing it, lowest first: which
    /// objects the segmenter loses.
    pub class_iou: Vec<(String, f64)>,
}

/// Mean matched IoU per class name over `scores` (ids the table does not name count as
/// `object <id>`), lowest first.
fn class_means(
    scores: &[crate::quality::FrameQuality],
    classes: &[opengs_datasets::InstanceClass],
) -> Vec<(String, f64)> {
    let mut sums: std::collections::BTreeMap<String, (f64, usize)> = Default::default();
    for (id, iou) in scores.iter().flat_map(|q| &q.object_iou) {
        let name = classes
            .iter()
            .find(|c| c.id == *id)
            .map_or_else(|| format!("object {id}"), |c| c.class.clone());
        let entry = sums.entry(name).or_default();
        *entry = (entry.0 + iou, entry.1 + 1);
    }
    let mut out: Vec<(String, f64)> = sums
        .into_iter()
        .map(|(name, (sum, n))| (name, sum / n as f64))
        .collect();
    out.sort_by(|a, b| a.1.total_cmp(&b.1));
    out
}

/// Scores geometry, classic, prior and simulated (the SAM-like reference, default failure
/// rates) on `frames` frames spread over the dataset of `spec` against its ground-truth
/// instances ([`crate::quality`]).
pub fn segment_quality(
    frames: usize,
    spec: &DatasetSpec,
) -> Result<Vec<SegmentQuality>, PerceptionError> {
    let bench = frames_of(frames, spec)?;
    let kinds = [
        SegmenterKind::Geometry,
        SegmenterKind::Classic,
        SegmenterKind::Prior,
        SegmenterKind::Simulated,
    ];
    kinds
        .into_iter()
        .map(|kind| {
            let mut segmenter = kind.create()?;
            let mut times = Vec::new();
            let mut scores = Vec::new();
            for frame in &bench.frames {
                let input = SegmenterInput::from_frame(frame, bench.intrinsics, &bench.classes);
                let truth = frame
                    .labels_where_measured()
                    .ok_or(PerceptionError::MissingLabels)?;
                let start = Instant::now();
                let out = segmenter.segment(&input)?;
                times.push(start.elapsed().as_secs_f64() * 1e3);
                scores.extend(crate::quality::frame_quality(&out.label_map, &truth));
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
                class_iou: class_means(&scores, &bench.classes),
            })
        })
        .collect()
}

/// Prints [`segment_quality`] as one line per segmenter.
pub fn print_segment_quality(frames: usize, spec: &DatasetSpec) -> Result<(), PerceptionError> {
    let name = open_dataset(spec)?.name();
    println!("{name}:");
    for q in segment_quality(frames, spec)? {
        println!(
            "quality/{:<9} per-frame mIoU {:6.2}  objects split {:5.1} %  segments merging objects {:5.1} %  {:.1} segments  median {:6.2} ms  ({} frames with objects)",
            q.name,
            q.miou,
            100.0 * q.split_share,
            100.0 * q.merge_share,
            q.segments,
            q.median_ms,
            q.frames,
        );
        let lowest: Vec<String> = q
            .class_iou
            .iter()
            .take(LOWEST_CLASSES)
            .map(|(name, iou)| format!("{name} {:.2}", iou))
            .collect();
        println!(
            "  lowest objects (mean IoU per class): {}",
            lowest.join(", ")
        );
    }
    Ok(())
}

/// Classes listed per segmenter by `print_segment_quality`.
const LOWEST_CLASSES: usize = 6;

fn available_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// The test fixtures, compiled in so the bench runs from any directory.
#[cfg(feature = "onnx")]
mod tiny {
    use std::path::{Path, PathBuf};
    use std::time::Instant;

    use ndarray::{Array3, Array4};
    use ort::session::Session;

    use super::{BenchFrames, SamPathTiming};
    use crate::ensemble::{Ensemble, EnsembleSegmenter};
    use crate::model_check::{load_checked, session_signature, ModelRole};
    use crate::npy::read_f32_matrix;
    use crate::sam::{model_error, tensor, AmgParams, BoxProposer, ModelClock, SamSegmenter};
    use crate::{
        EnsembleModelPaths, PerceptionError, SamModelPaths, Segmenter, SegmenterInput,
        SegmenterKind, SegmenterOptions,
    };

    /// One ONNX Runtime thread per session: the targets are for one core.
    const THREADS: usize = 1;

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

    /// Times one SAM path: the runner as the factory builds it, wrapped in
    /// the ensemble when `ensemble`; model time from the runner's clock plus
    /// bare tagger/detector runs.
    pub fn time_sam_path(
        bench: &BenchFrames,
        options: &SegmenterOptions,
        params: AmgParams,
        boxes: bool,
        ensemble: bool,
        repeats: usize,
    ) -> Result<SamPathTiming, PerceptionError> {
        let kind = if boxes {
            SegmenterKind::MobileSamV2
        } else {
            SegmenterKind::Sam
        };
        let paths = options
            .sam_models
            .as_ref()
            .ok_or_else(|| PerceptionError::InvalidInput("no SAM fixtures".into()))?;
        let clock = ModelClock::default();
        let mut sam = SamSegmenter::new(kind, paths, params, THREADS)?;
        if boxes {
            let proposals = options
                .proposals
                .as_ref()
                .ok_or_else(|| PerceptionError::InvalidInput("no proposal fixture".into()))?;
            sam = sam.with_box_proposals(BoxProposer::new(proposals, THREADS)?);
        }
        let sam = sam.with_model_clock(clock.clone());
        let (mut segmenter, mut bare): (Box<dyn Segmenter>, _) = if ensemble {
            let models = Ensemble::new(&options.ensemble, THREADS)?;
            (
                Box::new(EnsembleSegmenter::new(Box::new(sam), models)),
                Some(BareEnsemble::new(&options.ensemble)?),
            )
        } else {
            (Box::new(sam), None)
        };
        let (mut total, mut model, mut ours) = (Vec::new(), Vec::new(), Vec::new());
        let (mut segments, mut classified) = (0usize, 0usize);
        for frame in &bench.frames {
            let input = SegmenterInput::from_frame(frame, bench.intrinsics, &bench.classes);
            let warm = segmenter.segment(&input)?;
            segments += warm.labels.len();
            classified += warm.labels.iter().filter(|l| l.class.is_some()).count();
            let ensemble_ms = match &mut bare {
                Some(b) => b.median_ms(repeats)?,
                None => 0.0,
            };
            for _ in 0..repeats.max(1) {
                clock.take();
                let start = Instant::now();
                let out = segmenter.segment(&input)?;
                let ms = start.elapsed().as_secs_f64() * 1e3;
                let m = clock.take().as_secs_f64() * 1e3 + ensemble_ms;
                std::hint::black_box(out);
                total.push(ms);
                model.push(m);
                ours.push(ms - m);
            }
        }
        let n = bench.frames.len().max(1) as f64;
        Ok(SamPathTiming {
            name: format!(
                "{}{}",
                if boxes {
                    "mobilesamv2 boxes"
                } else {
                    "sam grid"
                },
                if ensemble { " + ensemble" } else { "" }
            ),
            prompts: if boxes {
                "proposed boxes".into()
            } else {
                format!("{0}x{0} points", params.points_per_side)
            },
            frames: bench.frames.len(),
            runs: total.len(),
            total_ms: median(&mut total),
            model_ms: median(&mut model),
            ours_ms: median(&mut ours),
            segments: segments as f64 / n,
            classified: classified as f64 / n,
        })
    }

    fn median(v: &mut [f64]) -> f64 {
        v.sort_unstable_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    }

    /// The tagger and detector sessions alone, fed zeros of the shapes their
    /// runners feed (the detector prompted with every tag: an upper bound).
    struct BareEnsemble {
        tagger: Option<(Session, Array4<f32>)>,
        detector: Session,
        images: Array4<f32>,
        text: Array3<f32>,
    }

    impl BareEnsemble {
        fn new(paths: &EnsembleModelPaths) -> Result<Self, PerceptionError> {
            let missing = |what: &str| PerceptionError::InvalidInput(format!("no {what} fixture"));
            let dim = |d: i64, default: usize| if d > 0 { d as usize } else { default };
            let tagger = match &paths.tagger {
                Some(p) => {
                    let session = load_checked(p, ModelRole::Tagger, THREADS)?;
                    let s = session_signature(&session).inputs[0].shape.clone();
                    let image = Array4::zeros((1, 3, dim(s[2], 384), dim(s[3], 384)));
                    Some((session, image))
                }
                None => None,
            };
            let path = paths.detector.as_ref().ok_or_else(|| missing("detector"))?;
            let detector = load_checked(path, ModelRole::Detector, THREADS)?;
            let sig = session_signature(&detector);
            let shape = |name: &str| {
                sig.inputs
                    .iter()
                    .find(|t| t.name == name)
                    .map(|t| t.shape.clone())
                    .ok_or_else(|| model_error(path, format!("no input named {name}")))
            };
            let (images, text) = (shape("images")?, shape("text_features")?);
            let features = read_f32_matrix(
                paths
                    .text_embeddings
                    .as_ref()
                    .ok_or_else(|| missing("text embeddings"))?,
            )?;
            Ok(Self {
                tagger,
                images: Array4::zeros((1, 3, dim(images[2], 640), dim(images[3], 640))),
                text: Array3::zeros((1, dim(text[1], features.rows), features.cols)),
                detector,
            })
        }

        /// Median ms of tagger + detector over `repeats` runs (after a warm-up).
        fn median_ms(&mut self, repeats: usize) -> Result<f64, PerceptionError> {
            let mut times = Vec::new();
            for i in 0..=repeats.max(1) {
                let start = Instant::now();
                if let Some((session, image)) = &mut self.tagger {
                    let path = Path::new("tagger");
                    session
                        .run(ort::inputs!["image" => tensor(image, path)?])
                        .map_err(|e| model_error(path, e))?;
                }
                let path = Path::new("detector");
                self.detector
                    .run(ort::inputs![
                        "images" => tensor(&self.images, path)?,
                        "text_features" => tensor(&self.text, path)?,
                    ])
                    .map_err(|e| model_error(path, e))?;
                if i > 0 {
                    times.push(start.elapsed().as_secs_f64() * 1e3);
                }
            }
            Ok(median(&mut times))
        }
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

    fn synthetic(frames: usize, noise: bool) -> DatasetSpec {
        let mut spec = DatasetSpec::new(DatasetKind::Synthetic);
        spec.synthetic.frames = Some(frames);
        spec.synthetic.noise = noise.then(opengs_datasets::DepthNoise::default);
        spec
    }

    #[test]
    fn quality_scores_truth_perfect_and_geometry_above_classic() {
        let q = segment_quality(3, &DatasetSpec::new(DatasetKind::Synthetic)).expect("room");
        let by_name = |name: &str| q.iter().find(|q| q.name == name).expect(name);
        let prior = by_name("prior");
        assert_eq!(prior.frames, 3);
        assert!((prior.miou - 100.0).abs() < 1e-9, "{prior:?}");
        assert_eq!((prior.split_share, prior.merge_share), (0.0, 0.0));
        // Every class the room shows, each matched whole by the truth.
        assert!(prior.class_iou.len() >= 10, "{:?}", prior.class_iou);
        assert!(prior
            .class_iou
            .iter()
            .all(|(_, iou)| (iou - 1.0).abs() < 1e-9));
        // Classic cuts the room's textures into patches; geometry does not.
        let (geometry, classic) = (by_name("geometry"), by_name("classic"));
        assert!(
            geometry.miou > classic.miou + 10.0 && geometry.split_share < classic.split_share,
            "{geometry:?} vs {classic:?}"
        );
    }

    #[test]
    fn quality_reads_a_tum_folder_with_labels_as_the_frames_it_was_written_from() {
        let dir = tempfile::tempdir().expect("temp dir");
        let spec = synthetic(6, true);
        let mut source = open_dataset(&spec).expect("synthetic");
        opengs_datasets::write_dataset(
            source.as_mut(),
            dir.path(),
            opengs_datasets::DatasetFormat::Tum,
            &mut |_, _| {},
        )
        .expect("written");
        let folder = DatasetSpec::new(
            format!("tum:{}", dir.path().display())
                .parse()
                .expect("kind"),
        );
        let (direct, read) = (
            segment_quality(2, &spec).expect("direct"),
            segment_quality(2, &folder).expect("folder"),
        );
        for (a, b) in direct.iter().zip(&read) {
            assert_eq!((&a.name, a.frames), (&b.name, b.frames));
            // The same frames, through PNG and 16-bit millimetres: the same segments.
            assert!((a.miou - b.miou).abs() < 1.0, "{a:?} vs {b:?}");
        }
        // A folder without instance labels is refused by name, not scored as 0.
        std::fs::remove_file(dir.path().join("labels.txt")).expect("removed");
        let err = segment_quality(2, &folder).expect_err("no labels");
        assert!(err.to_string().contains("labels"), "{err}");
    }
}
