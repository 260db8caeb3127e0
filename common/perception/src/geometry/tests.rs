//! The segmenter on hand-built depth images: objects come apart by
//! geometry, one-coloured scenes included; texture never cuts.

use std::collections::HashMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::scenes::*;
use super::*;

fn segment(r: &Rendered) -> Segmentation {
    segment_with(r, GeometryParams::default())
}

fn segment_with(r: &Rendered, params: GeometryParams) -> Segmentation {
    let input = SegmenterInput {
        width: WIDTH,
        height: HEIGHT,
        rgb: &r.rgb,
        depth: &r.depth,
        depth_scale: DEPTH_SCALE,
        intrinsics: r.intrinsics,
        gt_labels: None,
        classes: &[],
    };
    let mut segmenter = GeometrySegmenter::new(params).expect("valid params");
    segmenter.segment(&input).expect("segmentation")
}

/// The label covering most of `object`'s pixels, the share of the object it
/// covers, and the share of that label's pixels that are the object.
fn dominant(seg: &Segmentation, r: &Rendered, object: usize) -> (u32, f32, f32) {
    let mut counts: HashMap<u32, usize> = HashMap::new();
    for (i, &o) in r.object.iter().enumerate() {
        if o == object {
            *counts.entry(seg.label_map[i]).or_default() += 1;
        }
    }
    let total: usize = counts.values().sum();
    let (label, n) = counts
        .into_iter()
        .max_by_key(|&(_, n)| n)
        .expect("object visible");
    let labelled = seg.label_map.iter().filter(|&&l| l == label).count();
    (label, n as f32 / total as f32, n as f32 / labelled as f32)
}

/// Each object is mostly one label of its own, and the labels differ.
fn assert_apart(seg: &Segmentation, r: &Rendered, objects: &[usize], what: &str) {
    let found: Vec<(u32, f32, f32)> = objects.iter().map(|&o| dominant(seg, r, o)).collect();
    for (&o, &(label, cover, purity)) in objects.iter().zip(&found) {
        assert!(
            label != 0 && cover > 0.8 && purity > 0.85,
            "{what}: object {o} → label {label}, covers {cover:.2}, purity {purity:.2}"
        );
    }
    for (i, a) in found.iter().enumerate() {
        for b in &found[i + 1..] {
            assert_ne!(a.0, b.0, "{what}: two objects share a segment: {found:?}");
        }
    }
}

fn cuboid(min: [f32; 3], max: [f32; 3], colour: [u8; 3]) -> (Shape, Paint) {
    (Shape::Cuboid { min, max }, Paint::Plain(colour))
}

/// The camera at the origin looking straight along +z.
fn looking_ahead(objects: Vec<(Shape, Paint)>) -> Scene {
    Scene {
        eye: [0.0, 0.0, 0.0],
        pitch: 0.0,
        objects,
    }
}

/// The wall z = 2 m.
fn wall_ahead(paint: Paint) -> (Shape, Paint) {
    (
        Shape::Plane {
            normal: [0.0, 0.0, 1.0],
            offset: 2.0,
        },
        paint,
    )
}

fn box_on_floor() -> Scene {
    desk_view(vec![
        floor(Paint::Plain(GREY)),
        cuboid([-0.2, 0.0, 1.2], [0.2, 0.25, 1.5], GREY),
    ])
}

#[test]
fn box_on_a_plane_comes_apart_from_the_plane() {
    // One colour everywhere: only geometry can separate them.
    let r = box_on_floor().render();
    assert_apart(&segment(&r), &r, &[0, 1], "box on floor");
}

/// Kinect-like axial noise σ = 1.5 mm · z², then mm quantisation.
fn add_sensor_noise(r: &mut Rendered, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for d in r.depth.iter_mut().filter(|d| **d > 0) {
        let z = *d as f32 / DEPTH_SCALE;
        let (u1, u2): (f32, f32) = (rng.gen_range(1e-6..1.0), rng.gen());
        let gauss = (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos();
        *d = ((z + 0.0015 * z * z * gauss) * DEPTH_SCALE).round() as u16;
    }
}

#[test]
fn box_on_a_plane_with_sensor_noise() {
    let mut r = box_on_floor().render();
    add_sensor_noise(&mut r, 18);
    assert_apart(&segment(&r), &r, &[0, 1], "noisy box on floor");
}

#[test]
fn two_boxes_touching_side_by_side_come_apart() {
    // Touching; the taller one's side face meets the shorter one's top and
    // front in concave creases. (Equal boxes flush in height and front would
    // be one flat surface: no RGB-D cue separates them.)
    let boxes = |second: [u8; 3]| {
        desk_view(vec![
            floor(Paint::Plain(GREY)),
            cuboid([-0.4, 0.0, 1.2], [-0.1, 0.3, 1.5], GREY),
            cuboid([-0.1, 0.0, 1.3], [0.2, 0.15, 1.6], second),
        ])
        .render()
    };
    let r = boxes([150, 60, 40]);
    assert_apart(&segment(&r), &r, &[0, 1, 2], "two boxes");
    // In one colour the creases alone cut them, and the crease join (a sofa's
    // seat and back are such two boxes) makes them one object.
    let r = boxes(GREY);
    let (one, _, _) = dominant(&segment(&r), &r, 1);
    let (two, _, _) = dominant(&segment(&r), &r, 2);
    assert_eq!(one, two, "one colour: one object");
    let no_crease_join = GeometryParams {
        crease_max_share: 0.0,
        ..GeometryParams::default()
    };
    assert_apart(
        &segment_with(&r, no_crease_join),
        &r,
        &[0, 1, 2],
        "creases alone",
    );
}

#[test]
fn a_ball_on_a_box_comes_apart() {
    let r = desk_view(vec![
        floor(Paint::Plain(GREY)),
        cuboid([-0.25, 0.0, 1.2], [0.25, 0.2, 1.6], GREY),
        (
            Shape::Sphere {
                centre: [0.0, 0.32, 1.4],
                radius: 0.12,
            },
            Paint::Plain(GREY),
        ),
    ])
    .render();
    assert_apart(&segment(&r), &r, &[0, 1, 2], "ball on box");
}

#[test]
fn a_concave_wall_corner_splits() {
    // Looking straight at an inside corner: wall z = 2 m, wall x = 0.4 m.
    let r = looking_ahead(vec![
        wall_ahead(Paint::Plain(WHITE)),
        (
            Shape::Plane {
                normal: [1.0, 0.0, 0.0],
                offset: 0.4,
            },
            Paint::Plain(WHITE),
        ),
    ])
    .render();
    assert_apart(&segment(&r), &r, &[0, 1], "wall corner");
}

#[test]
fn a_checkered_plane_stays_one_segment() {
    let r = desk_view(vec![floor(Paint::Checker(0.1, BLACK, WHITE))]).render();
    let seg = segment(&r);
    let (label, cover, _) = dominant(&seg, &r, 0);
    assert!(
        label != 0 && cover > 0.97,
        "label {label} covers {cover:.3}"
    );
    assert!(seg.labels.len() <= 2, "{} segments", seg.labels.len());
}

#[test]
fn a_flat_book_splits_by_colour_where_geometry_is_weak() {
    // 2 cm high: below the depth-step threshold, so colour decides.
    let r = desk_view(vec![
        floor(Paint::Plain(WOOD)),
        cuboid([-0.15, 0.0, 1.3], [0.15, 0.02, 1.55], WHITE),
    ])
    .render();
    assert_apart(&segment(&r), &r, &[0, 1], "book on desk");
}

/// A closed laptop 1.5 cm thick on a desk, in the desk's own paint, seen through a noisy sensor:
/// its edge is within the depth-step tolerance and colour shows nothing, but its top lies
/// 1.5 cm above the plane the rest of the desk fits.
#[test]
fn a_laptop_in_its_desks_colour_splits_by_its_height() {
    for (paint, what) in [
        (Paint::Plain(WOOD), "plain desk"),
        (Paint::Checker(0.05, BLACK, WHITE), "checkered desk"),
    ] {
        let mut r = desk_view(vec![
            floor(paint),
            (
                Shape::Cuboid {
                    min: [-0.17, 0.0, 1.25],
                    max: [0.17, 0.015, 1.5],
                },
                paint,
            ),
        ])
        .render();
        add_sensor_noise(&mut r, 7);
        // The laptop is 4–5 patch cells (16 px) wide: the cells across its edges hold both and
        // go to one side (cover 0.70 / 0.76, purity 0.88 / 0.99 measured, plain / checkered), so
        // the bar is lower than `assert_apart`'s.
        let seg = segment(&r);
        let (desk, desk_cover, _) = dominant(&seg, &r, 0);
        let (laptop, cover, purity) = dominant(&seg, &r, 1);
        assert!(
            laptop != desk && laptop != 0 && desk_cover > 0.9 && cover > 0.6 && purity > 0.8,
            "{what}: desk {desk} (covers {desk_cover:.2}), laptop {laptop} covers {cover:.2}, \
             purity {purity:.2}"
        );
        // Without the raised-object split it stays in the desk.
        let without = GeometryParams {
            raised_min_share: 0.0,
            ..GeometryParams::default()
        };
        let seg = segment_with(&r, without);
        let (desk, _, _) = dominant(&seg, &r, 0);
        let (laptop, _, _) = dominant(&seg, &r, 1);
        assert_eq!(desk, laptop, "{what}: cut without the split");
    }
}

/// Three books in one paint stacked on a desk, each set back from the one under it: every edge
/// is a 2.5–3 cm step, inside the depth-step allowance, and every face between them convex, so
/// the boundary rules leave the stack one segment; its tops lie at three heights.
#[test]
fn a_stack_of_books_splits_book_by_book() {
    let r = desk_view(vec![
        floor(Paint::Plain(WOOD)),
        cuboid([-0.2, 0.0, 1.2], [0.2, 0.03, 1.6], GREY),
        cuboid([-0.15, 0.03, 1.32], [0.15, 0.055, 1.6], GREY),
        cuboid([-0.1, 0.055, 1.44], [0.1, 0.08, 1.6], GREY),
    ])
    .render();
    let seg = segment(&r);
    let found: Vec<(u32, f32, f32)> = (0..4).map(|o| dominant(&seg, &r, o)).collect();
    // Measured cover / purity: 0.63 / 0.88 (the bottom book's front face stays with the desk,
    // its top is a face of the desk's segment the stack adopts), 0.85 / 0.87, 0.94 / 0.93.
    for (book, &(label, cover, purity)) in found.iter().enumerate().skip(1) {
        assert!(
            label != 0 && label != found[0].0 && cover > 0.6 && purity > 0.8,
            "book {book} → label {label}, covers {cover:.2}, purity {purity:.2}: {found:?}"
        );
    }
    assert!(
        found[1].0 != found[2].0 && found[2].0 != found[3].0 && found[1].0 != found[3].0,
        "books share a label: {found:?}"
    );
    // Without the stack split the two upper books are one segment and the bottom one is the
    // desk's.
    let without = GeometryParams {
        level_min_share: 0.0,
        ..GeometryParams::default()
    };
    let seg = segment_with(&r, without);
    let labels: Vec<u32> = (0..4).map(|o| dominant(&seg, &r, o).0).collect();
    assert!(
        labels[1] == labels[0] && labels[2] == labels[3],
        "desk, books: {labels:?}"
    );
}

/// A box 8 cm tall on a desk: one face at one height above it, so no stack; its sides stay with
/// its top.
#[test]
fn a_low_box_on_a_desk_stays_whole() {
    let mut r = desk_view(vec![
        floor(Paint::Plain(WOOD)),
        cuboid([-0.15, 0.0, 1.3], [0.15, 0.08, 1.5], GREY),
    ])
    .render();
    add_sensor_noise(&mut r, 5);
    assert_apart(&segment(&r), &r, &[0, 1], "low box on desk");
}

/// A keyboard 1.8 cm thick, 2.3 m away on a desk in the desk's own paint, seen through a noisy
/// sensor: a band a dozen coarse pixels high, so every 16-pixel patch straddles its edges and
/// the patch-level height test cannot hold it; pixel by pixel its top lies above the desk.
#[test]
fn a_far_keyboard_in_its_desks_paint_splits_pixel_by_pixel() {
    let paint = Paint::Plain(WOOD);
    let mut r = desk_view(vec![
        floor(paint),
        (
            Shape::Cuboid {
                min: [-0.25, 0.0, 2.25],
                max: [0.25, 0.018, 2.42],
            },
            paint,
        ),
    ])
    .render();
    add_sensor_noise(&mut r, 11);
    let seg = segment(&r);
    let (desk, desk_cover, _) = dominant(&seg, &r, 0);
    let (keyboard, cover, purity) = dominant(&seg, &r, 1);
    assert!(
        keyboard != desk && keyboard != 0 && desk_cover > 0.9 && cover > 0.5 && purity > 0.8,
        "desk {desk} (covers {desk_cover:.2}), keyboard {keyboard} covers {cover:.2}, purity \
         {purity:.2}"
    );
    // Without the height splits it stays in the desk.
    let without = GeometryParams {
        raised_min_share: 0.0,
        ..GeometryParams::default()
    };
    let seg = segment_with(&r, without);
    assert_eq!(dominant(&seg, &r, 0).0, dominant(&seg, &r, 1).0);
}

#[test]
fn a_noisy_plain_desk_stays_one_segment() {
    let mut r = desk_view(vec![floor(Paint::Plain(WOOD))]).render();
    add_sensor_noise(&mut r, 3);
    let seg = segment(&r);
    let (label, cover, _) = dominant(&seg, &r, 0);
    assert!(
        label != 0 && cover > 0.97,
        "label {label} covers {cover:.3}"
    );
}

/// A wall 2 m ahead in `paint`, a picture in `colour` 4 mm thick on it (too thin for any
/// geometric cue: a plane offset of 0.2 of full evidence).
fn picture_on_a_wall(paint: Paint, colour: [u8; 3]) -> Rendered {
    looking_ahead(vec![
        wall_ahead(paint),
        cuboid([-0.4, -0.25, 1.996], [0.3, 0.25, 2.0], colour),
    ])
    .render()
}

#[test]
fn a_picture_on_a_wall_splits_by_its_own_colour() {
    // Colours a colour edge apart (patches never straddle one): white on grey, wood on black
    // and white.
    for (paint, colour, what) in [
        (Paint::Plain(GREY), WHITE, "plain wall"),
        // On the wall z = 2 the checker is vertical stripes 10 cm wide.
        (Paint::Checker(0.1, BLACK, WHITE), WOOD, "striped wall"),
    ] {
        let r = picture_on_a_wall(paint, colour);
        assert_apart(&segment(&r), &r, &[0, 1], what);
        // Geometry alone keeps the picture in the wall: the flat-object split is what cuts.
        let without = GeometryParams {
            flat_min_share: 0.0,
            ..GeometryParams::default()
        };
        let seg = segment_with(&r, without);
        let (wall, _, _) = dominant(&seg, &r, 0);
        let (picture, _, _) = dominant(&seg, &r, 1);
        assert_eq!(wall, picture, "{what}: cut without the split");
    }
}

#[test]
fn a_striped_wall_stays_one_segment() {
    let r = looking_ahead(vec![wall_ahead(Paint::Checker(0.1, BLACK, WHITE))]).render();
    let seg = segment(&r);
    let (label, cover, _) = dominant(&seg, &r, 0);
    assert!(
        label != 0 && cover > 0.97,
        "label {label} covers {cover:.3}"
    );
}

#[test]
fn pixels_without_depth_take_the_surrounding_surface_or_none() {
    let mut r = box_on_floor().render();
    // A hole in the floor, away from the box.
    let hole = |i: usize| {
        let (x, y) = ((i % WIDTH as usize) as f32, (i / WIDTH as usize) as f32);
        (x - 60.0).powi(2) + (y - 200.0).powi(2) < 256.0
    };
    let holes: Vec<usize> = (0..r.depth.len()).filter(|&i| hole(i)).collect();
    assert!(holes.iter().all(|&i| r.object[i] == 0));
    for &i in &holes {
        r.depth[i] = 0;
    }
    let seg = segment(&r);
    let (floor_label, _, _) = dominant(&seg, &r, 0);
    assert!(holes.iter().all(|&i| seg.label_map[i] == floor_label));
    // No depth at all: no segment, no error.
    r.depth.iter_mut().for_each(|d| *d = 0);
    let empty = segment(&r);
    assert!(empty.label_map.iter().all(|&l| l == 0));
    assert!(empty.labels.is_empty());
}

#[test]
fn labels_table_and_confidence_are_consistent() {
    let r = box_on_floor().render();
    let seg = segment(&r);
    let counts = seg.pixel_counts();
    assert!(
        counts.iter().all(|&n| n > 0),
        "every listed label is painted"
    );
    assert!(seg
        .label_map
        .iter()
        .all(|&l| l == 0 || seg.info(l).is_some()));
    // The box is bounded by steps and a crease: a confident segment.
    let (box_label, _, _) = dominant(&seg, &r, 1);
    let confidence = seg.info(box_label).map(|s| s.confidence);
    assert!(confidence.is_some_and(|c| c > 0.7), "{confidence:?}");
}

#[test]
fn a_box_seen_from_afar_is_trusted_less_by_the_square_of_its_distance() {
    let box_confidence = |r: &Rendered, confident_depth: f32| {
        let seg = segment_with(
            r,
            GeometryParams {
                confident_depth,
                ..GeometryParams::default()
            },
        );
        let (label, _, _) = dominant(&seg, r, 1);
        seg.info(label).map(|s| s.confidence).expect("box labelled")
    };
    // The depth (m) a tenth of the box's pixels lie nearer than.
    let near_tenth = |r: &Rendered| {
        let mut z: Vec<f32> = (r.object.iter().zip(&r.depth))
            .filter(|&(&o, &d)| o == 1 && d > 0)
            .map(|(_, &d)| d as f32 / DEPTH_SCALE)
            .collect();
        z.sort_by(f32::total_cmp);
        z[z.len() / 10]
    };
    let near = box_on_floor().render();
    let z_near = near_tenth(&near);
    // Nearer than the confident depth: the confidence is left alone.
    assert_eq!(
        box_confidence(&near, z_near + 0.5),
        box_confidence(&near, 0.0)
    );
    // The same box 1.8 m further and twice its size (as many pixels): (1.5 / z)².
    let far = desk_view(vec![
        floor(Paint::Plain(GREY)),
        cuboid([-0.4, 0.0, 3.0], [0.4, 0.5, 3.6], GREY),
    ])
    .render();
    let z_far = near_tenth(&far);
    let (with, without) = (box_confidence(&far, 1.5), box_confidence(&far, 0.0));
    let expected = (1.5 / z_far).powi(2);
    assert!(z_far > 2.5 && without > 0.7, "{z_far} {without}");
    assert!(
        (with / without / expected - 1.0).abs() < 0.1,
        "kept {:.3} of {without:.3}, expected {expected:.3} at {z_far:.2} m",
        with / without
    );
}

#[test]
fn bad_sizes_and_parameters_are_errors() {
    let r = box_on_floor().render();
    let input = SegmenterInput {
        width: WIDTH,
        height: HEIGHT,
        rgb: &r.rgb,
        depth: &r.depth[1..],
        depth_scale: DEPTH_SCALE,
        intrinsics: r.intrinsics,
        gt_labels: None,
        classes: &[],
    };
    let mut segmenter = GeometrySegmenter::new(GeometryParams::default()).expect("valid");
    assert!(segmenter.segment(&input).is_err());
    let bad = GeometryParams {
        cell: 0,
        ..GeometryParams::default()
    };
    assert!(GeometrySegmenter::new(bad).is_err());
}

/// A tall cabinet close in front of the camera hides the floor's middle from the top of
/// the image to the bottom: the floor is seen as two pieces that do not touch. They are one
/// plane, so they are one segment (before the coplanar join: one label per piece).
#[test]
fn a_floor_split_by_an_occluder_stays_one_segment() {
    let cabinet = Shape::Cuboid {
        min: [-0.15, 0.0, 0.3],
        max: [0.15, 1.5, 0.8],
    };
    let r = desk_view(vec![
        floor(Paint::Checker(0.25, BLACK, WHITE)),
        (cabinet, Paint::Plain(WHITE)),
    ])
    .render();
    // The cabinet reaches across every row: no floor pixel links the two sides.
    let w = WIDTH as usize;
    for row in r.object.chunks(w) {
        let (first, last) = (
            row.iter().position(|&o| o == 1),
            row.iter().rposition(|&o| o == 1),
        );
        let (Some(a), Some(b)) = (first, last) else {
            panic!("the cabinet does not cross every row");
        };
        assert!(row[a..=b].iter().all(|&o| o == 1));
    }
    let seg = segment(&r);
    assert_apart(&seg, &r, &[0, 1], "floor around a cabinet");
    let without = segment_with(
        &r,
        GeometryParams {
            coplanar_min_share: 0.0,
            ..GeometryParams::default()
        },
    );
    let (_, cover, _) = dominant(&without, &r, 0);
    assert!(
        cover < 0.8,
        "without the join the floor is in pieces (largest {cover:.2})"
    );
}
