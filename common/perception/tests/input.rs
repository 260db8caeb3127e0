use opengs_geometry::Intrinsics;
use opengs_perception::{PerceptionError, SegmenterInput, SegmenterKind};

/// Name of a malformed-input case, its buffers, and how it bends the input.
type Case = (&'static str, Buffers, Box<dyn Fn(&mut SegmenterInput)>);

struct Buffers {
    rgb: Vec<u8>,
    depth: Vec<u16>,
    labels: Vec<u16>,
}

fn buffers(w: u32, h: u32) -> Buffers {
    let n = (w * h) as usize;
    Buffers {
        rgb: vec![100; n * 3],
        depth: vec![1000; n],
        labels: vec![1; n],
    }
}

fn input<'a>(b: &'a Buffers, w: u32, h: u32) -> SegmenterInput<'a> {
    SegmenterInput {
        width: w,
        height: h,
        rgb: &b.rgb,
        depth: &b.depth,
        depth_scale: 1000.0,
        intrinsics: Intrinsics::new(
            50.0,
            50.0,
            (w as f64 - 1.0) / 2.0,
            (h as f64 - 1.0) / 2.0,
            w,
            h,
        ),
        gt_labels: Some(&b.labels),
        classes: &[],
    }
}

fn run_all(input: &SegmenterInput) -> Vec<Result<(), PerceptionError>> {
    [
        SegmenterKind::Geometry,
        SegmenterKind::Classic,
        SegmenterKind::Prior,
    ]
    .iter()
    .map(|kind| kind.create().and_then(|mut s| s.segment(input)).map(|_| ()))
    .collect()
}

#[test]
fn well_formed_input_runs_on_every_weight_free_segmenter() {
    let b = buffers(32, 24);
    assert!(run_all(&input(&b, 32, 24)).iter().all(Result::is_ok));
}

#[test]
fn wrong_sizes_are_errors() {
    let (w, h) = (32, 24);
    let mut cases: Vec<Case> = Vec::new();
    let mut b = buffers(w, h);
    b.rgb.pop();
    cases.push(("short rgb", b, Box::new(|_| {})));
    let mut b = buffers(w, h);
    b.depth.push(0);
    cases.push(("long depth", b, Box::new(|_| {})));
    let mut b = buffers(w, h);
    b.labels.truncate(10);
    cases.push(("short labels", b, Box::new(|_| {})));
    cases.push((
        "intrinsics for another size",
        buffers(w, h),
        Box::new(|i| i.intrinsics = i.intrinsics.scaled(0.5)),
    ));
    cases.push((
        "zero depth scale",
        buffers(w, h),
        Box::new(|i| i.depth_scale = 0.0),
    ));
    cases.push((
        "nan focal length",
        buffers(w, h),
        Box::new(|i| i.intrinsics.fx = f64::NAN),
    ));
    cases.push((
        "empty frame",
        buffers(0, 0),
        Box::new(|i| {
            i.width = 0;
            i.height = 0;
            i.intrinsics.width = 0;
            i.intrinsics.height = 0;
        }),
    ));
    for (what, b, tweak) in &cases {
        let mut i = input(b, w, h);
        tweak(&mut i);
        for result in run_all(&i) {
            let err = result.expect_err(what);
            assert!(
                matches!(
                    err,
                    PerceptionError::InputSize { .. } | PerceptionError::InvalidInput(_)
                ),
                "{what}: {err}"
            );
        }
    }
}

#[test]
fn model_segmenters_say_they_are_unavailable() {
    for kind in [SegmenterKind::Sam, SegmenterKind::MobileSamV2] {
        let err = kind.create().err().expect("no model runner yet");
        assert!(matches!(err, PerceptionError::Unavailable { .. }), "{err}");
    }
}
