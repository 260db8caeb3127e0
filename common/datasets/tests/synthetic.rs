//! Ray-cast correctness with hand values, determinism, path re-centring.

use approx::assert_relative_eq;
use nalgebra::{Point3, Vector3};
use opengs_datasets::synthetic::path::{default_start_pose, look_at};
use opengs_datasets::synthetic::raycast::render;
use opengs_datasets::synthetic::scene::{indoor_room, Part, Scene};
use opengs_datasets::synthetic::shape::Shape;
use opengs_datasets::synthetic::texture::Texture;
use opengs_datasets::trajectory::read_tum_trajectory;
use opengs_datasets::{
    open_dataset, DatasetSpec, DepthNoise, RgbdSource, SyntheticOptions, SyntheticSource,
};
use opengs_geometry::Intrinsics;

/// Principal point on a pixel centre so the centre pixel's ray is the optical axis.
fn centred_camera() -> Intrinsics {
    Intrinsics::new(500.0, 500.0, 320.0, 240.0, 641, 481)
}

fn trajectory_file() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/tum_trajectories/freiburg1_xyz-groundtruth.txt")
}

#[test]
fn wall_depth_is_exact_everywhere() {
    let scene = Scene::empty_room(Vector3::new(5.0, 4.0, 2.8));
    let k = centred_camera();
    // Looking along +x from 4 m in front of the +x wall: z-depth is 4 for every pixel on it.
    let pose = look_at(
        &Point3::new(1.0, 2.0, 1.4),
        &Point3::new(5.0, 2.0, 1.4),
        0.0,
    );
    let view = render(&scene, &k, &pose);
    let centre = (240 * k.width + 320) as usize;
    assert_eq!(view.depth[centre], 4.0);
    assert_eq!(view.labels[centre], 4, "+x wall is face 1 → instance 4");
    let on_wall = view
        .labels
        .iter()
        .zip(&view.depth)
        .filter(|(l, _)| **l == 4);
    let mut n = 0;
    for (_, d) in on_wall {
        assert_relative_eq!(*d, 4.0, epsilon = 1e-5);
        n += 1;
    }
    assert!(n > 50_000, "much of the view is the far wall ({n})");
    // Ceiling above, floor below the centre column.
    assert_eq!(view.labels[320], 2);
    assert_eq!(view.labels[(480 * k.width + 320) as usize], 1);
}

#[test]
fn sphere_label_and_depth_at_projected_centre() {
    let mut scene = Scene::empty_room(Vector3::new(5.0, 4.0, 2.8));
    scene.parts.push(Part {
        shape: Shape::Sphere {
            centre: Point3::new(4.0, 2.0, 1.0),
            radius: 0.3,
        },
        texture: Texture::Solid([1.0, 0.0, 0.0]),
        instance: 9,
    });
    let k = centred_camera();
    let eye = Point3::new(1.0, 2.0, 1.0);
    let pose = look_at(&eye, &Point3::new(4.0, 2.0, 1.0), 0.0);
    let view = render(&scene, &k, &pose);
    let centre = (240 * k.width + 320) as usize;
    assert_eq!(view.labels[centre], 9);
    assert_relative_eq!(view.depth[centre], 2.7, epsilon = 1e-6);
    // Red surface lit from the front-ish: red channel only.
    assert!(view.rgb[centre * 3] > 50 && view.rgb[centre * 3 + 1] == 0);
    // Angular radius asin(0.3/3) ≈ 0.1002 rad → ~50 px; 60 px away is the wall.
    assert_eq!(view.labels[centre + 60], 4);
    assert_eq!(view.labels[centre + 45], 9);
}

#[test]
fn default_room_object_at_its_projected_centre() {
    let scene = indoor_room();
    let ball = scene
        .parts
        .iter()
        .find(|p| matches!(p.shape, Shape::Sphere { radius, .. } if radius == 0.25))
        .expect("floor ball");
    let Shape::Sphere { centre, radius } = ball.shape else {
        unreachable!()
    };
    let k = centred_camera();
    let eye = Point3::new(2.2, 2.4, 1.2);
    let pose = look_at(&eye, &centre, 0.0);
    let view = render(&scene, &k, &pose);
    let px = (240 * k.width + 320) as usize;
    assert_eq!(view.labels[px], ball.instance);
    let class = &scene.classes[ball.instance as usize - 1];
    assert_eq!((class.id, class.class.as_str()), (ball.instance, "ball"));
    assert_relative_eq!(
        view.depth[px] as f64,
        (centre - eye).norm() - radius,
        epsilon = 1e-5
    );
}

#[test]
fn scene_has_many_instances_and_classes() {
    let scene = indoor_room();
    let objects = scene
        .classes
        .iter()
        .filter(|c| !matches!(c.class.as_str(), "wall" | "floor" | "ceiling"))
        .count();
    assert!(objects >= 10, "{objects} objects");
    for (i, c) in scene.classes.iter().enumerate() {
        assert_eq!(c.id as usize, i + 1);
    }
}

#[test]
fn default_path_sees_many_objects_with_full_depth() {
    let mut src = SyntheticSource::new(SyntheticOptions {
        frames: Some(600),
        ..SyntheticOptions::default()
    })
    .expect("source");
    for i in (0..600).step_by(60) {
        let f = src.frame(i).expect("frame");
        assert!(f.depth.iter().all(|&d| d > 0), "frame {i} has holes");
        let mut ids: Vec<u16> = f.labels.clone().unwrap_or_default();
        ids.sort_unstable();
        ids.dedup();
        assert!(ids.len() >= 6, "frame {i} sees only {ids:?}");
        // Depth is spread over several metres, not a single plane.
        let (lo, hi) = f
            .depth
            .iter()
            .fold((u16::MAX, 0), |(a, b), &d| (a.min(d), b.max(d)));
        assert!(
            (hi - lo) as f32 / f.depth_scale > 1.5,
            "frame {i}: depth range {lo}..{hi}"
        );
    }
}

#[test]
fn renders_are_deterministic_for_a_seed() {
    let opts = SyntheticOptions {
        frames: Some(10),
        seed: 42,
        noise: Some(DepthNoise::default()),
        ..SyntheticOptions::default()
    };
    let mut a = SyntheticSource::new(opts.clone()).expect("a");
    let mut b = SyntheticSource::new(opts.clone()).expect("b");
    let fa = a.frame(7).expect("frame");
    assert_eq!(fa, b.frame(7).expect("frame"));
    let mut c = SyntheticSource::new(SyntheticOptions { seed: 43, ..opts }).expect("c");
    let fc = c.frame(7).expect("frame");
    assert_ne!(fa.depth, fc.depth);
    assert_ne!(fa.gt_pose, fc.gt_pose, "the seed also changes the path");
}

#[test]
fn noisy_depth_has_dropouts_and_range_limit() {
    let mut src = SyntheticSource::new(SyntheticOptions {
        frames: Some(1),
        noise: Some(DepthNoise::default()),
        ..SyntheticOptions::default()
    })
    .expect("source");
    let f = src.frame(0).expect("frame");
    let missing = f.depth.iter().filter(|&&d| d == 0).count() as f64 / f.depth.len() as f64;
    assert!(
        missing > 0.001 && missing < 0.5,
        "missing fraction {missing}"
    );
    assert!(
        f.depth.iter().all(|&d| d as f32 / f.depth_scale <= 4.15),
        "noisy depth stays near the 4 m cut"
    );
}

#[test]
fn tum_trajectory_recentring_keeps_relative_motion() {
    let file = trajectory_file();
    let raw = read_tum_trajectory(&file).expect("trajectory");
    let mut src = SyntheticSource::new(SyntheticOptions {
        trajectory: Some(file.clone()),
        ..SyntheticOptions::default()
    })
    .expect("source");
    // ~30 s at 30 Hz.
    assert!((880..=910).contains(&src.len()), "{} frames", src.len());
    let poses = src.poses().to_vec();
    assert_relative_eq!(
        poses[0].to_homogeneous(),
        default_start_pose().to_homogeneous(),
        epsilon = 1e-9
    );
    let t0 = raw[0].0;
    for k in [1usize, 30, 300, 850] {
        // The sample for frame k is the file's pose nearest to its clock time
        // (k/30 until the 0.11 s mocap gap at 10.2 s drops two ticks).
        let expected_tick = if k < 305 { k } else { k + 2 };
        assert_relative_eq!(src.timestamps()[k], expected_tick as f64 / 30.0);
        let target = t0 + src.timestamps()[k];
        let nearest = raw
            .iter()
            .min_by(|a, b| (a.0 - target).abs().total_cmp(&(b.0 - target).abs()))
            .expect("pose");
        let rel_file = raw[0].1.inverse() * nearest.1;
        let rel_synth = poses[0].inverse() * poses[k];
        assert_relative_eq!(
            rel_file.to_homogeneous(),
            rel_synth.to_homogeneous(),
            epsilon = 1e-9
        );
    }
    let f = src.frame(450).expect("frame");
    assert!(f.depth.iter().filter(|&&d| d > 0).count() > 300_000);
}

#[test]
fn open_dataset_synthetic_with_frame_limit() {
    let spec: DatasetSpec = "synthetic".parse().expect("spec");
    let mut src = open_dataset(&spec.with_max_frames(Some(5))).expect("open");
    assert_eq!(src.len(), 5);
    assert_eq!(src.intrinsics().width, 640);
    assert_eq!(src.frame_rate(), 30.0);
    assert!(src.frame(5).is_err());
    let f = src.frame(4).expect("frame");
    assert_eq!(f.rgb.len(), 640 * 480 * 3);
    assert_eq!(f.depth.len(), 640 * 480);
    assert_eq!(f.depth_scale, 5000.0);
    assert!(f.gt_pose.is_some());
    assert!(!src.class_table().is_empty());
}

/// The +x wall seen head-on from 4 m, painted with vertical stripes (bands along y).
fn striped_wall_view(frequency: f64, area_sampling: bool) -> Vec<u8> {
    let mut scene = Scene::empty_room(Vector3::new(5.0, 4.0, 2.8));
    scene.ambient = 1.0;
    scene.diffuse = 0.0;
    scene.area_sampling = area_sampling;
    scene.room.faces[1].1 = Texture::Stripes {
        axis: [0.0, 1.0, 0.0],
        frequency,
        a: [0.2, 0.2, 0.2],
        b: [0.6, 0.6, 0.6],
    };
    let pose = look_at(
        &Point3::new(1.0, 2.0, 1.4),
        &Point3::new(5.0, 2.0, 1.4),
        0.0,
    );
    render(&scene, &centred_camera(), &pose).rgb
}

#[test]
fn area_sampling_averages_stripes_finer_than_a_pixel() {
    // A pixel spans 4 m / 500 = 8 mm of the wall. At 1000 bands per metre a band is 0.5 mm
    // and a pixel covers 16 of them. Area-sampled (4 × 4 jittered samples, each 51 or 153
    // at random), a pixel is 51 + 102 · k / 16 with k ~ Binomial(16, ½): the mean grey
    // (0.2 + 0.6) / 2 · 255 = 102 on average, ± 12.75 (one σ).
    let area = striped_wall_view(1000.0, true);
    let centre = (240 * 641 + 320) * 3;
    let row: Vec<f64> = (centre..centre + 3 * 200)
        .step_by(3)
        .map(|px| area[px] as f64)
        .collect();
    let mean = row.iter().sum::<f64>() / row.len() as f64;
    assert!((99.0..=105.0).contains(&mean), "mean {mean}");
    let within_2_sigma = row.iter().filter(|g| (*g - 102.0).abs() <= 26.0).count();
    assert!(within_2_sigma >= 180, "{within_2_sigma} of 200 within 2σ");
    // Point-sampled, each pixel is one band: 51 or 153, the moiré no camera records.
    let point = striped_wall_view(1000.0, false);
    for px in (centre..centre + 3 * 200).step_by(3) {
        assert!(
            point[px] == 51 || point[px] == 153,
            "pixel {}: {}",
            px / 3,
            point[px]
        );
    }
}

#[test]
fn area_sampling_blends_coarse_band_edges_by_coverage() {
    // Bands of 10 cm (5 per metre, 12.5 pixels wide): a pixel inside a band keeps its one
    // sample; a pixel across an edge records each band by its share of the pixel, as a
    // sensor does, where one sample drew a staircase of whole bands.
    let frequency = 5.0;
    let area = striped_wall_view(frequency, true);
    let point = striped_wall_view(frequency, false);
    // Pixel u of the centre row spans wall y in [y(u − ½), y(u + ½)], y(u) = 2 ± 0.008 (u − 320)
    // (head-on, 4 m, f = 500): the share of band a (phase < ½ of 5y + 0.371) in that span.
    let band_a_upto = |x: f64| x.floor() * 0.5 + (x - x.floor()).min(0.5);
    let share_a = |u: f64, sign: f64| {
        let x = |u: f64| (2.0 + sign * 0.008 * (u - 320.0)) * frequency + 0.371;
        let (x0, x1) = (x(u - 0.5), x(u + 0.5));
        (band_a_upto(x0.max(x1)) - band_a_upto(x0.min(x1))) / (x1 - x0).abs()
    };
    // Grey of a pixel holding `share` of a (0.2) and the rest of b (0.6), as written.
    let grey = |share: f64| ((0.2 + 0.4 * (1.0 - share)) * 255.0 + 0.5).floor();
    let row = |img: &[u8], u: usize| img[(240 * 641 + u) * 3] as f64;
    // Pixels on the +x wall (y from 0.24 to 3.76 m).
    let us = 100..540;
    let inside_a_band = |share: f64| !(1e-9..=1.0 - 1e-9).contains(&share);
    // The image's u runs along +y or −y: the point samples inside the bands say which.
    let sign = [1.0, -1.0]
        .into_iter()
        .find(|&sign| {
            us.clone().all(|u| {
                let share = share_a(u as f64, sign);
                !inside_a_band(share) || row(&point, u) == grey(share.round())
            })
        })
        .expect("the point-sampled bands match one direction of the wall");
    let (mut edges, mut area_err, mut point_err) = (0, 0.0, 0.0);
    for u in us {
        let share = share_a(u as f64, sign);
        if inside_a_band(share) {
            assert_eq!(row(&area, u), row(&point, u), "pixel {u} inside a band");
            continue;
        }
        // 4 × 4 jittered samples: the stratum across the edge (a quarter of them) may
        // miscount by at most its weight, ¼ of the 102 grey levels between the bands.
        let err = (row(&area, u) - grey(share)).abs();
        assert!(
            err <= 26.5,
            "pixel {u}: share {share:.2}, {} vs {}",
            row(&area, u),
            grey(share)
        );
        edges += 1;
        area_err += err;
        point_err += (row(&point, u) - grey(share)).abs();
    }
    let (area_err, point_err) = (area_err / edges as f64, point_err / edges as f64);
    eprintln!("{edges} edge pixels: mean error area {area_err:.2}, point {point_err:.2}");
    assert!(edges >= 30, "{edges} pixels across an edge");
    assert!(area_err <= 8.0, "mean error {area_err}");
    assert!(
        point_err >= 3.0 * area_err,
        "one sample per pixel: {point_err}"
    );
}

#[test]
fn the_reference_room_is_point_sampled_and_the_suite_area_sampled() {
    assert!(!indoor_room().area_sampling);
    let poses = [default_start_pose()];
    let fitted = opengs_datasets::synthetic::scene_suite::room_around_trajectory(3, &poses);
    assert!(fitted.scene.area_sampling);
}
