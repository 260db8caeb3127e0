//! Ensemble (tagger → detector → mask classes), MobileSAMv2 box prompts and
//! `models check` on the tiny ONNX stand-ins of `scripts/make_tiny_onnx.py`
//! (real input/output names and shapes). The image is grey with a red square
//! [20,60)×[30,70) and a green one [100,140)×[40,80). The fixtures' weights
//! imply: the tagger fires on "red cube" and "green cube" (not "blue cube");
//! the detector has a tight box around the red square and a loose one
//! (IoU 0.44) around the green square; the proposal model finds both squares.
//! Needs `--features onnx` and ORT_DYLIB_PATH; skipped with a message otherwise.
#![cfg(feature = "onnx")]

mod support;

use opengs_geometry::Intrinsics;
use opengs_perception::ensemble::{Ensemble, Tagger};
use opengs_perception::model_check::{check_model, ModelRole};
use opengs_perception::sam::{AmgParams, BoxProposer, SamSegmenter};
use opengs_perception::{
    EnsembleModelPaths, PerceptionError, Segmentation, Segmenter, SegmenterInput, SegmenterKind,
    SegmenterOptions,
};

use support::{fixture, runtime_available, sam_fixtures};

const W: u32 = 160;
const H: u32 = 120;
const RED: [u32; 4] = [20, 30, 60, 70];
const GREEN: [u32; 4] = [100, 40, 140, 80];

fn ensemble_paths(with_tagger: bool) -> EnsembleModelPaths {
    EnsembleModelPaths {
        tagger: with_tagger.then(|| fixture("tiny_tagger.onnx")),
        tag_list: Some(fixture("tiny_tag_list.txt")),
        detector: Some(fixture("tiny_detector.onnx")),
        text_embeddings: Some(fixture("tiny_tag_embeddings.npy")),
    }
}

fn inside(r: [u32; 4], x: u32, y: u32) -> bool {
    (r[0]..r[2]).contains(&x) && (r[1]..r[3]).contains(&y)
}

fn two_squares() -> Vec<u8> {
    let mut rgb = Vec::with_capacity((W * H * 3) as usize);
    for y in 0..H {
        for x in 0..W {
            rgb.extend_from_slice(if inside(RED, x, y) {
                &[220, 30, 30]
            } else if inside(GREEN, x, y) {
                &[30, 200, 40]
            } else {
                &[128, 128, 128]
            });
        }
    }
    rgb
}

fn input<'a>(rgb: &'a [u8], depth: &'a [u16]) -> SegmenterInput<'a> {
    SegmenterInput {
        width: W,
        height: H,
        rgb,
        depth,
        depth_scale: 1000.0,
        intrinsics: Intrinsics::new(150.0, 150.0, 79.5, 59.5, W, H),
        gt_labels: None,
        classes: &[],
    }
}

/// The label covering most of `r`, with the fraction of `r` it covers and
/// the fraction of the label inside `r`.
fn dominant(seg: &Segmentation, r: [u32; 4]) -> (u32, f64, f64) {
    let mut counts = std::collections::HashMap::<u32, usize>::new();
    for y in r[1]..r[3] {
        for x in r[0]..r[2] {
            *counts
                .entry(seg.label_map[(y * W + x) as usize])
                .or_default() += 1;
        }
    }
    let (label, n) = counts
        .into_iter()
        .max_by_key(|(l, n)| (*n, *l))
        .expect("non-empty region");
    let total = seg.label_map.iter().filter(|&&l| l == label).count();
    let area = ((r[2] - r[0]) * (r[3] - r[1])) as f64;
    (label, n as f64 / area, n as f64 / total as f64)
}

#[test]
fn tagger_proposes_the_colours_in_the_image() {
    if !runtime_available() {
        return;
    }
    let (rgb, depth) = (two_squares(), vec![0u16; (W * H) as usize]);
    let mut tagger = Tagger::new(&fixture("tiny_tagger.onnx"), 3, 1).expect("tagger");
    let scores = tagger.scores(&input(&rgb, &depth)).expect("scores");
    println!("tag scores {scores:?}");
    assert!(scores[0] > 0.95 && scores[1] > 0.95, "{scores:?}");
    assert!(scores[2] < 0.1, "no blue in the image: {scores:?}");
    let present = tagger.present(&input(&rgb, &depth)).expect("present");
    let mut ids: Vec<usize> = present.iter().map(|p| p.0).collect();
    ids.sort_unstable();
    assert_eq!(ids, vec![0, 1]);
    // A tag list of the wrong length is refused, naming the model.
    let err = Tagger::new(&fixture("tiny_tagger.onnx"), 4, 1)
        .err()
        .expect("4 tags");
    assert!(err.to_string().contains("tiny_tagger.onnx"), "{err}");
}

#[test]
fn detector_boxes_the_prompted_classes() {
    if !runtime_available() {
        return;
    }
    let (rgb, depth) = (two_squares(), vec![0u16; (W * H) as usize]);
    let mut ensemble = Ensemble::new(&ensemble_paths(true), 1).expect("ensemble");
    assert_eq!(ensemble.tags(), ["red cube", "green cube", "blue cube"]);
    let dets = ensemble.detections(&input(&rgb, &depth)).expect("detect");
    println!("{dets:?}");
    assert_eq!(dets.len(), 2, "{dets:?}");
    assert_eq!(dets[0].class, "red cube");
    assert!(dets[0].score > 0.99, "{dets:?}");
    // 640-frame box [76,196,244,364] → image pixels (scale 4, 80 rows of border).
    assert_eq!(dets[0].bbox, [19.0, 29.0, 61.0, 71.0]);
    assert_eq!(dets[1].class, "green cube");
    assert_eq!(dets[1].bbox, [100.0, 40.0, 160.0, 100.0]);
    assert!((0.5..0.95).contains(&dets[1].score), "{dets:?}");
}

fn check_classes(seg: &Segmentation) {
    println!("{:?}", seg.labels);
    let (red, red_cover, red_purity) = dominant(seg, RED);
    let (green, green_cover, green_purity) = dominant(seg, GREEN);
    assert!(red != 0 && green != 0 && red != green);
    // The toy encoder's 2.5-pixel cells leave 1–2-pixel seams along the edges
    // of masks upsampled from its low-res logits (a 40-pixel square: 36², 0.81).
    assert!(
        red_cover > 0.78 && red_purity > 0.9,
        "{red_cover} {red_purity}"
    );
    assert!(
        green_cover > 0.78 && green_purity > 0.9,
        "{green_cover} {green_purity}"
    );
    let red = seg.info(red).expect("red label");
    assert_eq!(red.class.as_deref(), Some("red cube"));
    assert!(red.score > 0.99, "{red:?}");
    let green = seg.info(green).expect("green label");
    assert_eq!(
        (green.class.as_deref(), green.score),
        (None, 0.0),
        "the only green box has IoU 0.44 with the green mask"
    );
}

#[test]
fn sam_with_ensemble_names_the_red_mask_only() {
    if !runtime_available() {
        return;
    }
    let (rgb, depth) = (two_squares(), vec![0u16; (W * H) as usize]);
    let params = AmgParams {
        points_per_side: 8,
        min_mask_pixels: 50,
        ..AmgParams::default()
    };
    let sam = SamSegmenter::new(SegmenterKind::Sam, &sam_fixtures(), params, 1).expect("sam");
    let ensemble = Ensemble::new(&ensemble_paths(true), 1).expect("ensemble");
    let mut seg = opengs_perception::ensemble::EnsembleSegmenter::new(Box::new(sam), ensemble);
    assert_eq!(seg.name(), "sam");
    let out = seg.segment(&input(&rgb, &depth)).expect("segment");
    check_classes(&out);
    let (bg, _, _) = dominant(&out, [0, 100, 160, 120]);
    let bg = out.info(bg).expect("background segment");
    assert_eq!((bg.class.as_deref(), bg.score), (None, 0.0));
}

#[test]
fn mobilesamv2_prompts_with_proposed_boxes() {
    if !runtime_available() {
        return;
    }
    let (rgb, depth) = (two_squares(), vec![0u16; (W * H) as usize]);
    let mut proposer = BoxProposer::new(&fixture("tiny_proposals.onnx"), 1).expect("proposals");
    let boxes = proposer.propose(&input(&rgb, &depth)).expect("propose");
    assert_eq!(
        boxes,
        vec![[19.0, 29.0, 61.0, 71.0], [99.0, 39.0, 141.0, 81.0]],
        "both squares; the near-duplicate red box and the grey boxes are dropped"
    );
    // Through the factory, as the segmenter stage builds it.
    let options = SegmenterOptions {
        sam_models: Some(sam_fixtures()),
        proposals: Some(fixture("tiny_proposals.onnx")),
        ensemble: ensemble_paths(false),
        threads: 1,
        ..Default::default()
    };
    let mut seg = SegmenterKind::MobileSamV2
        .create_with(&options)
        .expect("build");
    assert_eq!(seg.name(), "mobilesamv2");
    let out = seg.segment(&input(&rgb, &depth)).expect("segment");
    assert_eq!(
        out.labels.len(),
        2,
        "one mask per proposed box: {:?}",
        out.labels
    );
    check_classes(&out);
    let bg = out.label_map[(110 * W + 5) as usize];
    assert_eq!(bg, 0, "no box prompted the background");
    // Box proposals belong to mobilesamv2 only.
    let err = SegmenterKind::Sam
        .create_with(&options)
        .err()
        .expect("sam + proposals");
    assert!(matches!(err, PerceptionError::Unavailable { .. }), "{err}");
}

#[test]
fn missing_and_malformed_side_files_name_the_file() {
    if !runtime_available() {
        return;
    }
    let mut paths = ensemble_paths(true);
    paths.detector = None;
    let err = Ensemble::new(&paths, 1).unwrap_err();
    assert!(err.to_string().contains("--detector"), "{err}");
    let mut paths = ensemble_paths(true);
    paths.text_embeddings = Some(fixture("tiny_tag_list.txt"));
    let err = Ensemble::new(&paths, 1).unwrap_err();
    assert!(
        err.to_string().contains("tiny_tag_list.txt") && err.to_string().contains(".npy"),
        "{err}"
    );
    let mut paths = ensemble_paths(true);
    paths.tag_list = Some(fixture("missing_tags.txt"));
    let err = Ensemble::new(&paths, 1).unwrap_err();
    assert!(err.to_string().contains("missing_tags.txt"), "{err}");
}

#[test]
fn models_check_accepts_fixtures_and_rejects_wrong_input_names() {
    if !runtime_available() {
        return;
    }
    for (file, role) in [
        ("tiny_sam_encoder.onnx", ModelRole::Encoder),
        ("tiny_sam_decoder.onnx", ModelRole::Decoder),
        ("tiny_tagger.onnx", ModelRole::Tagger),
        ("tiny_detector.onnx", ModelRole::Detector),
        ("tiny_proposals.onnx", ModelRole::Proposals),
    ] {
        let guessed = check_model(&fixture(file), None).expect(file);
        assert_eq!((guessed.role, guessed.guessed), (role, true), "{file}");
        let given = check_model(&fixture(file), Some(role)).expect(file);
        assert!(!given.guessed);
    }
    let err = check_model(
        &fixture("tiny_tagger_wrong_input.onnx"),
        Some(ModelRole::Tagger),
    )
    .unwrap_err()
    .to_string();
    println!("{err}");
    assert!(err.contains("tiny_tagger_wrong_input.onnx"), "{err}");
    assert!(err.contains("no input named image"), "{err}");
    assert!(err.contains("Expected inputs image[1,3,?,?]"), "{err}");
    assert!(err.contains("found inputs img[1,3,384,384]"), "{err}");
    // Guessed from its output name, it still fails as a tagger.
    assert!(check_model(&fixture("tiny_tagger_wrong_input.onnx"), None).is_err());
    // A decoder given as an encoder.
    let err = check_model(&fixture("tiny_sam_decoder.onnx"), Some(ModelRole::Encoder))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("no input named image;") || err.contains("no input named image."),
        "{err}"
    );
    // Runners check too: a tagger is no detector.
    let mut paths = ensemble_paths(false);
    paths.detector = Some(fixture("tiny_tagger.onnx"));
    let err = Ensemble::new(&paths, 1).unwrap_err();
    assert!(
        err.to_string().contains("does not fit role detector"),
        "{err}"
    );
}
