//! The action of each relation on a 20×20 grid (400 px, rows of 20).

mod common;

use approx::assert_relative_eq;
use common::{conf, consensus_with, Scene};
use opengs_semantics::{ConsensusConfig, LabelTarget, RelabelInstruction, RelabelScope, Relation};

fn config() -> ConsensusConfig {
    ConsensusConfig::default()
}

/// Rows without a segment stand for other objects in some scenes below, so they count in b
/// (by default they abstain, docs/METHOD.md §5.5).
fn counted() -> ConsensusConfig {
    ConsensusConfig {
        unsegmented_pixels_abstain: false,
        ..config()
    }
}

#[test]
fn full_match_takes_rendered_label_and_max_confidence() {
    // (C_r before, C_s, C_r after)
    let cases = [(0.5, 0.8, 0.8), (0.5, 0.3, 0.5), (0.7, 0.7, 0.7)];
    for (cr, cs, expected) in cases {
        let mut scene = Scene::new(20, 20);
        scene.input_rows(0..10, 5, cs).rendered_rows(0..10, 1);
        let mut consensus = consensus_with(&[cr], config());
        let out = scene.run(&mut consensus);
        assert_eq!(out.assignments[0].relation, Relation::Full);
        assert_eq!(out.target_of(5), Some(&LabelTarget::Label(1)));
        assert_eq!(&out.consistent_label_map[..200], &[1; 200][..]);
        assert_eq!(&out.consistent_label_map[200..], &[0; 200][..]);
        assert_relative_eq!(conf(&consensus, 1), expected);
        assert!(out.relabels.is_empty());
    }
}

/// Rendered 1 covers the grid; input 10 covers rows 0..split, input 11 rows split..20.
fn partial_scene(split: usize, c10: f32, c11: f32) -> Scene {
    let mut scene = Scene::new(20, 20);
    scene.rendered_rows(0..20, 1);
    scene
        .input_rows(0..split, 10, c10)
        .input_rows(split..20, 11, c11);
    scene
}

#[test]
fn partial_map_wins_when_its_confidence_beats_area_weighted_mean() {
    // C̄s = (0.5·200 + 0.7·200)/400 = 0.6 < C_r = 0.9: every part → 1, no relabel, no decay.
    let scene = partial_scene(10, 0.5, 0.7);
    let mut consensus = consensus_with(&[0.9], config());
    let out = scene.run(&mut consensus);
    for label in [10, 11] {
        assert_eq!(out.target_of(label), Some(&LabelTarget::Label(1)));
    }
    assert!(out.relabels.is_empty());
    assert!(out.consistent_label_map.iter().all(|&l| l == 1));
    assert_relative_eq!(conf(&consensus, 1), 0.9);
}

#[test]
fn partial_uses_area_weighted_mean_not_plain_mean() {
    // 160 px at 0.8 and 240 px at 0.3: C̄s = 0.5 (plain mean 0.55). C_r = 0.52 > 0.5: map wins.
    let scene = partial_scene(8, 0.8, 0.3);
    let mut consensus = consensus_with(&[0.52], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(10), Some(&LabelTarget::Label(1)));
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(1)));
    assert!(out.relabels.is_empty());
}

#[test]
fn partial_parts_win_get_new_labels_and_relabel_instructions() {
    // C̄s = (0.8·200 + 0.4·200)/400 = 0.6 ≥ C_r = 0.5: part 10 (0.8 > 0.5) gets fresh label 2,
    // part 11 (0.4) stays on 1; label 1 is a part now and decays by δ.
    let scene = partial_scene(10, 0.8, 0.4);
    let mut consensus = consensus_with(&[0.5], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(10), Some(&LabelTarget::Label(2)));
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(1)));
    assert_eq!(
        out.relabels,
        vec![RelabelInstruction {
            from: 1,
            to: 2,
            pixels: scene.rows(0..10),
            scope: RelabelScope::Pixels,
        }]
    );
    assert_eq!(&out.consistent_label_map[..200], &[2; 200][..]);
    assert_eq!(&out.consistent_label_map[200..], &[1; 200][..]);
    assert_relative_eq!(conf(&consensus, 1), 0.44);
    assert_relative_eq!(conf(&consensus, 2), 0.8);
}

#[test]
fn a_winning_part_that_holds_most_of_the_label_keeps_it() {
    // Rendered 1 (C_r 0.5) is input 10 on rows 0..14 (b = 0.7, C_s 0.9) and input 11 on rows
    // 14..20 (b = 0.3, C_s 0.8); both beat C_r. Part 10 holds most of 1 and keeps it, part
    // 11 alone splits off: the Gaussians of 1 that this view does not meet stay with 10.
    let mut scene = Scene::new(20, 20);
    scene.rendered_rows(0..20, 1);
    scene.input_rows(0..14, 10, 0.9).input_rows(14..20, 11, 0.8);
    let mut consensus = consensus_with(&[0.5], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(10), Some(&LabelTarget::Label(1)));
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(2)));
    assert_eq!(
        out.relabels,
        vec![RelabelInstruction {
            from: 1,
            to: 2,
            pixels: scene.rows(14..20),
            scope: RelabelScope::Pixels,
        }]
    );
    // Alone, such a part keeps the label: nothing splits (a Partial part with the rows
    // 14..20 counted; by default those rows, without a segment, abstain and it is Full).
    let mut lone = Scene::new(20, 20);
    lone.rendered_rows(0..20, 1).input_rows(0..14, 10, 0.9);
    for (config, relation) in [(counted(), Relation::Partial), (config(), Relation::Full)] {
        let mut consensus = consensus_with(&[0.5], config);
        let out = lone.run(&mut consensus);
        assert_eq!(out.assignments[0].relation, relation);
        assert_eq!(out.target_of(10), Some(&LabelTarget::Label(1)));
        assert!(out.relabels.is_empty());
    }
    // Another piece that stays on 1 (C_s 0.3 < C_r) holds τ3 of it: two objects the map
    // merged. The winner takes a fresh label as in the paper, so they come apart.
    let mut merged = Scene::new(20, 20);
    merged.rendered_rows(0..20, 1);
    merged
        .input_rows(0..14, 10, 0.9)
        .input_rows(14..20, 11, 0.3);
    let mut consensus = consensus_with(&[0.5], config());
    let out = merged.run(&mut consensus);
    assert_eq!(out.target_of(10), Some(&LabelTarget::Label(2)));
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(1)));
    assert_eq!(
        out.relabels,
        vec![RelabelInstruction {
            from: 1,
            to: 2,
            pixels: merged.rows(0..14),
            scope: RelabelScope::Pixels,
        }]
    );
    // Switched off (the paper's table): each winning part takes a fresh label.
    let mut consensus = consensus_with(
        &[0.5],
        ConsensusConfig {
            partial_majority_keeps: false,
            ..config()
        },
    );
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(10), Some(&LabelTarget::Label(2)));
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(3)));
    assert_eq!(out.relabels.len(), 2);
}

/// Input 20 covers the grid; rendered 1 rows 0..10 (C 0.4), rendered 2 rows 10..15 (C 0.5).
fn whole_scene(cs: f32) -> Scene {
    let mut scene = Scene::new(20, 20);
    scene.input_rows(0..20, 20, cs);
    scene.rendered_rows(0..10, 1).rendered_rows(10..15, 2);
    scene
}

#[test]
fn whole_input_wins_merges_parts_into_largest() {
    // C̄r = (0.4·200 + 0.5·100)/300 = 0.433 < C_s = 0.6: parts merge into 1 (the largest).
    // The paper's reach: only the Gaussians met at the part's pixels move.
    let scene = whole_scene(0.6);
    let mut consensus = consensus_with(
        &[0.4, 0.5],
        ConsensusConfig {
            merge_whole_labels: false,
            ..config()
        },
    );
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::Whole);
    assert_eq!(out.target_of(20), Some(&LabelTarget::Label(1)));
    assert_eq!(
        out.relabels,
        vec![RelabelInstruction {
            from: 2,
            to: 1,
            pixels: scene.rows(10..15),
            scope: RelabelScope::Pixels,
        }]
    );
    assert!(out.consistent_label_map.iter().all(|&l| l == 1));
    assert_relative_eq!(conf(&consensus, 1), 0.6); // merged label takes C_s
    assert_relative_eq!(conf(&consensus, 2), 0.44); // part decayed
}

#[test]
fn a_whole_merge_moves_all_of_a_part_mostly_in_view() {
    // As above, part 2 wholly in view: every Gaussian of 2 moves, hidden ones too, and 2
    // leaves the table; merged from the view alone, the hidden rest would come back as 2 from
    // the next side seen.
    for (completeness, merged) in [(1.0, true), (0.5, true), (0.49, false)] {
        let mut scene = whole_scene(0.6);
        scene.completeness(2, completeness);
        let mut consensus = consensus_with(&[0.4, 0.5], config());
        let out = scene.run(&mut consensus);
        assert_eq!(out.target_of(20), Some(&LabelTarget::Label(1)));
        let expected = match merged {
            true => RelabelInstruction {
                from: 2,
                to: 1,
                pixels: Vec::new(),
                scope: RelabelScope::Merged,
            },
            false => RelabelInstruction {
                from: 2,
                to: 1,
                pixels: scene.rows(10..15),
                scope: RelabelScope::Pixels,
            },
        };
        assert_eq!(out.relabels, vec![expected], "completeness {completeness}");
        assert_eq!(consensus.table().get(2).is_none(), merged);
        assert!(out.consistent_label_map.iter().all(|&l| l == 1));
    }
    // Switched off, the paper's reach: the pixels only.
    let scene = whole_scene(0.6);
    let mut consensus = consensus_with(
        &[0.4, 0.5],
        ConsensusConfig {
            merge_whole_labels: false,
            ..config()
        },
    );
    let out = scene.run(&mut consensus);
    assert_eq!(out.relabels[0].scope, RelabelScope::Pixels);
    assert_eq!(out.relabels[0].pixels, scene.rows(10..15));
}

#[test]
fn whole_input_loses_takes_rendered_parts() {
    // C_s = 0.4 < C̄r = 0.433: pixels take the rendered parts, unmapped rows the largest part
    // (1); parts decay.
    let scene = whole_scene(0.4);
    let mut consensus = consensus_with(&[0.4, 0.5], config());
    let out = scene.run(&mut consensus);
    assert_eq!(
        out.target_of(20),
        Some(&LabelTarget::RenderedParts(vec![1, 2]))
    );
    assert!(out.relabels.is_empty());
    assert_eq!(&out.consistent_label_map[..200], &[1; 200][..]);
    assert_eq!(&out.consistent_label_map[200..300], &[2; 100][..]);
    assert_eq!(&out.consistent_label_map[300..], &[1; 100][..]);
    assert_relative_eq!(conf(&consensus, 1), 0.34);
    assert_relative_eq!(conf(&consensus, 2), 0.44);
}

/// A wall's segment (input 20, rows 0..10, C_s 0.6) over two map labels of the wall: 1 on
/// rows 0..5 (C 0.4), 2 on rows 5..14, rows 10..14 of it where the frame has no depth (input 0:
/// beyond the sensor's range, mapped from nearer views).
fn wall_beyond_depth_scene() -> Scene {
    let mut scene = Scene::new(20, 20);
    scene.input_rows(0..10, 20, 0.6);
    scene.rendered_rows(0..5, 1).rendered_rows(5..14, 2);
    scene
}

#[test]
fn a_label_that_renders_beyond_the_frames_depth_is_a_whole_part_of_its_wall() {
    // b(2) = 100/100 over the segmented pixels: 1 and 2 are Whole parts; C̄r = (0.4·100 +
    // 0.5·180)/280 = 0.46 < C_s: they merge into 2, the larger.
    let scene = wall_beyond_depth_scene();
    let mut consensus = consensus_with(&[0.4, 0.5], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::Whole);
    assert_eq!(out.target_of(20), Some(&LabelTarget::Label(2)));
    assert_eq!(out.relabels.len(), 1);
    assert_eq!((out.relabels[0].from, out.relabels[0].to), (1, 2));
    assert!(out.consistent_label_map[..200].iter().all(|&l| l == 2));
    // Counted, b(2) = 100/180: 2 is no part, 1 merges with nothing, and the wall keeps both.
    let mut consensus = consensus_with(
        &[0.4, 0.5],
        ConsensusConfig {
            unsegmented_pixels_abstain: false,
            ..config()
        },
    );
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(20), Some(&LabelTarget::Label(1)));
    assert!(out.relabels.iter().all(|r| r.from != 2 && r.to != 2));
}

#[test]
fn pixels_without_a_segment_prune_no_counter_gaussians() {
    // Input 20 rows 0..10, its Full partner 1 on rows 0..11: row 10 has no segment (input 0).
    let mut scene = Scene::new(20, 20);
    scene.input_rows(0..10, 20, 0.9);
    scene.rendered_rows(0..11, 1);
    let mut consensus = consensus_with(&[0.5], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::Full);
    assert!(out.counter_pruning.is_empty());
    // Counted (b = 200/220, still Full): row 10 is a counter region of 1.
    let mut consensus = consensus_with(
        &[0.5],
        ConsensusConfig {
            unsegmented_pixels_abstain: false,
            ..config()
        },
    );
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::Full);
    assert_eq!(out.counter_pruning.len(), 1);
    assert_eq!(out.counter_pruning[0].pixels, scene.rows(10..11));
}

#[test]
fn new_segments_get_increasing_fresh_labels() {
    // Table holds 1..=3; inputs 31 and 30 over unmapped space get 4 and 5 in input-label order.
    let mut scene = Scene::new(20, 20);
    scene.input_rows(0..5, 31, 0.7).input_rows(5..10, 30, 0.6);
    scene.rendered_rows(10..20, 1);
    let mut consensus = consensus_with(&[0.5, 0.5, 0.5], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(30), Some(&LabelTarget::Label(4)));
    assert_eq!(out.target_of(31), Some(&LabelTarget::Label(5)));
    assert!(out.assignments.iter().all(|a| a.relation == Relation::New));
    assert_eq!(&out.consistent_label_map[..100], &[5; 100][..]);
    assert_eq!(&out.consistent_label_map[100..200], &[4; 100][..]);
    assert_relative_eq!(conf(&consensus, 4), 0.6);
    assert_relative_eq!(conf(&consensus, 5), 0.7);
}

#[test]
fn other_sends_pixels_to_background() {
    let mut scene = Scene::new(20, 20);
    scene.input_rows(5..15, 9, 0.9).input_rows(0..5, 8, 0.9);
    scene.rendered_rows(0..10, 1).rendered_rows(10..20, 2);
    let mut consensus = consensus_with(&[0.5, 0.5], counted());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(9), Some(&LabelTarget::Background));
    // Input 8 (rows 0..5) is a Partial part of 1: a = 1, b = 0.5.
    assert_eq!(out.assignments[0].relation, Relation::Partial);
    assert!(out.consistent_label_map[100..300].iter().all(|&l| l == 0));
}

#[test]
fn decay_hits_only_part_labels() {
    // Label 1: Full match (no decay). Label 2: Partial target that lost a part (decay).
    // Label 3: Partial target whose map won (no decay). Label 4: not in view (no decay).
    let mut scene = Scene::new(20, 20);
    scene
        .rendered_rows(0..4, 1)
        .rendered_rows(4..12, 2)
        .rendered_rows(12..20, 3);
    scene.input_rows(0..4, 50, 0.9);
    scene.input_rows(4..8, 51, 0.9).input_rows(8..12, 52, 0.2);
    scene
        .input_rows(12..16, 53, 0.2)
        .input_rows(16..20, 54, 0.2);
    let mut consensus = consensus_with(&[0.5, 0.5, 0.5, 0.5], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(50), Some(&LabelTarget::Label(1)));
    assert_eq!(out.target_of(51), Some(&LabelTarget::Label(5)));
    assert_eq!(out.target_of(52), Some(&LabelTarget::Label(2)));
    assert_eq!(out.target_of(53), Some(&LabelTarget::Label(3)));
    let expected = [(1, 0.9), (2, 0.44), (3, 0.5), (4, 0.5), (5, 0.9)];
    for (label, c) in expected {
        assert_relative_eq!(conf(&consensus, label), c, epsilon = 1e-6);
    }
    assert_eq!(consensus.table().get(2).map(|l| l.part_decays), Some(1));
    assert_eq!(consensus.table().get(3).map(|l| l.part_decays), Some(0));
}

#[test]
fn decay_never_goes_below_zero() {
    let scene = whole_scene(0.01);
    let mut consensus = consensus_with(&[0.03, 0.5], config());
    scene.run(&mut consensus);
    assert_eq!(conf(&consensus, 1), 0.0);
}

#[test]
fn a_part_inside_a_fully_matched_label_splits_off() {
    // Rendered 1 rows 0..20; input 5 rows 0..18 (Full: a = 1, b = 0.9); input 6 rows 18..20
    // (a = 1, b = 0.1) lies inside label 1, which input 5 Full-matches: Inside → fresh label 2,
    // relabel 1 → 2 there. The Full match's prune region is rows 18..20 (rendered 1 outside
    // input 5).
    let mut scene = Scene::new(20, 20);
    scene.rendered_rows(0..20, 1);
    scene.input_rows(0..18, 5, 0.6).input_rows(18..20, 6, 0.9);
    let mut consensus = consensus_with(&[0.5], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(5), Some(&LabelTarget::Label(1)));
    assert_eq!(out.target_of(6), Some(&LabelTarget::Label(2)));
    assert_eq!(
        out.relabels,
        vec![RelabelInstruction {
            from: 1,
            to: 2,
            pixels: scene.rows(18..20),
            scope: RelabelScope::Pixels,
        }]
    );
    assert_eq!(out.counter_pruning.len(), 1);
    assert_eq!(out.counter_pruning[0].pixels, scene.rows(18..20));
    // Full raised C_r to 0.6; label 1 is whole (its Full partner says so), so no decay.
    assert_relative_eq!(conf(&consensus, 1), 0.6, epsilon = 1e-6);
}

#[test]
fn whole_merge_ties_go_to_smallest_part_id() {
    // Parts 3 and 2 have 100 px each: merged label is 2.
    let mut scene = Scene::new(20, 20);
    scene.input_rows(0..20, 9, 0.9);
    scene.rendered_rows(0..5, 3).rendered_rows(5..10, 2);
    let mut consensus = consensus_with(&[0.1, 0.1, 0.1], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(9), Some(&LabelTarget::Label(2)));
    assert_eq!(
        out.relabels,
        vec![RelabelInstruction {
            from: 3,
            to: 2,
            pixels: Vec::new(),
            scope: RelabelScope::Merged,
        }]
    );
}

/// Rendered 1 covers the grid (a table that absorbed a ball); input 10 is the table (rows
/// 0..19: a = 1, b = 0.95, Full), input 11 the ball (the 20 px of row 19: a = 1, b = 0.05).
fn absorbed_scene() -> Scene {
    let mut scene = Scene::new(20, 20);
    scene.rendered_rows(0..20, 1);
    scene.input_rows(0..19, 10, 0.9).input_rows(19..20, 11, 0.5);
    scene
}

#[test]
fn inside_a_full_matched_label_splits_off_whatever_the_confidences() {
    // The ball's C_s = 0.5 is far below C_r = 0.95, yet the table's Full match says label 1
    // is the table without the ball: the ball gets fresh label 2 and its Gaussians move there.
    let scene = absorbed_scene();
    let mut consensus = consensus_with(&[0.95], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(10), Some(&LabelTarget::Label(1)));
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(2)));
    let ball = out.assignments.iter().find(|a| a.input_label == 11);
    assert_eq!(ball.map(|a| a.relation), Some(Relation::Inside));
    assert_eq!(
        out.relabels,
        vec![RelabelInstruction {
            from: 1,
            to: 2,
            pixels: scene.rows(19..20),
            scope: RelabelScope::Pixels,
        }]
    );
    assert_eq!(&out.consistent_label_map[..380], &[1; 380][..]);
    assert_eq!(&out.consistent_label_map[380..], &[2; 20][..]);
    assert_relative_eq!(conf(&consensus, 1), 0.95); // no decay: the table is whole
    assert_relative_eq!(conf(&consensus, 2), 0.5);
    assert_eq!(consensus.table().get(1).map(|l| l.part_decays), Some(0));
}

#[test]
fn without_the_inside_relation_an_absorbed_object_stays_absorbed() {
    // The paper's table: b = 0.05 < τ3 is no relation, so the ball's pixels go to background.
    let scene = absorbed_scene();
    let config = ConsensusConfig {
        enable_inside_split: false,
        ..config()
    };
    let mut consensus = consensus_with(&[0.95], config);
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(11), Some(&LabelTarget::Background));
    assert!(out.relabels.is_empty());
    assert_eq!(consensus.table().len(), 1);
}

/// A chair's label 1 (rows 0..15, 300 px) that absorbed a ball; the chair's segment 10 (rows
/// 5..17) holds it by Majority (a = 200/240 = 0.83, b = 200/300 = 0.67: no relation of the
/// table) and spills onto floor label 4 (rows 15..18, b = 40/60); `ball_rows` of input 11
/// lie inside 1. The rows without a segment stand for other objects: the tests count them
/// ([`counted`]).
fn majority_held_scene(ball_rows: std::ops::Range<usize>) -> Scene {
    let mut scene = Scene::new(20, 20);
    scene.rendered_rows(0..15, 1).rendered_rows(15..18, 4);
    scene
        .input_rows(5..17, 10, 0.9)
        .input_rows(ball_rows, 11, 0.9);
    scene
}

#[test]
fn inside_a_label_another_segment_holds_by_majority_splits_off() {
    // The ball (row 0: a = 1, b = 20/300 < τ3) has no relation of the table; the chair's
    // segment holds label 1 without it, so the ball is Inside: fresh label 5, relabel 1 → 5.
    let scene = majority_held_scene(0..1);
    let mut consensus = consensus_with(&[0.9, 0.9, 0.9, 0.9], counted());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(10), Some(&LabelTarget::Label(1)));
    let ball = out.assignments.iter().find(|a| a.input_label == 11);
    assert_eq!(ball.map(|a| a.relation), Some(Relation::Inside));
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(5)));
    assert_eq!(
        out.relabels,
        vec![RelabelInstruction {
            from: 1,
            to: 5,
            pixels: scene.rows(0..1),
            scope: RelabelScope::Pixels,
        }]
    );
}

#[test]
fn a_label_mostly_out_of_view_is_held_by_no_majority() {
    // Label 1 with 30 % of its Gaussians in view (a floor larger than the view): the segment
    // sharing most of it is one piece of many, and the ball stays background, as before.
    let mut scene = majority_held_scene(0..1);
    scene.completeness(1, 0.3);
    let mut consensus = consensus_with(&[0.9, 0.9, 0.9, 0.9], counted());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(11), Some(&LabelTarget::Background));
    assert!(out.relabels.is_empty());
}

#[test]
fn a_piece_touching_the_segment_that_holds_its_label_is_no_inside() {
    // Row 4 meets the chair's segment (rows 5..17): a piece of the same surface the segmenter
    // cut off (a floor between table legs), not an object apart. No split: background.
    let scene = majority_held_scene(4..5);
    let mut consensus = consensus_with(&[0.9, 0.9, 0.9, 0.9], counted());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(11), Some(&LabelTarget::Background));
    assert!(out.relabels.is_empty());
}

#[test]
fn a_tenth_of_a_majority_held_label_is_still_a_partial_part() {
    // Rows 0..2 are 40/300 = 0.13 ≥ τ3 of label 1: a Partial part, and the confident map
    // keeps it on 1. A segmenter's pieces of one object are no Inside.
    let scene = majority_held_scene(0..2);
    let mut consensus = consensus_with(&[0.95, 0.9, 0.9, 0.9], counted());
    let out = scene.run(&mut consensus);
    let ball = out.assignments.iter().find(|a| a.input_label == 11);
    assert_eq!(ball.map(|a| a.relation), Some(Relation::Partial));
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(1)));
    assert!(out.relabels.is_empty());
}

#[test]
fn inside_two_held_labels_splits_off_from_both() {
    // The ball (row 0) renders the chair's label 1 on 14 px and the lamp's label 2 on 6 px;
    // the lamp's segment 12 (rows 18..20) Full-matches 2 (a = 1, b = 40/46), the chair's
    // segment 10 holds 1 by Majority. Neither label alone holds τ2 of the ball; together all
    // of it: Inside, and both move to the fresh label over the ball's pixels.
    let mut scene = majority_held_scene(0..1);
    scene
        .rendered_span(14..20, 2)
        .rendered_rows(18..20, 2)
        .input_rows(18..20, 12, 0.9);
    let mut consensus = consensus_with(&[0.9, 0.9, 0.9, 0.9], counted());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(12), Some(&LabelTarget::Label(2)));
    let ball = out.assignments.iter().find(|a| a.input_label == 11);
    assert_eq!(ball.map(|a| a.relation), Some(Relation::Inside));
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(5)));
    let moved: Vec<(u32, u32, usize)> = out
        .relabels
        .iter()
        .map(|r| (r.from, r.to, r.pixels.len()))
        .collect();
    assert_eq!(moved, vec![(1, 5, 20), (2, 5, 20)]);
    assert!(out.relabels.iter().all(|r| r.pixels == scene.rows(0..1)));
    // Without the Inside relation the ball is background.
    let config_off = ConsensusConfig {
        enable_inside_split: false,
        ..counted()
    };
    let mut off = consensus_with(&[0.9, 0.9, 0.9, 0.9], config_off);
    assert_eq!(
        scene.run(&mut off).target_of(11),
        Some(&LabelTarget::Background)
    );
}

#[test]
fn inside_needs_the_full_partner_a_map_label_split_into_parts_stays_partial() {
    // The table is seen as two halves (b = 0.5 and 0.4) and the ball as rows 18..20 (b = 0.1):
    // no Full match, so all three are Partial parts and the confident map keeps them on 1.
    let mut scene = Scene::new(20, 20);
    scene.rendered_rows(0..20, 1);
    scene
        .input_rows(0..10, 10, 0.9)
        .input_rows(10..18, 12, 0.9)
        .input_rows(18..20, 11, 0.5);
    let mut consensus = consensus_with(&[0.95], config());
    let out = scene.run(&mut consensus);
    for label in [10, 11, 12] {
        assert_eq!(out.target_of(label), Some(&LabelTarget::Label(1)));
    }
    assert!(out.relabels.is_empty());
}

/// A picture (input 11, rows 0..10) whose Gaussians are mostly unlabelled: its old label 5
/// renders on rows 0..2 inside it and on 6 pixels of row 10 outside; label 0 on the rest.
/// a = 40/200 = 0.2 over all its pixels, 40/40 = 1 over the mapped ones; b = 40/46 = 0.87.
fn half_unmapped_scene() -> Scene {
    let mut scene = Scene::new(20, 20);
    scene.input_rows(0..10, 11, 0.8);
    scene.rendered_rows(0..2, 5).rendered_span(200..206, 5);
    scene
}

#[test]
fn unmapped_pixels_abstain_so_a_half_labelled_object_keeps_its_label() {
    // Full over the mapped pixels: every pixel of the picture paints 5, so its unlabelled
    // Gaussians get 5.
    let scene = half_unmapped_scene();
    let mut consensus = consensus_with(&[0.5, 0.5, 0.5, 0.5, 0.9], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::Full);
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(5)));
    assert_eq!(&out.consistent_label_map[..200], &[5; 200][..]);
}

#[test]
fn with_unmapped_pixels_counted_the_object_falls_to_background_for_good() {
    // The paper's table: a = 0.2 with b = 0.87 is no relation, so "other": its unlabelled
    // Gaussians stay unlabelled, and next time it looks the same.
    let scene = half_unmapped_scene();
    let config = ConsensusConfig {
        unmapped_pixels_abstain: false,
        ..counted()
    };
    let mut consensus = consensus_with(&[0.5, 0.5, 0.5, 0.5, 0.9], config);
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::Other);
    assert!(out.consistent_label_map[..200].iter().all(|&l| l == 0));
}

#[test]
fn a_segment_mostly_over_unmapped_space_is_new() {
    // 10 of its 200 pixels render label 1 (5 % < τ3): New, whatever those few render.
    let mut scene = Scene::new(20, 20);
    scene.input_rows(0..10, 11, 0.8);
    scene.rendered_span(0..10, 1).rendered_rows(10..20, 1);
    let mut consensus = consensus_with(&[0.9], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::New);
    assert_eq!(out.target_of(11), Some(&LabelTarget::Label(2)));
}

/// Input 5 covers the grid; rendered 1 rows 0..18 (its Full partner: mapped a = 360/400 = 0.9,
/// b = 1) and rendered 2 rows 18..20: wholly inside input 5 (b = 1) at a = 0.1, a fragment.
fn fragment_scene(cs: f32, fragment_completeness: f32) -> Scene {
    let mut scene = Scene::new(20, 20);
    scene.input_rows(0..20, 5, cs);
    scene.rendered_rows(0..18, 1).rendered_rows(18..20, 2);
    scene.completeness(2, fragment_completeness);
    scene
}

#[test]
fn a_fragment_beaten_by_the_segment_is_absorbed_whole_and_retires() {
    // C_s = 0.8 (completeness 1 everywhere) > C_r(2) = 0.6: every Gaussian of 2 takes 1.
    let scene = fragment_scene(0.8, 1.0);
    let at_once = ConsensusConfig {
        absorb_after_views: 1,
        ..config()
    };
    let mut consensus = consensus_with(&[0.5, 0.6], at_once);
    let out = scene.run(&mut consensus);
    assert_eq!(out.assignments[0].relation, Relation::Full);
    assert_eq!(
        out.relabels,
        vec![RelabelInstruction {
            from: 2,
            to: 1,
            pixels: Vec::new(),
            scope: RelabelScope::Label,
        }]
    );
    assert!(out.consistent_label_map.iter().all(|&l| l == 1));
    assert!(consensus.table().get(2).is_none(), "absorbed label retires");
    assert_relative_eq!(conf(&consensus, 1), 0.8);
    assert!(out.counter_pruning.iter().all(|r| r.label == 1));
}

#[test]
fn a_fragment_kept_or_far_out_of_view_or_switched_off_keeps_its_gaussians() {
    // (C_s, completeness of 2, absorb switch, C_r(2) after): kept by its higher confidence
    // (decayed by δ as a part); half out of view (completeness 0.4 < 0.5, no decay); switch off.
    let cases = [
        (0.8, 1.0, true, 0.84),
        (0.9, 0.4, true, 0.9),
        (0.95, 1.0, false, 0.9),
    ];
    for (cs, completeness, absorb, after) in cases {
        let scene = fragment_scene(cs, completeness);
        let cfg = ConsensusConfig {
            absorb_fragments: absorb,
            absorb_after_views: 1,
            ..config()
        };
        let mut consensus = consensus_with(&[0.5, 0.9], cfg);
        let out = scene.run(&mut consensus);
        assert!(
            out.relabels.is_empty(),
            "C_s {cs}, completeness {completeness}"
        );
        assert_relative_eq!(conf(&consensus, 2), after);
    }
}

#[test]
fn a_label_straddling_two_segments_is_no_fragment() {
    // Rendered 2 (rows 17..20) lies 2/3 inside input 5 (rows 0..19); the rest is inside input
    // 6 (rows 19..30, mostly unmapped: New). b = 2/3 < τ2, so 2 stays, whatever the confidences.
    let mut scene = Scene::new(20, 30);
    scene.input_rows(0..19, 5, 1.0).input_rows(19..30, 6, 1.0);
    scene.rendered_rows(0..17, 1).rendered_rows(17..20, 2);
    let mut consensus = consensus_with(&[0.5, 0.1], config());
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(5), Some(&LabelTarget::Label(1)));
    assert_eq!(out.assignments[1].relation, Relation::New);
    assert!(out.relabels.is_empty());
    assert_relative_eq!(conf(&consensus, 2), 0.1);
}

/// Input 7 on rows 18..20 only, over label 2: its own Full match (a = b = 1).
fn own_match_scene() -> Scene {
    let mut alone = Scene::new(20, 20);
    alone.input_rows(18..20, 7, 0.5);
    alone.rendered_rows(18..20, 2);
    alone
}

/// Whether a keyframe's output absorbed a whole label.
fn absorbed(out: &opengs_semantics::ConsensusOutput) -> bool {
    out.relabels.iter().any(|r| r.scope == RelabelScope::Label)
}

#[test]
fn a_fragment_is_absorbed_on_its_third_view_in_a_row_and_a_match_of_its_own_restarts_the_count() {
    let inside = fragment_scene(0.8, 1.0);
    let alone = own_match_scene();
    let mut consensus = consensus_with(&[0.5, 0.6], config());
    // Two views inside 5: decayed twice, kept.
    assert!(!absorbed(&inside.run(&mut consensus)));
    assert!(!absorbed(&inside.run(&mut consensus)));
    assert_relative_eq!(conf(&consensus, 2), 0.48, epsilon = 1e-6);
    assert_eq!(consensus.table().fragment_streak(2), 2);
    // Matched on its own: the count starts again.
    alone.run(&mut consensus);
    assert_eq!(consensus.table().fragment_streak(2), 0);
    assert!(!absorbed(&inside.run(&mut consensus)));
    assert!(!absorbed(&inside.run(&mut consensus)));
    assert!(absorbed(&inside.run(&mut consensus)));
    assert!(consensus.table().get(2).is_none());
}

#[test]
fn a_label_matched_on_its_own_five_times_takes_five_fragment_views_to_absorb() {
    let inside = fragment_scene(0.8, 1.0);
    let alone = own_match_scene();
    let mut consensus = consensus_with(&[0.5, 0.6], config());
    for _ in 0..5 {
        alone.run(&mut consensus);
    }
    assert_eq!(consensus.table().own_matches(2), 5);
    // Its own matches raised C_r to 0.6 at most (max(C_r, C_s = 0.5)); four views inside 5 decay
    // it to 0.36 < C_s = 0.8 and keep it, the fifth absorbs it.
    for view in 1..5 {
        assert!(!absorbed(&inside.run(&mut consensus)), "view {view}");
    }
    assert!(absorbed(&inside.run(&mut consensus)));
    assert!(consensus.table().get(2).is_none());
}
