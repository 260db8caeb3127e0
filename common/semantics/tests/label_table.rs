//! Global Label-Class table: best-scored class, cap, adoption and labels.json rows.

mod common;

use common::Scene;
use opengs_semantics::{
    ConsensusConfig, GlobalLabelTable, LabelConsensus, LabelRecord, LabelTarget, SemanticsError,
};

#[test]
fn keeps_best_scored_class() {
    // Observations in order → (class, score) afterwards.
    type Observation = (Option<&'static str>, f32);
    let cases: [(&[Observation], Observation); 5] = [
        (
            &[(Some("chair"), 0.4), (Some("sofa"), 0.7)],
            (Some("sofa"), 0.7),
        ),
        (
            &[(Some("sofa"), 0.7), (Some("chair"), 0.4)],
            (Some("sofa"), 0.7),
        ),
        (&[(Some("chair"), 0.5), (None, 0.0)], (Some("chair"), 0.5)),
        (&[(None, 0.0), (Some("lamp"), 0.0)], (Some("lamp"), 0.0)),
        (&[(Some("a"), 0.5), (Some("b"), 0.5)], (Some("a"), 0.5)),
    ];
    for (observations, (class, score)) in cases {
        let mut table = GlobalLabelTable::new(10);
        let id = table.allocate(None, 0.0, 0.5).expect("room");
        for &(c, s) in observations {
            table.observe(id, c, s);
        }
        let label = table.get(id).expect("present");
        assert_eq!(
            (label.class.as_deref(), label.score),
            (class, score),
            "{observations:?}"
        );
        assert_eq!(label.observations, observations.len() as u32);
    }
}

#[test]
fn allocation_respects_cap_with_increasing_ids() {
    let mut table = GlobalLabelTable::new(3);
    let ids: Vec<_> = (0..3).map(|_| table.allocate(None, 0.0, 0.5)).collect();
    assert_eq!(ids, vec![Ok(1), Ok(2), Ok(3)]);
    assert!(table.is_full());
    assert_eq!(
        table.allocate(None, 0.0, 0.5),
        Err(SemanticsError::LabelTableFull { cap: 3 })
    );
    assert_eq!(table.len(), 3);
}

#[test]
fn adopted_labels_push_next_id_past_them() {
    let mut table = GlobalLabelTable::new(10);
    assert!(table.adopt(7));
    assert!(!table.adopt(7));
    assert!(!table.adopt(0));
    assert_eq!(table.confidence(7), 0.0);
    assert_eq!(table.allocate(None, 0.0, 0.5), Ok(8));
}

#[test]
fn a_retired_label_the_map_still_carries_comes_back_as_it_was() {
    let mut table = GlobalLabelTable::new(10);
    let id = table.allocate(Some("cup"), 0.7, 0.9).expect("room");
    table.note_fragment(id);
    table.note_fragment(id);
    table.retire(id);
    assert!(table.get(id).is_none() && table.is_empty());
    assert!(table.records(|_| 0).is_empty());
    // The mapper kept it (it stands off its host): the next render shows it again.
    assert!(table.adopt(id));
    let back = table.get(id).expect("restored");
    assert_eq!((back.class.as_deref(), back.confidence), (Some("cup"), 0.9));
    assert_eq!(table.fragment_streak(id), 0);
    // Ids are never reused.
    assert_eq!(table.allocate(None, 0.0, 0.5), Ok(id + 1));
}

#[test]
fn consensus_with_full_table_sends_new_segments_to_background() {
    // Cap 2: inputs 1, 2, 3 over unmapped space → labels 1, 2, then refusal (pixels → 0).
    let config = ConsensusConfig {
        max_labels: 2,
        ..ConsensusConfig::default()
    };
    let mut consensus = LabelConsensus::new(config).expect("valid");
    let mut scene = Scene::new(3, 1);
    scene
        .input_span(0..1, 1, 0.5)
        .input_span(1..2, 2, 0.5)
        .input_span(2..3, 3, 0.5);
    let out = scene.run(&mut consensus);
    assert_eq!(out.consistent_label_map, vec![1, 2, 0]);
    assert_eq!(out.target_of(3), Some(&LabelTarget::Background));
    assert_eq!(out.refused_allocations, 1);
    assert_eq!(consensus.table().len(), 2);
}

#[test]
fn consensus_updates_classes_from_input_table() {
    let mut consensus = LabelConsensus::new(ConsensusConfig::default()).expect("valid");
    let mut scene = Scene::new(4, 1);
    scene.input_span(0..2, 1, 0.5).input_span(2..4, 2, 0.5);
    scene.class(1, Some("chair"), 0.6); // label 2 missing from the input table → None, 0.0
    scene.run(&mut consensus);
    // Next keyframe sees global 1 again (Full) with a better-scored class.
    let mut next = Scene::new(4, 1);
    next.input_span(0..2, 9, 0.5)
        .rendered_span(0..2, 1)
        .class(9, Some("armchair"), 0.8);
    next.run(&mut consensus);
    let records = consensus.table().records(|id| u64::from(id) * 10);
    assert_eq!(
        records,
        vec![
            LabelRecord {
                id: 1,
                class: Some("armchair".into()),
                score: 0.8,
                confidence: 0.5,
                gaussians: 10
            },
            LabelRecord {
                id: 2,
                class: None,
                score: 0.0,
                confidence: 0.5,
                gaussians: 20
            },
        ]
    );
}

#[test]
fn table_and_records_round_trip_through_json() {
    let mut table = GlobalLabelTable::new(5);
    let id = table.allocate(Some("table"), 0.9, 0.7).expect("room");
    table.adopt(4);
    let json = serde_json::to_string(&table).expect("serialise");
    let back: GlobalLabelTable = serde_json::from_str(&json).expect("parse");
    assert_eq!(back, table);
    let records = serde_json::to_value(table.records(|_| 3)).expect("serialise");
    assert_eq!(records[0]["id"], id);
    assert_eq!(records[0]["class"], "table");
    assert_eq!(records[0]["gaussians"], 3);
    assert_eq!(records[1]["class"], serde_json::Value::Null);
}
