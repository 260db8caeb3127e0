//! Deterministic synthetic indoor scene for benchmarks and demos: a room's surfaces plus a few
//! objects, covered with flat Gaussians of 1–5 cm like a SLAM map.

use nalgebra::{Matrix3, Point3, Rotation3, UnitQuaternion, Vector3};
use opengs_geometry::Pose;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::map::{Gaussian, GaussianMap};

/// An axis-aligned rectangle patch: origin + two edge vectors, with a label and base colour.
struct Patch {
    origin: Vector3<f32>,
    u: Vector3<f32>,
    v: Vector3<f32>,
    label: u32,
    color: [f32; 3],
}

impl Patch {
    fn area(&self) -> f32 {
        self.u.cross(&self.v).norm()
    }
}

fn boxed(patches: &mut Vec<Patch>, min: [f32; 3], max: [f32; 3], label: u32, color: [f32; 3]) {
    let (a, b) = (Vector3::from(min), Vector3::from(max));
    let d = b - a;
    let (x, y, z) = (Vector3::x() * d.x, Vector3::y() * d.y, Vector3::z() * d.z);
    for (o, u, v) in [
        (a, x, z),
        (a + y, x, z),
        (a, x, y),
        (a + z, x, y),
        (a, y, z),
        (a + x, y, z),
    ] {
        patches.push(Patch {
            origin: o,
            u,
            v,
            label,
            color,
        });
    }
}

/// The room (6 × 2.8 × 5 m, y up, centred on x/z) with furniture-like boxes; labels 1..
fn room_patches() -> Vec<Patch> {
    let mut p = Vec::new();
    let (hx, h, hz) = (3.0f32, 2.8f32, 2.5f32);
    let walls = [
        // floor, ceiling, four walls
        (
            [-hx, 0.0, -hz],
            [2.0 * hx, 0.0, 0.0],
            [0.0, 0.0, 2.0 * hz],
            [0.55, 0.45, 0.35],
        ),
        (
            [-hx, h, -hz],
            [2.0 * hx, 0.0, 0.0],
            [0.0, 0.0, 2.0 * hz],
            [0.9, 0.9, 0.9],
        ),
        (
            [-hx, 0.0, -hz],
            [2.0 * hx, 0.0, 0.0],
            [0.0, h, 0.0],
            [0.8, 0.75, 0.7],
        ),
        (
            [-hx, 0.0, hz],
            [2.0 * hx, 0.0, 0.0],
            [0.0, h, 0.0],
            [0.7, 0.8, 0.75],
        ),
        (
            [-hx, 0.0, -hz],
            [0.0, 0.0, 2.0 * hz],
            [0.0, h, 0.0],
            [0.75, 0.7, 0.8],
        ),
        (
            [hx, 0.0, -hz],
            [0.0, 0.0, 2.0 * hz],
            [0.0, h, 0.0],
            [0.7, 0.7, 0.6],
        ),
    ];
    for (i, (o, u, v, c)) in walls.into_iter().enumerate() {
        p.push(Patch {
            origin: Vector3::from(o),
            u: Vector3::from(u),
            v: Vector3::from(v),
            label: i as u32 + 1,
            color: c,
        });
    }
    let objects = [
        ([0.5, 0.0, 0.5], [2.0, 0.75, 1.5], [0.5, 0.3, 0.1]), // table
        ([-2.8, 0.0, 1.0], [-1.9, 0.9, 2.4], [0.2, 0.3, 0.6]), // sofa
        ([2.2, 0.0, -2.4], [2.9, 1.8, -1.6], [0.4, 0.4, 0.45]), // cabinet
        ([0.9, 0.75, 0.8], [1.2, 1.05, 1.1], [0.9, 0.2, 0.2]), // box on table
        ([1.4, 0.75, 0.9], [1.6, 1.0, 1.1], [0.2, 0.8, 0.3]), // small box on table
        ([-1.0, 0.0, -1.5], [-0.5, 0.5, -1.0], [0.8, 0.7, 0.1]), // crate
    ];
    for (i, (a, b, c)) in objects.into_iter().enumerate() {
        boxed(&mut p, a, b, 7 + i as u32, c);
    }
    p
}

/// `n` Gaussians on the room's surfaces, deterministic for a given `seed`.
/// At 100k and 640×480 a pixel gets ~16 contributions and keeps T ≈ 0.2 (`bench -- stats`):
/// random placement leaves surfaces partly see-through, and making them opaque at this count
/// takes more overlap (measured: 27–45 contributions/px), so the scene does not flatter the renderer.
pub fn indoor_scene(n: usize, seed: u64) -> GaussianMap {
    let patches = room_patches();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Objects get 3× the density of walls, as SLAM maps are denser on clutter.
    let weight = |p: &Patch| p.area() * if p.label > 6 { 3.0 } else { 1.0 };
    let total: f32 = patches.iter().map(weight).sum();
    let mut map = GaussianMap::with_capacity(n);
    let mut placed = 0usize;
    let mut acc = 0.0f32;
    for (k, patch) in patches.iter().enumerate() {
        acc += weight(patch);
        let target = if k + 1 == patches.len() {
            n
        } else {
            ((acc / total) * n as f32).round() as usize
        };
        let normal = patch.u.cross(&patch.v).normalize();
        let t1 = patch.u.normalize();
        let t2 = normal.cross(&t1);
        while placed < target.min(n) {
            let pos = patch.origin + patch.u * rng.gen::<f32>() + patch.v * rng.gen::<f32>();
            // In-plane rotation about the normal.
            let phi: f32 = rng.gen_range(0.0..std::f32::consts::TAU);
            let (s, c) = phi.sin_cos();
            let a = t1 * c + t2 * s;
            let b = normal.cross(&a);
            let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[a, b, normal]));
            let q = UnitQuaternion::from_rotation_matrix(&rot);
            let scale = [
                (rng.gen_range(0.01f32.ln()..0.05f32.ln())).exp(),
                (rng.gen_range(0.01f32.ln()..0.05f32.ln())).exp(),
                rng.gen_range(0.002..0.005),
            ];
            let jitter =
                |rng: &mut ChaCha8Rng, c: f32| (c + rng.gen_range(-0.08..0.08)).clamp(0.0, 1.0);
            let color = patch.color.map(|c| jitter(&mut rng, c));
            map.push(Gaussian::from_values(
                pos.into(),
                [q.w, q.i, q.j, q.k],
                scale,
                rng.gen_range(0.3..0.99),
                color,
                patch.label,
            ));
            placed += 1;
        }
    }
    map
}

/// Camera-to-world pose at `eye` looking at `target` (OpenCV axes: x right, y down, z forward),
/// for a y-up world.
pub fn look_at(eye: [f64; 3], target: [f64; 3]) -> Pose {
    let e = Point3::from(eye);
    let f = (Point3::from(target) - e).normalize();
    let r = f.cross(&Vector3::y()).normalize();
    let d = f.cross(&r);
    let rot = Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_columns(&[r, d, f]));
    Pose::from_parts(e.coords.into(), UnitQuaternion::from_rotation_matrix(&rot))
}

/// A few camera poses inside the room looking at the furniture (a short arc).
pub fn indoor_poses(count: usize) -> Vec<Pose> {
    (0..count)
        .map(|i| {
            let a = i as f64 * 0.15;
            look_at(
                [-1.8 + 0.3 * a.cos(), 1.5, -1.8 + 0.3 * a.sin()],
                [1.0, 0.8, 1.0],
            )
        })
        .collect()
}
