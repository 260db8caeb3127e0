//! Top-K application (§4) and counter-pruning selection (§5.3) on a hand-built record.

mod common;

use common::{consensus_with, Scene};
use opengs_semantics::{
    apply_relabels, apply_relabels_centred, select_counter_gaussians, ConsensusConfig,
    CounterPruneRegion, RelabelInstruction, RelabelScope, SemanticsError,
};
use opengs_splat::TopK;

/// Four pixels (a 4×1 image) and the Gaussian ids in each one's top-K, front to back.
const LISTS: [&[u32]; 4] = [&[0, 1, 2], &[1, 3], &[4], &[5]];
/// Gaussian labels g0..g5.
const LABELS: [u32; 6] = [1, 1, 2, 1, 1, 1];
/// Largest scale (metres) of g0..g5.
const MAX_SCALE: [f32; 6] = [0.05, 0.2, 0.5, 0.11, 0.3, 0.10];

fn view() -> TopK {
    let lists: Vec<Vec<(u32, f32)>> = LISTS
        .iter()
        .map(|ids| ids.iter().map(|&id| (id, 0.5)).collect())
        .collect();
    TopK::from_lists(4, 1, &lists)
}

#[test]
fn counter_pruning_selection_table() {
    // (θ, region label, region pixels, expected Gaussian ids)
    let cases: [(f32, u32, &[u32], &[u32]); 6] = [
        (0.10, 1, &[0, 1, 3], &[1, 3]), // g0 too small, g5 exactly θ (not above), g2 other label
        (0.10, 1, &[0, 1, 2, 3], &[1, 3, 4]),
        (0.25, 1, &[0, 1, 2], &[4]),
        (0.10, 2, &[0], &[2]),
        (0.01, 1, &[3], &[5]),
        (0.10, 1, &[], &[]),
    ];
    for (theta, label, pixels, expected) in cases {
        let regions = [CounterPruneRegion {
            label,
            pixels: pixels.to_vec(),
        }];
        let got = select_counter_gaussians(&view(), &LABELS, |g| MAX_SCALE[g], theta, &regions);
        assert_eq!(
            got.as_deref(),
            Ok(expected),
            "θ={theta} label={label} pixels={pixels:?}"
        );
    }
}

#[test]
fn selection_is_sorted_and_unique_across_regions() {
    let regions = [
        CounterPruneRegion {
            label: 1,
            pixels: vec![1, 0],
        },
        CounterPruneRegion {
            label: 1,
            pixels: vec![0],
        },
    ];
    let got = select_counter_gaussians(&view(), &LABELS, |g| MAX_SCALE[g], 0.1, &regions);
    assert_eq!(got, Ok(vec![1, 3]));
}

#[test]
fn relabel_changes_only_from_label_in_listed_pixels() {
    let mut labels = LABELS;
    let relabels = [RelabelInstruction {
        from: 1,
        to: 7,
        pixels: vec![0, 1],
        scope: RelabelScope::Pixels,
    }];
    assert_eq!(apply_relabels(&view(), &mut labels, &relabels), Ok(3));
    assert_eq!(labels, [7, 7, 2, 7, 1, 1]);
}

#[test]
fn a_centred_relabel_moves_only_gaussians_centred_in_its_pixels() {
    // Region pixels 0, 1 (label 1 there: g0, g1, g3). g1 is a large Gaussian centred on
    // pixel 3, outside the region: it overlaps the segment but belongs to what lies around
    // it, and stays. g0's centre is unknown (behind the camera): it moves, as before.
    let centres: [Option<usize>; 6] = [None, Some(3), Some(0), Some(1), Some(2), Some(3)];
    let mut labels = LABELS;
    let relabels = [RelabelInstruction {
        from: 1,
        to: 7,
        pixels: vec![0, 1],
        scope: RelabelScope::Pixels,
    }];
    let moved = apply_relabels_centred(&view(), &mut labels, &relabels, |g| centres[g as usize]);
    assert_eq!(moved, Ok(2));
    assert_eq!(labels, [7, 1, 2, 7, 1, 1]);
    // A label-scope instruction moves the whole label whatever the centres.
    let whole = [RelabelInstruction {
        from: 1,
        to: 9,
        pixels: Vec::new(),
        scope: RelabelScope::Label,
    }];
    let moved = apply_relabels_centred(&view(), &mut labels, &whole, |g| centres[g as usize]);
    assert_eq!((moved, labels), (Ok(3), [7, 9, 2, 7, 9, 9]));
}

#[test]
fn relabel_instructions_apply_in_order() {
    let mut labels = LABELS;
    let relabels = [
        RelabelInstruction {
            from: 2,
            to: 8,
            pixels: vec![0],
            scope: RelabelScope::Pixels,
        },
        RelabelInstruction {
            from: 1,
            to: 9,
            pixels: vec![2, 3],
            scope: RelabelScope::Pixels,
        },
    ];
    assert_eq!(apply_relabels(&view(), &mut labels, &relabels), Ok(3));
    assert_eq!(labels, [1, 1, 8, 1, 9, 9]);
}

#[test]
fn bad_indices_are_errors_and_change_nothing() {
    let mut labels = LABELS;
    let relabels = [
        RelabelInstruction {
            from: 1,
            to: 7,
            pixels: vec![0],
            scope: RelabelScope::Pixels,
        },
        RelabelInstruction {
            from: 1,
            to: 7,
            pixels: vec![4],
            scope: RelabelScope::Pixels,
        },
    ];
    assert_eq!(
        apply_relabels(&view(), &mut labels, &relabels),
        Err(SemanticsError::PixelOutOfRange {
            pixel: 4,
            pixels: 4
        })
    );
    assert_eq!(labels, LABELS);
    // Only five Gaussians: id 5 in pixel 3 is out of range.
    let mut short = [1u32; 5];
    let relabels = [RelabelInstruction {
        from: 1,
        to: 7,
        pixels: vec![3],
        scope: RelabelScope::Pixels,
    }];
    assert_eq!(
        apply_relabels(&view(), &mut short, &relabels),
        Err(SemanticsError::GaussianOutOfRange {
            id: 5,
            gaussians: 5
        })
    );
    let regions = [CounterPruneRegion {
        label: 1,
        pixels: vec![9],
    }];
    assert!(select_counter_gaussians(&view(), &LABELS, |g| MAX_SCALE[g], 0.1, &regions).is_err());
}

#[test]
fn full_match_prune_region_is_the_symmetric_difference() {
    // 20×5 grid: input 10 on pixels 0..90, rendered 1 on 5..95 → a = b = 85/90: Full; input
    // 11 on 90..100 (pixels without a segment would say nothing, docs/METHOD.md §5.5).
    let mut scene = Scene::new(20, 5);
    scene
        .input_span(0..90, 10, 0.9)
        .input_span(90..100, 11, 0.9)
        .rendered_span(5..95, 1);
    let mut consensus = consensus_with(&[0.5], ConsensusConfig::default());
    let out = scene.run(&mut consensus);
    let expected: Vec<u32> = (0..5).chain(90..95).collect();
    assert_eq!(
        out.counter_pruning,
        vec![CounterPruneRegion {
            label: 1,
            pixels: expected
        }]
    );
}

#[test]
fn partial_split_applied_through_top_k() {
    // Consensus on a 2×2 image: rendered 1 everywhere, input 5 on pixel 0 (a = 1, b = 0.25)
    // beats C_r, so Gaussians labelled 1 in pixel 0's top-K move to the fresh label 2.
    let mut scene = Scene::new(2, 2);
    scene
        .rendered_span(0..4, 1)
        .input_span(0..1, 5, 0.9)
        .input_span(1..4, 6, 0.1);
    let mut consensus = consensus_with(&[0.2], ConsensusConfig::default());
    let out = scene.run(&mut consensus);
    let mut labels = [1, 1, 1, 1, 1, 1];
    apply_relabels(&view(), &mut labels, &out.relabels).expect("valid");
    assert_eq!(labels, [2, 2, 2, 1, 1, 1]);
}

#[test]
fn a_whole_label_relabel_reaches_gaussians_no_pixel_lists() {
    // g4 and g5 are labelled 1 but appear in no listed pixel; a whole-label relabel moves them
    // too, and a pixel relabel after it finds no 1 left.
    let mut labels = LABELS;
    let relabels = [
        RelabelInstruction {
            from: 1,
            to: 3,
            pixels: Vec::new(),
            scope: RelabelScope::Label,
        },
        RelabelInstruction {
            from: 1,
            to: 7,
            pixels: vec![0, 1, 2, 3],
            scope: RelabelScope::Pixels,
        },
    ];
    assert_eq!(apply_relabels(&view(), &mut labels, &relabels), Ok(5));
    assert_eq!(labels, [3, 3, 2, 3, 3, 3]);
}
