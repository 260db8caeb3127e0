//! Object operations on hand-built maps: list, pick, extract, remove, move, rotate.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use opengs_geometry::{Intrinsics, Pose};
use opengs_objects::{
    apply, compare_edit, list_objects, pick_pixel, split, Catalog, ObjectError, RigidMotion,
    Selection,
};
use opengs_semantics::LabelRecord;
use opengs_splat::{render, Camera, Gaussian, GaussianMap, RenderOutput, RenderRequest};

const SCALE: f32 = 0.01;

/// An axis-aligned Gaussian (identity rotation).
fn blob(mean: [f32; 3], scale: [f32; 3], opacity: f32, colour: [f32; 3], label: u32) -> Gaussian {
    Gaussian::from_values(mean, [1.0, 0.0, 0.0, 0.0], scale, opacity, colour, label)
}

fn gaussian(mean: [f32; 3], opacity: f32, label: u32) -> Gaussian {
    blob(mean, [SCALE; 3], opacity, [0.8, 0.3, 0.1], label)
}

/// A `nx × ny × nz` lattice filling the box `size` (edges included), turned by `turn` about
/// its centre `centre`.
fn lattice(
    map: &mut GaussianMap,
    label: u32,
    centre: [f64; 3],
    size: [f64; 3],
    n: [usize; 3],
    turn: UnitQuaternion<f64>,
) {
    for i in 0..n[0] {
        for j in 0..n[1] {
            for k in 0..n[2] {
                let t = [i, j, k];
                let local =
                    Vector3::from_fn(|a, _| size[a] * (t[a] as f64 / (n[a] - 1) as f64 - 0.5));
                let p = Vector3::from(centre) + turn * local;
                map.push(gaussian([p.x as f32, p.y as f32, p.z as f32], 0.9, label));
            }
        }
    }
}

fn catalog(rows: &[(u32, &str)]) -> Catalog {
    let records = rows
        .iter()
        .map(|&(id, class)| LabelRecord {
            id,
            class: Some(class.to_string()),
            score: 0.9,
            confidence: 1.0,
            gaussians: 0,
        })
        .collect();
    Catalog::from_records(records, "labels.json")
}

/// 64×48 pinhole camera, f = 100 px, principal point on pixel (32, 24).
fn camera(pose: &Pose) -> Camera {
    Camera::from_pose(
        Intrinsics::new(100.0, 100.0, 32.0, 24.0, 64, 48),
        pose,
        0.05,
    )
}

fn semantic_render(map: &GaussianMap, camera: &Camera) -> opengs_splat::Rendered {
    let request = RenderRequest {
        labels: true,
        ..RenderRequest::color_depth()
    };
    render(map, camera, &request)
}

fn max_difference(a: &RenderOutput, b: &RenderOutput) -> f32 {
    let colour = a
        .color
        .iter()
        .zip(&b.color)
        .flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs()));
    let depth = a.depth.iter().zip(&b.depth).map(|(x, y)| (x - y).abs());
    let alpha = a
        .silhouette
        .iter()
        .zip(&b.silhouette)
        .map(|(x, y)| (x - y).abs());
    colour.chain(depth).chain(alpha).fold(0.0, f32::max)
}

/// Every field of every Gaussian as bits, for exact comparisons.
fn bits(map: &GaussianMap) -> Vec<Vec<u32>> {
    (0..map.len())
        .map(|i| {
            let g = map.get(i);
            g.mean
                .iter()
                .chain(&g.rotation)
                .chain(&g.log_scale)
                .chain(std::iter::once(&g.opacity_logit))
                .chain(&g.sh_dc)
                .map(|v| v.to_bits())
                .chain(std::iter::once(g.label))
                .collect()
        })
        .collect()
}

/// Anisotropic, turned Gaussians of two labels in front of the camera (for render checks).
fn two_objects() -> GaussianMap {
    let mut map = GaussianMap::new();
    for k in 0..40 {
        let t = k as f32 * 0.37;
        let label = if k % 3 == 0 { 2 } else { 4 };
        let rotation = [t.cos(), 0.3 * t.sin(), -0.5, 0.2 * (2.0 * t).cos()];
        map.push(Gaussian::from_values(
            [0.3 * t.sin(), 0.2 * (1.3 * t).cos(), 2.0 + 0.1 * t.sin()],
            rotation,
            [
                0.05 + 0.01 * (k % 4) as f32,
                0.02,
                0.008 + 0.004 * (k % 3) as f32,
            ],
            0.4 + 0.5 * ((k * 7 % 11) as f32 / 11.0),
            [0.2 + 0.02 * k as f32, 0.5, 0.9 - 0.02 * k as f32],
            label,
        ));
    }
    map
}

#[test]
fn list_finds_each_object_with_its_count_and_boxes() {
    let mut map = GaussianMap::new();
    // Label 3: a 5×4×3 lattice filling 1.0 × 0.6 × 0.4 m at (2, 1, 0.5), plus a stray 20 m away
    // and a Gaussian too transparent to show.
    lattice(
        &mut map,
        3,
        [2.0, 1.0, 0.5],
        [1.0, 0.6, 0.4],
        [5, 4, 3],
        UnitQuaternion::identity(),
    );
    map.push(gaussian([22.0, 21.0, 20.5], 0.9, 3));
    map.push(gaussian([2.1, 1.0, 0.5], 0.001, 3));
    // Label 7: a 6×3×2 lattice filling 0.5 × 0.2 × 0.1 m, turned 30° about z.
    let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians());
    lattice(
        &mut map,
        7,
        [-1.0, 0.0, 1.0],
        [0.5, 0.2, 0.1],
        [6, 3, 2],
        turn,
    );
    // Unlabelled Gaussians are no object.
    map.push(gaussian([0.0, 0.0, 0.0], 0.9, 0));
    let classes = catalog(&[(3, "table"), (7, "book")]);

    let rows = list_objects(&map, Some(&classes));
    assert_eq!(
        rows.iter().map(|r| r.id).collect::<Vec<_>>(),
        vec![3, 7],
        "largest first"
    );
    let table = &rows[0];
    assert_eq!(
        (table.class.as_deref(), table.gaussians),
        (Some("table"), 62)
    );
    let e = table.extent.as_ref().expect("visible");
    assert_eq!((e.kept, e.trimmed), (60, 2));
    for k in 0..3 {
        let (lo, hi) = ([1.5, 0.7, 0.3][k], [2.5, 1.3, 0.7][k]);
        assert!(
            (e.aabb.min[k] - lo).abs() < 1e-6 && (e.aabb.max[k] - hi).abs() < 1e-6,
            "{:?}",
            e.aabb
        );
        assert!(
            (e.centroid[k] - [2.0, 1.0, 0.5][k]).abs() < 1e-6,
            "{:?}",
            e.centroid
        );
        assert!(
            (e.obb.half_extents[k] - [0.5, 0.3, 0.2][k]).abs() < 1e-6,
            "{:?}",
            e.obb
        );
    }
    // Volume: the box grown by one Gaussian diameter (2 × 1 cm).
    let d = 2.0 * f64::from(SCALE);
    let volume = (1.0 + d) * (0.6 + d) * (0.4 + d);
    assert!((e.volume - volume).abs() < 1e-5, "{} vs {volume}", e.volume);

    let book = &rows[1];
    assert_eq!((book.class.as_deref(), book.gaussians), (Some("book"), 36));
    let e = book.extent.as_ref().expect("visible");
    assert_eq!(e.trimmed, 0);
    for k in 0..3 {
        assert!(
            (e.obb.half_extents[k] - [0.25, 0.1, 0.05][k]).abs() < 1e-6,
            "{:?}",
            e.obb
        );
        assert!(
            (e.obb.center[k] - [-1.0, 0.0, 1.0][k]).abs() < 1e-6,
            "{:?}",
            e.obb
        );
    }
    // Its long axis is x turned 30° about z; the axis-aligned box is larger than the turned one.
    let long = Vector3::from(e.obb.axes[0]);
    assert!(
        (long.dot(&(turn * Vector3::x())).abs() - 1.0).abs() < 1e-9,
        "{long}"
    );
    let aabb_x = e.aabb.max[0] - e.aabb.min[0];
    let expected_x = 0.5 * 30f64.to_radians().cos() + 0.2 * 30f64.to_radians().sin();
    assert!(
        (aabb_x - expected_x).abs() < 1e-6,
        "{aabb_x} vs {expected_x}"
    );
}

#[test]
fn pick_at_a_pixel_of_a_known_object_returns_it() {
    let mut map = GaussianMap::new();
    // x = ∓0.5 m at 2 m: pixels u = 32 ∓ 25.
    map.push(blob([-0.5, 0.0, 2.0], [0.05; 3], 0.8, [1.0, 0.0, 0.0], 11));
    map.push(blob([0.5, 0.0, 2.0], [0.05; 3], 0.8, [0.0, 1.0, 0.0], 12));
    let rendered = semantic_render(&map, &camera(&Pose::identity()));
    let left = pick_pixel(&map, &rendered, 7, 24).expect("object 11 there");
    assert_eq!(left.label, 11);
    assert!((left.weight - 0.8).abs() < 1e-4, "{left:?}");
    assert_eq!(
        pick_pixel(&map, &rendered, 57, 24)
            .expect("object 12")
            .label,
        12
    );
    match pick_pixel(&map, &rendered, 32, 24) {
        Err(ObjectError::EmptySelection(m)) => assert!(m.contains("(32, 24)"), "{m}"),
        other => panic!("nothing is at the centre, got {other:?}"),
    }
    match pick_pixel(&map, &rendered, 64, 3) {
        Err(e @ ObjectError::PixelOutside { .. }) => {
            assert!(e.to_string().contains("64x48"), "{e}")
        }
        other => panic!("outside the image, got {other:?}"),
    }
}

#[test]
fn overlapping_labels_give_the_gs_voting_winner_not_the_front_one() {
    // On the optical axis: label 5 in front (α 0.3), label 9 behind it twice (α 0.3 each).
    // Weights α·T: 5 → 0.3; 9 → 0.7·0.3 + 0.49·0.3 = 0.357. The vote goes to 9.
    let mut map = GaussianMap::new();
    for (z, label) in [(1.0, 5), (2.0, 9), (3.0, 9)] {
        map.push(blob([0.0, 0.0, z], [0.05; 3], 0.3, [0.5; 3], label));
    }
    let rendered = semantic_render(&map, &camera(&Pose::identity()));
    let pick = pick_pixel(&map, &rendered, 32, 24).expect("labelled pixel");
    assert_eq!(pick.label, 9);
    assert!((pick.weight - 0.357).abs() < 1e-4, "{pick:?}");
    assert!(
        (pick.alpha - (1.0 - 0.7f32.powi(3))).abs() < 1e-4,
        "{pick:?}"
    );
    let front = pick
        .votes
        .iter()
        .find(|v| v.label == 5)
        .expect("label 5 seen");
    assert!((front.weight - 0.3).abs() < 1e-4);
    // The single heaviest Gaussian there is the front one: voting, not top-1, decided.
    let heaviest = rendered.top_k_at(32, 24, 1);
    assert_eq!(map.labels[heaviest[0].0 as usize], 5);
}

#[test]
fn extract_plus_the_rest_is_the_map_bit_for_bit() {
    let map = opengs_splat::scene::indoor_scene(3000, 7);
    let labels: Vec<u32> = map
        .count_per_label()
        .into_keys()
        .filter(|&l| l != 0)
        .take(2)
        .collect();
    let selection = Selection::of_labels(&map, None, &labels).expect("labels of the map");
    let (object, rest) = split(&map, &selection);
    let expected: usize = labels
        .iter()
        .map(|&l| map.indices_with_label(l).len())
        .sum();
    assert!(expected > 0);
    assert_eq!((object.len(), rest.len()), (expected, map.len() - expected));
    assert!(object.labels.iter().all(|l| labels.contains(l)));
    // Interleaving the two parts back by the selection gives the map, bit for bit.
    let (mut from_object, mut from_rest) = (bits(&object).into_iter(), bits(&rest).into_iter());
    let merged: Vec<Vec<u32>> = selection
        .mask(&map)
        .iter()
        .map(|&selected| {
            if selected {
                from_object.next()
            } else {
                from_rest.next()
            }
        })
        .collect::<Option<_>>()
        .expect("as many as selected");
    assert_eq!(merged, bits(&map));
    // The extracted object survives a PLY round trip unchanged, labels included.
    let mut ply = Vec::new();
    opengs_splat::write_ply(&object, &mut ply).expect("write to memory");
    let back = opengs_splat::read_ply(&ply).expect("read back");
    assert_eq!(bits(&back), bits(&object));
}

#[test]
fn remove_leaves_no_gaussian_of_the_label() {
    let map = opengs_splat::scene::indoor_scene(3000, 3);
    let label = *map
        .count_per_label()
        .keys()
        .find(|&&l| l != 0)
        .expect("a label");
    let selection = Selection::of_labels(&map, None, &[label]).expect("in the map");
    let (removed, rest) = split(&map, &selection);
    assert!(!removed.is_empty());
    assert!(rest.labels.iter().all(|&l| l != label));
    assert_eq!(rest.len(), map.len() - removed.len());
    // Every other label keeps all its Gaussians.
    for (l, n) in map.count_per_label() {
        if l != label {
            assert_eq!(rest.count_per_label().get(&l), Some(&n), "label {l}");
        }
    }
}

#[test]
fn moving_by_t_renders_as_the_original_seen_from_a_camera_moved_by_minus_t() {
    let map = two_objects();
    let selection = Selection::of_labels(&map, None, &[4]).expect("label 4");
    let (object, _) = split(&map, &selection);
    let t = Vector3::new(0.3, -0.2, 0.5);
    let mut moved = object.clone();
    let n = apply(
        &mut moved,
        &selection,
        &RigidMotion::translation(t.into()).expect("finite"),
    );
    assert_eq!(n, object.len());
    // Only the means changed.
    assert_eq!(moved.rotations, object.rotations);
    let pose: Pose = Isometry3::from_parts(
        Translation3::new(0.2, 0.1, 0.6),
        UnitQuaternion::from_euler_angles(0.05, -0.1, 0.08),
    );
    let mut moved_back = pose;
    moved_back.translation.vector -= t;
    let a = semantic_render(&moved, &camera(&pose)).output;
    let b = semantic_render(&object, &camera(&moved_back)).output;
    assert!(
        a.silhouette.iter().filter(|&&s| s > 0.5).count() > 100,
        "the object is in view"
    );
    let diff = max_difference(&a, &b);
    assert!(diff < 1e-4, "max difference {diff}");
    assert_eq!(a.labels, b.labels);
}

#[test]
fn rotating_renders_as_the_original_seen_from_the_inversely_turned_camera() {
    // Checks the quaternion composition: wrong order would turn the anisotropic Gaussians wrongly.
    let map = two_objects();
    let selection = Selection::of_labels(&map, None, &[2, 4]).expect("labels");
    let pivot = [0.1, -0.05, 2.1];
    let motion = RigidMotion::rotation_about([0.3, 1.0, -0.2], 25.0, pivot).expect("valid");
    let mut turned = map.clone();
    apply(&mut turned, &selection, &motion);
    // Camera-to-world P sees M·object as M⁻¹·P sees the object.
    let m: Isometry3<f64> = Isometry3::from_parts(
        Translation3::from(Vector3::from(pivot) - motion.rotation * Vector3::from(pivot)),
        motion.rotation,
    );
    let pose: Pose = Isometry3::from_parts(
        Translation3::new(0.0, 0.05, 0.3),
        UnitQuaternion::identity(),
    );
    let a = semantic_render(&turned, &camera(&pose)).output;
    let b = semantic_render(&map, &camera(&(m.inverse() * pose))).output;
    assert!(
        a.silhouette.iter().filter(|&&s| s > 0.5).count() > 100,
        "the objects are in view"
    );
    let diff = max_difference(&a, &b);
    assert!(diff < 1e-4, "max difference {diff}");
}

#[test]
fn a_full_turn_returns_the_object() {
    let map = two_objects();
    let selection = Selection::of_labels(&map, None, &[4]).expect("label 4");
    let motion =
        RigidMotion::rotation_about([1.0, -2.0, 0.5], 360.0, [0.2, 0.1, 2.0]).expect("valid");
    let mut turned = map.clone();
    apply(&mut turned, &selection, &motion);
    for i in 0..map.len() {
        let (a, b) = (map.get(i), turned.get(i));
        if a.label != 4 {
            assert_eq!(a, b, "Gaussian {i} of another label moved");
            continue;
        }
        let furthest = |x: &[f32], y: &[f32]| {
            x.iter()
                .zip(y)
                .map(|(p, q)| (p - q).abs())
                .fold(0.0, f32::max)
        };
        assert!(
            furthest(&a.mean, &b.mean) < 1e-5,
            "mean {i}: {:?} {:?}",
            a.mean,
            b.mean
        );
        assert!(
            furthest(&a.rotation, &b.rotation) < 1e-5,
            "rotation {i}: {:?} {:?}",
            a.rotation,
            b.rotation
        );
        assert_eq!(
            (a.log_scale, a.opacity_logit, a.sh_dc),
            (b.log_scale, b.opacity_logit, b.sh_dc)
        );
    }
}

#[test]
fn removal_seen_from_a_camera_shows_what_was_behind() {
    // A small red object in front of a grey wall: removed, its pixels show the wall.
    let mut map = GaussianMap::new();
    for i in 0..30 {
        for j in 0..24 {
            let p = [(i as f32 - 15.0) * 0.05, (j as f32 - 12.0) * 0.05, 3.0];
            map.push(blob(p, [0.04, 0.04, 0.005], 0.95, [0.5; 3], 1));
        }
    }
    map.push(blob([0.0, 0.0, 1.5], [0.05; 3], 0.95, [1.0, 0.0, 0.0], 8));
    let selection = Selection::of_labels(&map, None, &[8]).expect("label 8");
    let (_, rest) = split(&map, &selection);
    let comparison = compare_edit(&map, &rest, &camera(&Pose::identity()), &selection);
    let e = &comparison.effect;
    assert!(e.before > 20, "{e:?}");
    assert_eq!(e.after, 0);
    assert_eq!(
        (e.former_now_other_label, e.former_now_empty),
        (e.before, 0),
        "{e:?}"
    );
    assert_eq!(e.former_now_labels, vec![(1, e.before)]);
    let centre = comparison.after.index(32, 24);
    assert_eq!(comparison.after.labels.as_ref().map(|l| l[centre]), Some(1));
    assert!((comparison.after.color[centre][0] - 0.5).abs() < 0.05);
    assert_eq!(comparison.image.dimensions(), (2 * 64 + 4, 2 * 48 + 4));
}

#[test]
fn bad_selections_name_what_is_wrong() {
    let map = two_objects();
    let classes = catalog(&[(2, "cup"), (4, "bowl"), (6, "plate")]);
    let err = Selection::of_labels(&map, Some(&classes), &[99]).expect_err("unknown");
    assert!(
        err.to_string()
            .contains("label 99 is not a label of the map")
            && err.to_string().contains("2, 4"),
        "{err}"
    );
    let err = Selection::of_labels(&map, Some(&classes), &[6]).expect_err("no Gaussian");
    assert!(err.to_string().contains("(plate)"), "{err}");
    assert!(matches!(
        Selection::of_labels(&map, None, &[0]),
        Err(ObjectError::Background)
    ));
    let err = Selection::of_class(&map, Some(&classes), "sofa").expect_err("unknown class");
    assert!(
        err.to_string().contains("'sofa'") && err.to_string().contains("bowl, cup, plate"),
        "{err}"
    );
    assert!(matches!(
        Selection::of_class(&map, Some(&classes), "plate"),
        Err(ObjectError::EmptySelection(_))
    ));
    assert!(matches!(
        Selection::of_class(&map, None, "cup"),
        Err(ObjectError::NoClassNames)
    ));
    let cup = Selection::of_class(&map, Some(&classes), "CUP").expect("case ignored");
    assert_eq!(cup.labels().iter().copied().collect::<Vec<_>>(), vec![2]);
    let mut unlabelled = map.clone();
    unlabelled.labels.iter_mut().for_each(|l| *l = 0);
    assert!(matches!(
        Selection::of_labels(&unlabelled, None, &[2]),
        Err(ObjectError::NoLabels)
    ));
}
