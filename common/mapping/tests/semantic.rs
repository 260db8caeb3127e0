//! The mapper's semantic loop on a hand-built map: render at a keyframe, then apply a
//! consensus result (relabel via top-K, counter pruning with θ, unlabelled Gaussians).

use opengs_geometry::{Intrinsics, Pose};
use opengs_mapping::{ConsensusApplyError, ConsensusUpdate, Mapper, MapperConfig};
use opengs_semantics::{CounterPruneRegion, RelabelInstruction, RelabelScope};
use opengs_splat::{Camera, Gaussian, GaussianMap};

const W: u32 = 64;

fn gaussian(x: f32, y: f32, z: f32, scale: f32, label: u32) -> Gaussian {
    Gaussian::from_values(
        [x, y, z],
        [1.0, 0.0, 0.0, 0.0],
        [scale; 3],
        0.99,
        [0.5; 3],
        label,
    )
}

fn camera() -> Camera {
    Camera::from_pose(
        Intrinsics::new(64.0, 64.0, 32.0, 32.0, W, W),
        &Pose::identity(),
        0.05,
    )
}

/// Pixel index of (u, v).
fn px(u: u32, v: u32) -> u32 {
    v * W + u
}

/// G0 small, label 5, at pixel (22, 32); G1 large (0.15 m), label 5, at (42, 32);
/// G2 small, unlabelled, at (42, 42); G3 unlabelled, hidden 2 m behind G0.
fn mapper() -> Mapper {
    let mut map = GaussianMap::new();
    map.push(gaussian(-0.3125, 0.0, 2.0, 0.05, 5));
    map.push(gaussian(0.3125, 0.0, 2.0, 0.15, 5));
    map.push(gaussian(0.3125, 0.3125, 2.0, 0.05, 0));
    map.push(gaussian(-0.625, 0.0, 4.0, 0.05, 0));
    Mapper::with_map(MapperConfig::default(), map)
}

fn update<'a>(
    labels: &'a [u32],
    relabels: &'a [RelabelInstruction],
    regions: &'a [CounterPruneRegion],
) -> ConsensusUpdate<'a> {
    ConsensusUpdate {
        seq: 7,
        consistent_label_map: labels,
        relabels,
        counter_regions: regions,
        counter_prune_scale: 0.10,
    }
}

#[test]
fn render_reports_labels_visibility_and_top_k() {
    let mut m = mapper();
    let r = m.render_for_consensus(7, &camera(), 50);
    assert_eq!(r.label_map[px(22, 32) as usize], 5);
    assert_eq!(r.label_map[px(42, 32) as usize], 5);
    assert_eq!(r.label_map[px(5, 5) as usize], 0);
    // Two Gaussians carry label 5 and both are visible.
    assert_eq!(r.visibility.len(), 1);
    assert_eq!(
        (
            r.visibility[0].label,
            r.visibility[0].visible,
            r.visibility[0].total
        ),
        (5, 2, 2)
    );
    assert!((r.surface_depth[px(42, 42) as usize] - 2.0).abs() < 1e-3);
    assert_eq!(m.pending_renders().len(), 1);
}

#[test]
fn relabel_goes_through_top_k_of_the_listed_pixels_only() {
    let mut m = mapper();
    m.render_for_consensus(7, &camera(), 50);
    let labels = vec![0u32; (W * W) as usize];
    let relabels = [RelabelInstruction {
        from: 5,
        to: 8,
        pixels: vec![px(22, 32)],
        scope: RelabelScope::Pixels,
    }];
    let done = m.apply_consensus(&update(&labels, &relabels, &[])).unwrap();
    assert_eq!(done.relabelled, 1);
    assert_eq!(&m.map().labels, &[8, 5, 0, 0]);
    // The render was used up.
    assert!(matches!(
        m.apply_consensus(&update(&labels, &relabels, &[])),
        Err(ConsensusApplyError::NoRender(7))
    ));
}

#[test]
fn counter_pruning_removes_only_gaussians_larger_than_theta() {
    let mut m = mapper();
    m.render_for_consensus(7, &camera(), 50);
    let labels = vec![0u32; (W * W) as usize];
    let regions = [CounterPruneRegion {
        label: 5,
        pixels: vec![px(22, 32), px(42, 32)],
    }];
    let done = m.apply_consensus(&update(&labels, &[], &regions)).unwrap();
    assert_eq!(done.pruned, 1);
    // G1 (0.15 m > θ = 0.10 m) is gone, G0 (0.05 m) stays.
    assert_eq!(m.map().len(), 3);
    assert_eq!(&m.map().labels, &[5, 0, 0]);
    assert!((m.map().scale(0)[0] - 0.05).abs() < 1e-6);
}

#[test]
fn unlabelled_gaussians_on_the_surface_take_the_consistent_label() {
    let mut m = mapper();
    m.render_for_consensus(7, &camera(), 50);
    let mut labels = vec![0u32; (W * W) as usize];
    labels[px(42, 42) as usize] = 9;
    labels[px(22, 32) as usize] = 4; // G3 projects here too, but 2 m behind the surface.
    let done = m.apply_consensus(&update(&labels, &[], &[])).unwrap();
    assert_eq!(done.labelled, 1);
    assert_eq!(&m.map().labels, &[5, 5, 9, 0]);
}

#[test]
fn wrong_sizes_and_pixels_are_rejected_without_changes() {
    let mut m = mapper();
    m.render_for_consensus(7, &camera(), 50);
    let short = vec![0u32; 10];
    assert!(matches!(
        m.apply_consensus(&update(&short, &[], &[])),
        Err(ConsensusApplyError::SizeMismatch { .. })
    ));
    m.render_for_consensus(7, &camera(), 50);
    let labels = vec![0u32; (W * W) as usize];
    let relabels = [RelabelInstruction {
        from: 5,
        to: 8,
        pixels: vec![W * W + 3],
        scope: RelabelScope::Pixels,
    }];
    assert!(matches!(
        m.apply_consensus(&update(&labels, &relabels, &[])),
        Err(ConsensusApplyError::Invalid { .. })
    ));
    assert_eq!(&m.map().labels, &[5, 5, 0, 0]);
}

#[test]
fn pending_top_k_follows_a_compaction() {
    let mut m = mapper();
    m.render_for_consensus(7, &camera(), 50);
    // Prune G0 by a consensus of another render, then relabel through the first one.
    m.render_for_consensus(8, &camera(), 50);
    let labels = vec![0u32; (W * W) as usize];
    let regions = [CounterPruneRegion {
        label: 5,
        pixels: vec![px(42, 32)],
    }];
    let mut u = update(&labels, &[], &regions);
    u.seq = 8;
    assert_eq!(m.apply_consensus(&u).unwrap().pruned, 1);
    let relabels = [RelabelInstruction {
        from: 5,
        to: 6,
        pixels: vec![px(22, 32), px(42, 32)],
        scope: RelabelScope::Pixels,
    }];
    let done = m.apply_consensus(&update(&labels, &relabels, &[])).unwrap();
    // G1 is gone from the kept lists; G0 (still index 0) is relabelled.
    assert_eq!(done.relabelled, 1);
    assert_eq!(&m.map().labels, &[6, 0, 0]);
}

#[test]
fn the_next_keyframe_render_reuses_the_buffers_and_sees_the_relabel() {
    let mut m = mapper();
    let labels = vec![0u32; (W * W) as usize];
    m.render_for_consensus(7, &camera(), 50);
    let first = [RelabelInstruction {
        from: 5,
        to: 8,
        pixels: vec![px(22, 32)],
        scope: RelabelScope::Pixels,
    }];
    m.apply_consensus(&update(&labels, &first, &[])).unwrap();
    // Keyframe 8 renders into the buffers (top-K included) that keyframe 7's consensus gave back.
    let r = m.render_for_consensus(8, &camera(), 50);
    assert_eq!(r.label_map[px(22, 32) as usize], 8);
    assert_eq!(r.label_map[px(42, 32) as usize], 5);
    let second = [RelabelInstruction {
        from: 5,
        to: 9,
        pixels: vec![px(42, 32)],
        scope: RelabelScope::Pixels,
    }];
    let done = m
        .apply_consensus(&ConsensusUpdate {
            seq: 8,
            ..update(&labels, &second, &[])
        })
        .unwrap();
    assert_eq!(done.relabelled, 1);
    assert_eq!(&m.map().labels, &[8, 9, 0, 0]);
}

/// A label voted from a faint edge or from behind unlabelled Gaussians is not the map's claim:
/// those pixels render 0 for the consensus (`MIN_LABELLED_COVER`).
#[test]
fn pixels_where_labelled_gaussians_weigh_under_half_render_unmapped() {
    let mut map = GaussianMap::new();
    // G0: label 5 at pixel (22, 32), 0.05 m at 2 m: σ ≈ 64·0.05/2 = 1.6 px.
    map.push(gaussian(-0.3125, 0.0, 2.0, 0.05, 5));
    // G1: unlabelled, opacity 0.95, at pixel (42, 42), 2 m in front of G2 (label 7, 0.4 m at
    // 4 m: σ ≈ 6.4 px).
    map.push(Gaussian::from_values(
        [0.3125, 0.3125, 2.0],
        [1.0, 0.0, 0.0, 0.0],
        [0.05; 3],
        0.95,
        [0.5; 3],
        0,
    ));
    map.push(gaussian(0.625, 0.625, 4.0, 0.4, 7));
    let mut m = Mapper::with_map(MapperConfig::default(), map);
    let r = m.render_for_consensus(7, &camera(), 50);
    // G0's centre: α ≈ 0.99.
    assert_eq!(r.label_map[px(22, 32) as usize], 5);
    // 4 px from G0's centre only its tail reaches: α ≈ 0.99·exp(−0.5·16/1.6²) ≈ 0.04.
    let tail = r.top_k.weight_of(px(26, 32) as usize, 0).unwrap_or(0.0);
    assert!(tail > 0.01 && tail < 0.1, "tail weight {tail}");
    assert_eq!(r.label_map[px(26, 32) as usize], 0);
    // Behind G1, G2 weighs about (1 − 0.95)·0.99 ≈ 0.05; label 0 never wins a vote, so
    // without the rule the pixel would be 7.
    let behind = r.top_k.weight_of(px(42, 42) as usize, 2).unwrap_or(0.0);
    assert!(behind > 0.03 && behind < 0.07, "weight behind {behind}");
    assert_eq!(r.label_map[px(42, 42) as usize], 0);
    // 6 px away G1 is gone and G2 weighs 0.99·exp(−0.5·36/6.4²) ≈ 0.64: label 7.
    assert_eq!(r.label_map[px(48, 42) as usize], 7);
}
