mod support;

use opengs_perception::{PerceptionError, PriorSegmenter, Segmenter, SegmenterInput};
use support::synthetic_frames;

#[test]
fn returns_exactly_the_ground_truth_with_classes() {
    let (frames, k, classes) = synthetic_frames(&[0, 300]);
    let mut prior = PriorSegmenter::new();
    for frame in &frames {
        let out = prior
            .segment(&SegmenterInput::from_frame(frame, k, &classes))
            .expect("segment");
        let gt = frame.labels.as_deref().expect("labels");
        assert_eq!(
            out.label_map,
            gt.iter().map(|&l| l as u32).collect::<Vec<_>>()
        );
        let mut present: Vec<u32> = gt.iter().map(|&l| l as u32).filter(|&l| l != 0).collect();
        present.sort_unstable();
        present.dedup();
        assert_eq!(
            out.labels.iter().map(|s| s.label).collect::<Vec<_>>(),
            present
        );
        for s in &out.labels {
            let class = classes
                .iter()
                .find(|c| c.id as u32 == s.label)
                .map(|c| c.class.clone());
            assert!(
                class.is_some(),
                "synthetic class table covers instance {}",
                s.label
            );
            assert_eq!(s.class, class);
            assert_eq!((s.confidence, s.score), (1.0, 1.0));
        }
    }
}

#[test]
fn unknown_ids_get_no_class_and_missing_labels_are_an_error() {
    let (mut frames, k, _) = synthetic_frames(&[0]);
    let out = PriorSegmenter::new()
        .segment(&SegmenterInput::from_frame(&frames[0], k, &[]))
        .expect("segment");
    assert!(out
        .labels
        .iter()
        .all(|s| s.class.is_none() && s.score == 0.0));
    frames[0].labels = None;
    let err = PriorSegmenter::new()
        .segment(&SegmenterInput::from_frame(&frames[0], k, &[]))
        .unwrap_err();
    assert!(matches!(err, PerceptionError::MissingLabels), "{err}");
}
