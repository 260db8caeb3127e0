//! A label absorbed whole must lie on its host's surface (docs/METHOD.md §5.5): offsets measured
//! on hand-built planes, the mapper keeping a label that stands off its host, and a label split
//! off a surface going back to it where it lies on it.

use approx::assert_relative_eq;
use opengs_geometry::{Intrinsics, Pose};
use opengs_mapping::{
    lies_on_host, median_offset_from_host, ConsensusApplied, ConsensusUpdate, Mapper, MapperConfig,
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

/// A 64 × 64 camera 1 m above (0.25, 0.25) looking down at the floor (its +z is the world's −z).
fn looking_down() -> Camera {
    let pose = Pose::from_parts(
        nalgebra::Translation3::new(0.25, 0.25, 1.0),
        nalgebra::UnitQuaternion::from_axis_angle(
            &nalgebra::Vector3::x_axis(),
            std::f64::consts::PI,
        ),
    );
    Camera::from_pose(Intrinsics::new(64.0, 64.0, 32.0, 32.0, 64, 64), &pose, 0.05)
}

/// Renders `m`'s map for keyframe 7 from [`looking_down`] and applies a consensus with the
/// consistent label map `labels` that moves labels 2 and 3 to 1 with `scope`.
fn labels_2_and_3_to_1(m: &mut Mapper, labels: &[u32], scope: RelabelScope) -> ConsensusApplied {
    m.render_for_consensus(7, &looking_down(), 50);
    let relabels = [2, 3].map(|from| RelabelInstruction {
        from,
        to: 1,
        pixels: Vec::new(),
        scope,
    });
    m.apply_consensus(&ConsensusUpdate {
        seq: 7,
        consistent_label_map: labels,
        relabels: &relabels,
        counter_regions: &[],
        counter_prune_scale: 0.1,
    })
    .expect("valid update")
}

/// The floor strip (2) and the cup (3) relabelled to the floor (1) with `scope`, seen by a
/// camera 1 m above the floor: how many moved, which were kept back, the labels' sizes after.
fn relabel_strip_and_cup(scope: RelabelScope) -> (usize, Vec<u32>, [Option<u32>; 3]) {
    let mut m = Mapper::with_map(MapperConfig::default(), floor_strip_and_cup());
    let done = labels_2_and_3_to_1(&mut m, &vec![0u32; 64 * 64], scope);
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

#[test]
fn a_split_off_piece_of_the_floor_rejoins_it_and_a_cup_keeps_its_fresh_label() {
    // The strip and the cup unlabelled (the map left them so); the consensus split both off
    // the floor (1) with fresh labels 2 and 3 and asks them to rejoin it.
    let mut map = floor_strip_and_cup();
    for l in map.labels.iter_mut().filter(|l| **l != 1) {
        *l = 0;
    }
    let mut m = Mapper::with_map(MapperConfig::default(), map);
    // The consistent label map: 2 at the strip's pixels (world x = 0.5, u = 48), 3 around the
    // cup's (world (0.2, 0.2): u ≈ 28, v ≈ 36), the floor's label elsewhere.
    let labels: Vec<u32> = (0..64 * 64)
        .map(|p| match (p % 64, p / 64) {
            (u, _) if u >= 46 => 2,
            (24..=32, 32..=40) => 3,
            _ => 1,
        })
        .collect();
    let done = labels_2_and_3_to_1(&mut m, &labels, RelabelScope::Rejoin);
    // All twelve took their pixel's label; the strip (4 mm off the floor) went back whole, the
    // cup (median 8 cm off) kept its own.
    assert_eq!(done.labelled, 12);
    assert_eq!(done.rejoined, vec![2]);
    assert_eq!(done.relabelled, 0);
    let counts = m.map().count_per_label();
    assert_eq!(
        [1, 2, 3].map(|l| counts.get(&l).copied()),
        [Some(106), None, Some(6)]
    );
}
