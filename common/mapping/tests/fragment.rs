//! A label absorbed whole must lie on its host's surface (docs/METHOD.md §5.5): offsets measured
//! on hand-built planes, and the mapper keeping a label that stands off its host.

use approx::assert_relative_eq;
use opengs_geometry::{Intrinsics, Pose};
use opengs_mapping::{
    lies_on_host, median_offset_from_host, ConsensusUpdate, Mapper, MapperConfig,
};
use opengs_semantics::{RelabelInstruction, RelabelScope};
use opengs_splat::{Camera, Gaussian, GaussianMap};

/// A flat Gaussian (3 cm × 3 cm × 3 mm) with rotation `q` (w, x, y, z): its normal is R·z.
fn flat(mean: [f32; 3], q: [f32; 4], label: u32) -> Gaussian {
    Gaussian::from_values(mean, q, [0.03, 0.03, 0.003], 0.9, [0.5; 3], label)
}

const LEVEL: [f32; 4] = [1.0, 0.0, 0.0, 0.0];

/// Host label 1: a 10 × 10 grid, 5 cm apart, in the plane z = 0.
fn floor() -> GaussianMap {
    let mut map = GaussianMap::new();
    for i in 0..10 {
        for j in 0..10 {
            map.push(flat([i as f32 * 0.05, j as f32 * 0.05, 0.0], LEVEL, 1));
        }
    }
    map
}

/// The floor, with label 2: a strip 4 mm above it beside the grid, and label 3: a cup 5–10 cm
/// above its middle (six Gaussians each).
fn floor_strip_and_cup() -> GaussianMap {
    let mut map = floor();
    for k in 0..6 {
        map.push(flat([0.5, k as f32 * 0.05, 0.004], LEVEL, 2));
        map.push(flat([0.2, 0.2, 0.05 + k as f32 * 0.01], LEVEL, 3));
    }
    map
}

#[test]
fn a_strip_in_the_floor_lies_on_it_and_a_cup_on_it_does_not() {
    let map = floor_strip_and_cup();
    // Every strip Gaussian is 4 mm off the plane through its 8 nearest floor Gaussians.
    assert_relative_eq!(
        median_offset_from_host(&map, 2, 1).expect("both labels"),
        0.004,
        epsilon = 1e-6
    );
    // Cup offsets 5, 6, …, 10 cm: the median of six is the fourth, 8 cm.
    assert_relative_eq!(
        median_offset_from_host(&map, 3, 1).expect("both labels"),
        0.08,
        epsilon = 1e-6
    );
    assert!(lies_on_host(&map, 2, 1));
    assert!(!lies_on_host(&map, 3, 1));
    // Nothing to judge against: no host Gaussian.
    assert_eq!(median_offset_from_host(&map, 2, 9), None);
    assert!(!lies_on_host(&map, 2, 9));
    // Nothing left to move: trivially fine.
    assert!(lies_on_host(&map, 9, 1));
}

#[test]
fn the_host_plane_follows_the_gaussians_rotation() {
    // The grid tilted 30° about x: points (x, y cos 30°, y sin 30°), normal (0, −sin 30°, cos 30°).
    let (s, c) = (30f32.to_radians().sin(), 30f32.to_radians().cos());
    let half = 15f32.to_radians();
    let q = [half.cos(), half.sin(), 0.0, 0.0];
    let mut map = GaussianMap::new();
    for i in 0..10 {
        for j in 0..10 {
            let (x, y) = (i as f32 * 0.05, j as f32 * 0.05);
            map.push(flat([x, y * c, y * s], q, 1));
        }
    }
    // Label 2 sits 1.5 cm along the normal from in-plane points.
    for k in 0..5 {
        let (x, y) = (0.1 + k as f32 * 0.05, 0.2);
        map.push(flat([x, y * c - 0.015 * s, y * s + 0.015 * c], q, 2));
    }
    assert_relative_eq!(
        median_offset_from_host(&map, 2, 1).expect("both labels"),
        0.015,
        epsilon = 1e-5
    );
    assert!(lies_on_host(&map, 2, 1));
}

/// The floor strip (2) and the cup (3) relabelled to the floor (1) with `scope`, seen by a
/// camera 1 m above the floor: how many moved, which were kept back, the labels' sizes after.
fn relabel_strip_and_cup(scope: RelabelScope) -> (usize, Vec<u32>, [Option<u32>; 3]) {
    let mut m = Mapper::with_map(MapperConfig::default(), floor_strip_and_cup());
    // Looking down at the floor (+z of the camera is −z of the world).
    let pose = Pose::from_parts(
        nalgebra::Translation3::new(0.25, 0.25, 1.0),
        nalgebra::UnitQuaternion::from_axis_angle(
            &nalgebra::Vector3::x_axis(),
            std::f64::consts::PI,
        ),
    );
    let camera = Camera::from_pose(Intrinsics::new(64.0, 64.0, 32.0, 32.0, 64, 64), &pose, 0.05);
    m.render_for_consensus(7, &camera, 50);
    let labels = vec![0u32; 64 * 64];
    let relabels = [2, 3].map(|from| RelabelInstruction {
        from,
        to: 1,
        pixels: Vec::new(),
        scope,
    });
    let done = m
        .apply_consensus(&ConsensusUpdate {
            seq: 7,
            consistent_label_map: &labels,
            relabels: &relabels,
            counter_regions: &[],
            counter_prune_scale: 0.1,
        })
        .expect("valid update");
    let counts = m.map().count_per_label();
    let count = |l: u32| counts.get(&l).copied();
    (
        done.relabelled,
        done.kept_off_host,
        [count(1), count(2), count(3)],
    )
}

#[test]
fn the_mapper_absorbs_a_strip_whole_and_keeps_a_label_standing_off_its_host() {
    let (relabelled, kept, counts) = relabel_strip_and_cup(RelabelScope::Label);
    assert_eq!((relabelled, kept), (6, vec![3]));
    assert_eq!(counts, [Some(106), None, Some(6)]);
}

#[test]
fn a_whole_merge_moves_a_label_standing_off_the_surface_too() {
    // A Whole merge joins parts of one object that need not share a surface (a chair's seat
    // and back): no surface test, the cup standing 5 cm off the floor moves with the strip.
    let (relabelled, kept, counts) = relabel_strip_and_cup(RelabelScope::Merged);
    assert_eq!((relabelled, kept), (12, vec![]));
    assert_eq!(counts, [Some(112), None, None]);
}
