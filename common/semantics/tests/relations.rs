//! Relation boundaries of docs/METHOD.md §5 (τ1 = 0.85, τ2 = 0.9, τ3 = 0.1) on both sides.

mod common;

use common::{consensus_with, Scene};
use opengs_semantics::{
    pair_relation, ConsensusConfig, LabelTarget, PairRelation, RelabelScope, Relation,
};

/// One input label (1) and one rendered label (1) laid out on a line:
/// `s_only` input-only pixels, then `shared`, then `r_only` rendered-only pixels.
struct Case {
    name: &'static str,
    s_only: usize,
    shared: usize,
    r_only: usize,
    expected: Relation,
}

fn run_case(case: &Case, config: &ConsensusConfig) -> Relation {
    let width = 100;
    let total = case.s_only + case.shared + case.r_only;
    let mut scene = Scene::new(width, total.div_ceil(width) + 1);
    scene.input_span(0..case.s_only + case.shared, 1, 0.5);
    scene.rendered_span(case.s_only..total, 1);
    let mut consensus = consensus_with(&[0.5], config.clone());
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments.len(), 1, "{}", case.name);
    out.assignments[0].relation
}

/// Rendered-only pixels (input 0) stand for the label's pixels over other segments in most
/// cases here, so they count in b (by default they abstain, docs/METHOD.md §5.5).
fn counted() -> ConsensusConfig {
    ConsensusConfig {
        unsegmented_pixels_abstain: false,
        ..ConsensusConfig::default()
    }
}

/// Asserts every case's relation under `config`.
fn check(cases: &[Case], config: &ConsensusConfig) {
    for case in cases {
        assert_eq!(run_case(case, config), case.expected, "{}", case.name);
    }
}

/// The paper's table: input-only pixels (rendered 0) count in a = I/|ℓs|, rendered-only
/// pixels (input 0) in b = I/|ℓr|.
#[test]
fn relation_boundaries_on_both_sides() {
    use Relation::*;
    let paper = ConsensusConfig {
        unmapped_pixels_abstain: false,
        unsegmented_pixels_abstain: false,
        majority_match: false,
        ..ConsensusConfig::default()
    };
    #[rustfmt::skip]
    let cases = [
        // a = b = 340/400 = 0.85 exactly.
        Case { name: "full: a = b = τ1", s_only: 60, shared: 340, r_only: 60, expected: Full },
        // a = 339/400 = 0.8475, b = 1: not Full, rendered label inside input → Whole.
        Case { name: "a just below τ1", s_only: 61, shared: 339, r_only: 0, expected: Whole },
        Case { name: "a = 0.8499 (1e4 px)", s_only: 1501, shared: 8499, r_only: 0, expected: Whole },
        Case { name: "a = 0.85 (1e4 px)", s_only: 1500, shared: 8500, r_only: 1500, expected: Full },
        // a = 1, b = 0.85 → Full; b = 0.8475 → Partial.
        Case { name: "full: b = τ1", s_only: 0, shared: 340, r_only: 60, expected: Full },
        Case { name: "b just below τ1", s_only: 0, shared: 339, r_only: 61, expected: Partial },
        // a = 0.85, b = 340/401: neither Full, Partial (a < τ2) nor Whole (b < τ2).
        Case { name: "a = τ1, b below τ1", s_only: 60, shared: 340, r_only: 61, expected: Other },
        // Partial: a = 360/400 = 0.9 = τ2; a = 359/400 below.
        Case { name: "partial: a = τ2", s_only: 40, shared: 360, r_only: 200, expected: Partial },
        Case { name: "a just below τ2", s_only: 41, shared: 359, r_only: 200, expected: Other },
        // Partial: b = 40/400 = 0.1 = τ3; b = 39/400 below.
        Case { name: "partial: b = τ3", s_only: 0, shared: 40, r_only: 360, expected: Partial },
        Case { name: "b just below τ3", s_only: 0, shared: 39, r_only: 361, expected: Other },
        // Whole: b = 0.9 = τ2; b = 359/400 below.
        Case { name: "whole: b = τ2", s_only: 200, shared: 360, r_only: 40, expected: Whole },
        Case { name: "b just below τ2", s_only: 200, shared: 359, r_only: 41, expected: Other },
        // Whole: a = 40/400 = 0.1 = τ3; a = 39/400 below → New (a < τ3 for every ℓr).
        Case { name: "whole: a = τ3", s_only: 360, shared: 40, r_only: 0, expected: Whole },
        Case { name: "new: a just below τ3", s_only: 361, shared: 39, r_only: 0, expected: New },
        Case { name: "new: no overlap", s_only: 400, shared: 0, r_only: 100, expected: New },
    ];
    check(&cases, &paper);
}

/// The default: input-only pixels render 0, so they abstain from the a of Full and Inside;
/// under τ3 of a segment mapped is New.
#[test]
fn unmapped_pixels_abstain_boundaries() {
    use Relation::*;
    #[rustfmt::skip]
    let cases = [
        // Mapped: 339 of 400 pixels, all rendering the label: a = 1, b = 1.
        Case { name: "a = 0.8475 of all pixels", s_only: 61, shared: 339, r_only: 0, expected: Full },
        // Mapped share 40/400 = τ3: matched (a = 1, b = 1); 39/400 below: New.
        Case { name: "mapped share = τ3", s_only: 360, shared: 40, r_only: 0, expected: Full },
        Case { name: "mapped share below τ3", s_only: 361, shared: 39, r_only: 0, expected: New },
        // Only Full (and Inside) read the mapped a: with b = 340/401 < τ1 this stays other.
        Case { name: "a = τ1, b below τ1", s_only: 60, shared: 340, r_only: 61, expected: Other },
        // Partial keeps the paper's a = 360/400 = τ2 …
        Case { name: "partial: a = τ2", s_only: 40, shared: 360, r_only: 200, expected: Partial },
        // … and a = 359/400 is not Partial even though all mapped pixels render the label.
        Case { name: "a just below τ2", s_only: 41, shared: 359, r_only: 200, expected: Other },
        Case { name: "new: no overlap", s_only: 400, shared: 0, r_only: 100, expected: New },
    ];
    // The Majority relation (tested below) would take the two "other" cases.
    let abstain_only = ConsensusConfig {
        majority_match: false,
        ..counted()
    };
    check(&cases, &abstain_only);
}

/// The default: a segment that misses the table's thresholds takes the map label sharing over
/// half of its mapped pixels and over half of the label's pixels (Majority, §5.5).
#[test]
fn majority_boundaries() {
    use Relation::*;
    #[rustfmt::skip]
    let cases = [
        // a = 1 over the mapped pixels, b = 340/401: Full misses b ≥ τ1 by one pixel.
        Case { name: "a = τ1, b below τ1", s_only: 60, shared: 340, r_only: 61, expected: Majority },
        // a = 359/400 misses Partial's τ2; mapped a = 1, b = 359/559.
        Case { name: "a just below τ2", s_only: 41, shared: 359, r_only: 200, expected: Majority },
        // b = 201/400 is over half; at 200/400 all its mapped pixels still lie in ℓr, of
        // which it covers τ3 or more: a part but for its unmapped pixels.
        Case { name: "b just over half", s_only: 100, shared: 201, r_only: 199, expected: Majority },
        Case { name: "b = half", s_only: 100, shared: 200, r_only: 200, expected: Majority },
        // b = 20/220 below τ3: no part of ℓr.
        Case { name: "b below τ3", s_only: 100, shared: 20, r_only: 200, expected: Other },
        Case { name: "b = τ3", s_only: 100, shared: 20, r_only: 180, expected: Majority },
    ];
    check(&cases, &counted());
}

/// The default: rendered pixels where the input is 0 (no depth, no mask) abstain from
/// b = I/|ℓr|, the mirror of the unmapped pixels in a.
#[test]
fn unsegmented_pixels_abstain_boundaries() {
    use Relation::*;
    #[rustfmt::skip]
    let cases = [
        // b = 340/340 over the segmented pixels (340/540 over all): Full.
        Case { name: "label beyond the segment's depth", s_only: 0, shared: 340, r_only: 200, expected: Full },
        // a = 340/400 = τ1 (1 over the mapped pixels) with b = 1: Full.
        Case { name: "a = τ1", s_only: 60, shared: 340, r_only: 61, expected: Full },
        Case { name: "new: no overlap", s_only: 400, shared: 0, r_only: 100, expected: New },
    ];
    let no_majority = ConsensusConfig {
        majority_match: false,
        ..ConsensusConfig::default()
    };
    check(&cases, &no_majority);
    // Counted, as the paper does: b = 340/540 makes the first a Partial part, the second other.
    let paper = ConsensusConfig {
        majority_match: false,
        ..counted()
    };
    assert_eq!(run_case(&cases[0], &paper), Partial);
    assert_eq!(run_case(&cases[1], &paper), Other);
}

#[test]
fn a_majority_segment_takes_the_label_and_changes_nothing_else() {
    // Input 1: rows 0..10, rendered 1 rows 3..16: a = 0.7 (1 over its 7 mapped rows), b = 7/13
    // (rows 10..16 stand for another object: counted).
    let mut scene = Scene::new(20, 20);
    scene.input_rows(0..10, 1, 0.9);
    scene.rendered_rows(3..16, 1);
    let mut consensus = consensus_with(&[0.4], counted());
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::Majority);
    // All its pixels, mapped or not, take label 1; the rest stays 0.
    assert!(out.consistent_label_map[..200].iter().all(|&l| l == 1));
    assert!(out.consistent_label_map[200..].iter().all(|&l| l == 0));
    assert!(out.relabels.is_empty() && out.counter_pruning.is_empty());
    // C_r stays: a Majority is no confirmation.
    assert_eq!(consensus.table().confidence(1), 0.4);
    let paper = ConsensusConfig {
        majority_match: false,
        ..counted()
    };
    let mut consensus = consensus_with(&[0.4], paper);
    assert_eq!(
        scene.run(&mut consensus).assignments[0].relation,
        Relation::Other
    );
}

#[test]
fn pair_relation_table() {
    let cfg = ConsensusConfig::default();
    let cases = [
        (0.85, 0.85, Some(PairRelation::Full)),
        (1.0, 0.8499, Some(PairRelation::Partial)),
        (0.9, 0.1, Some(PairRelation::Partial)),
        (0.8999, 0.5, None),
        (0.9, 0.0999, None),
        (0.1, 0.9, Some(PairRelation::Whole)),
        (0.0999, 0.9, None),
        (0.8499, 1.0, Some(PairRelation::Whole)),
        (0.5, 0.5, None),
    ];
    for (a, b, expected) in cases {
        assert_eq!(pair_relation(a, b, &cfg), expected, "a={a} b={b}");
    }
}

#[test]
fn full_has_priority_over_whole() {
    // Input 1 covers rendered 1 (Full, a = 340/400) and contains rendered 2 (b = 1, a = 0.1).
    let mut scene = Scene::new(20, 30);
    scene.input_span(0..400, 1, 0.5);
    scene.rendered_span(0..340, 1).rendered_span(340..380, 2);
    let mut consensus = consensus_with(&[0.5, 0.5], ConsensusConfig::default());
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::Full);
    assert!(out.relabels.is_empty());
}

#[test]
fn other_when_segment_straddles_two_labels() {
    // Input rows 5..15 cover half of rendered 1 (rows 0..10) and half of rendered 2 (the rows
    // without a segment stand for other objects: counted).
    let mut scene = Scene::new(20, 20);
    scene.input_rows(5..15, 9, 0.9);
    scene.rendered_rows(0..10, 1).rendered_rows(10..20, 2);
    let mut consensus = consensus_with(&[0.5, 0.5], counted());
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::Other);
    assert!(out.consistent_label_map.iter().all(|&l| l == 0));
}

/// A table in two map labels (1 left, 3 right) over `rows` rows of 20 pixels, each held whole
/// by its segment (1, 3), and a box on it (segment 2: rows 10..20, columns 5..15, 100 pixels)
/// whose Gaussians the map left unlabelled inside a fringe `fringe` pixels wide that renders the
/// table's labels (the fringe of width 1 is 36 pixels, 18 on each label).
fn box_on_a_table_left_unlabelled(rows: usize, fringe: usize) -> Scene {
    let mut scene = Scene::new(20, rows);
    for row in 0..rows {
        let at = row * 20;
        scene
            .input_span(at..at + 10, 1, 0.9)
            .input_span(at + 10..at + 20, 3, 0.9);
        scene
            .rendered_span(at..at + 10, 1)
            .rendered_span(at + 10..at + 20, 3);
    }
    for row in 10..20 {
        scene.input_span(row * 20 + 5..row * 20 + 15, 2, 0.9);
    }
    for row in 10 + fringe..20 - fringe {
        scene.rendered_span(row * 20 + 5 + fringe..row * 20 + 15 - fringe, 0);
    }
    scene
}

fn box_pixels() -> Vec<usize> {
    (10..20)
        .flat_map(|row| row * 20 + 5..row * 20 + 15)
        .collect()
}

#[test]
fn an_object_left_unlabelled_beside_held_labels_takes_a_fresh_label() {
    let scene = box_on_a_table_left_unlabelled(40, 1);
    // Mapped 36 < 50 of 100; a = 18/100 per label, over τ3: not New; a over the mapped pixels
    // 0.5 per label, under τ2: not Inside one label; b = 18/382 < τ3 for both.
    let mut consensus = consensus_with(&[0.5, 0.5, 0.5], ConsensusConfig::default());
    let out = scene.run(&mut consensus);
    let of = |s: u32| {
        out.assignments
            .iter()
            .find(|a| a.input_label == s)
            .expect("assigned")
    };
    assert_eq!(of(2).relation, Relation::Inside);
    let fresh = 4;
    assert_eq!(of(2).target, LabelTarget::Label(fresh));
    assert!(box_pixels()
        .iter()
        .all(|&p| out.consistent_label_map[p] == fresh));
    // Over the box's 100 pixels the Gaussians of both table labels (the fringe) move to the
    // box's label, and the box's label goes back to the table label it shares most with (a
    // tie: the smaller, 1) wherever the mapper finds it on that label's surface.
    let moved: Vec<(u32, u32, usize, RelabelScope)> = out
        .relabels
        .iter()
        .map(|r| (r.from, r.to, r.pixels.len(), r.scope))
        .collect();
    assert_eq!(
        moved,
        vec![
            (1, fresh, 100, RelabelScope::Pixels),
            (3, fresh, 100, RelabelScope::Pixels),
            (fresh, 1, 0, RelabelScope::Rejoin)
        ]
    );
    assert_eq!(
        (of(1).relation, of(3).relation),
        (Relation::Full, Relation::Full)
    );

    // Off: the box is "other" and stays unlabelled.
    let off = ConsensusConfig {
        split_unlabelled_objects: false,
        ..ConsensusConfig::default()
    };
    let out = scene.run(&mut consensus_with(&[0.5, 0.5, 0.5], off));
    assert_eq!(box_relation(&out), Relation::Other);
    assert!(box_pixels()
        .iter()
        .all(|&p| out.consistent_label_map[p] == 0));
}

fn box_relation(out: &opengs_semantics::ConsensusOutput) -> Relation {
    out.assignments
        .iter()
        .find(|a| a.input_label == 2)
        .expect("assigned")
        .relation
}

#[test]
fn a_segment_mostly_labelled_or_a_share_of_its_labels_is_not_split_off() {
    // Half the rows: b = 18/168 = 0.107 ≥ τ3 for both labels, which may be of its own surface.
    let short = box_on_a_table_left_unlabelled(20, 1);
    let out = short.run(&mut consensus_with(
        &[0.5, 0.5, 0.5],
        ConsensusConfig::default(),
    ));
    assert_eq!(box_relation(&out), Relation::Other);
    // A fringe 2 pixels wide: 64 of its 100 pixels render a label, so it is not unlabelled.
    let labelled = box_on_a_table_left_unlabelled(40, 2);
    let out = labelled.run(&mut consensus_with(
        &[0.5, 0.5, 0.5],
        ConsensusConfig::default(),
    ));
    assert_eq!(box_relation(&out), Relation::Other);
}
