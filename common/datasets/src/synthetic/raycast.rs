//! Ray-casting renderer: one primary ray per pixel, Lambertian shading,
//! z-depth and instance labels; colour optionally averaged over the pixel's
//! footprint (`Scene::area_sampling`). Rows run in parallel with rayon.

use nalgebra::{Point3, Vector3};
use opengs_geometry::{Intrinsics, Pose};
use rayon::prelude::*;

use super::scene::{Part, Room, Scene};
use super::shape::Ray;
use super::texture::Texture;

/// Camera-space depth below which a part counts as "behind" for culling.
const NEAR: f64 = 1e-3;

/// A rendered view: colour, metric z-depth (0 = no hit) and instance ids.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedView {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
    pub depth: Vec<f32>,
    pub labels: Vec<u16>,
}

/// Nearest surface along a ray.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceHit<'a> {
    pub t: f64,
    pub normal: Vector3<f64>,
    pub instance: u16,
    pub texture: &'a Texture,
}

/// Pixel rectangle (inclusive) a part can cover; parts outside are skipped.
#[derive(Debug, Clone, Copy)]
struct ScreenRect {
    u0: i64,
    u1: i64,
    v0: i64,
    v1: i64,
}

/// Renders `scene` from camera-to-world `pose`.
pub fn render(scene: &Scene, k: &Intrinsics, pose: &Pose) -> RenderedView {
    let (w, h) = (k.width as usize, k.height as usize);
    let mut view = RenderedView {
        width: k.width,
        height: k.height,
        rgb: vec![0; w * h * 3],
        depth: vec![0.0; w * h],
        labels: vec![0; w * h],
    };
    let rects: Vec<Option<ScreenRect>> = scene
        .parts
        .iter()
        .map(|part| screen_rect(part, k, pose))
        .collect();
    let origin = Point3::from(pose.translation.vector);
    let inside = is_inside(&scene.room, &origin);
    let rot = pose.rotation.to_rotation_matrix();
    view.rgb
        .par_chunks_mut(w * 3)
        .zip(view.depth.par_chunks_mut(w))
        .zip(view.labels.par_chunks_mut(w))
        .enumerate()
        .for_each(|(v, ((rgb_row, depth_row), label_row))| {
            let vi = v as i64;
            // Parts whose screen rectangle spans this row.
            let row_parts: Vec<(&Part, ScreenRect)> = scene
                .parts
                .iter()
                .zip(&rects)
                .filter_map(|(part, r)| r.filter(|r| r.v0 <= vi && vi <= r.v1).map(|r| (part, r)))
                .collect();
            // World ray direction is affine in u: row start + u · step.
            let row_start = rot * Vector3::new(-k.cx / k.fx, (v as f64 - k.cy) / k.fy, 1.0);
            let step = rot * Vector3::new(1.0 / k.fx, 0.0, 0.0);
            let step_v = rot * Vector3::new(0.0, 1.0 / k.fy, 0.0);
            for u in 0..w {
                let ui = u as i64;
                let dir = row_start + step * u as f64;
                let candidates = row_parts
                    .iter()
                    .filter(|(_, r)| r.u0 <= ui && ui <= r.u1)
                    .map(|(part, _)| *part);
                let Some(hit) = cast_among(&scene.room, candidates, &origin, &dir, inside) else {
                    continue;
                };
                let p = origin + dir * hit.t;
                let pixel = (v as u64) << 32 | u as u64;
                let colour = shade(scene, &hit, &p, &dir, [&step, &step_v], pixel);
                rgb_row[u * 3..u * 3 + 3].copy_from_slice(&colour);
                // dir_cam.z = 1, so the ray parameter is the z-depth.
                depth_row[u] = hit.t as f32;
                label_row[u] = hit.instance;
            }
        });
    view
}

/// Nearest hit of a world ray against the whole scene (no culling).
pub fn cast<'a>(
    scene: &'a Scene,
    origin: &Point3<f64>,
    dir: &Vector3<f64>,
) -> Option<SurfaceHit<'a>> {
    let inside = is_inside(&scene.room, origin);
    cast_among(&scene.room, scene.parts.iter(), origin, dir, inside)
}

fn is_inside(room: &Room, p: &Point3<f64>) -> bool {
    (0..3).all(|i| room.min[i] < p[i] && p[i] < room.max[i])
}

fn cast_among<'a>(
    room: &'a Room,
    mut parts: impl Iterator<Item = &'a Part>,
    origin: &Point3<f64>,
    dir: &Vector3<f64>,
    camera_inside: bool,
) -> Option<SurfaceHit<'a>> {
    let mut best = if camera_inside {
        room_exit_from_inside(room, origin, dir)
    } else {
        room_hit(room, &Ray::new(*origin, *dir))
    };
    // Divisions are the per-pixel bottleneck: build the inverse direction
    // only for pixels that have candidate parts.
    let Some(first) = parts.next() else {
        return best;
    };
    let ray = Ray::new(*origin, *dir);
    for part in std::iter::once(first).chain(parts) {
        let t_max = best.map_or(f64::INFINITY, |b| b.t);
        if let Some(h) = part.shape.intersect(&ray, t_max) {
            best = Some(SurfaceHit {
                t: h.t,
                normal: h.normal,
                instance: part.instance,
                texture: &part.texture,
            });
        }
    }
    best
}

/// Exit point of a ray starting inside the room, with one division: the
/// exit face is the axis with the smallest (distance to far face) / |d|,
/// compared by cross-multiplication.
fn room_exit_from_inside<'a>(
    room: &'a Room,
    o: &Point3<f64>,
    d: &Vector3<f64>,
) -> Option<SurfaceHit<'a>> {
    let mut best: Option<(f64, f64, usize)> = None;
    for i in 0..3 {
        let (num, den, face) = if d[i] > 0.0 {
            (room.max[i] - o[i], d[i], 2 * i + 1)
        } else if d[i] < 0.0 {
            (o[i] - room.min[i], -d[i], 2 * i)
        } else {
            continue;
        };
        if best.is_none_or(|(bn, bd, _)| num * bd < bn * den) {
            best = Some((num, den, face));
        }
    }
    let (num, den, face) = best?;
    Some(face_hit(room, num / den, face))
}

/// Hit record for room face `face` (order −x, +x, −y, +y, −z, +z) at `t`.
fn face_hit(room: &Room, t: f64, face: usize) -> SurfaceHit<'_> {
    let mut normal = Vector3::zeros();
    // Inward-facing normal: +axis on the min face, −axis on the max face.
    normal[face / 2] = if face & 1 == 0 { 1.0 } else { -1.0 };
    let (instance, texture) = &room.faces[face];
    SurfaceHit {
        t,
        normal,
        instance: *instance,
        texture,
    }
}

/// Inside faces of the room box: the exit point of the ray. Walls are
/// one-sided, so a camera outside the room sees through to the far faces.
fn room_hit<'a>(room: &'a Room, ray: &Ray) -> Option<SurfaceHit<'a>> {
    let mut t_enter = 0.0f64;
    let mut t_exit = f64::INFINITY;
    let mut face = 0;
    for i in 0..3 {
        let t0 = (room.min[i] - ray.origin[i]) * ray.inv_dir[i];
        let t1 = (room.max[i] - ray.origin[i]) * ray.inv_dir[i];
        let (near, far, far_face) = if t0 < t1 {
            (t0, t1, 2 * i + 1)
        } else {
            (t1, t0, 2 * i)
        };
        t_enter = t_enter.max(near);
        if far < t_exit {
            t_exit = far;
            face = far_face;
        }
    }
    if t_exit <= t_enter || !t_exit.is_finite() {
        return None;
    }
    Some(face_hit(room, t_exit, face))
}

/// Lambertian shading with one point light plus ambient; `pixel_steps` are
/// the ray direction's change per pixel in u and v, `pixel` seeds the jitter
/// of area sampling.
fn shade(
    scene: &Scene,
    hit: &SurfaceHit,
    p: &Point3<f64>,
    dir: &Vector3<f64>,
    pixel_steps: [&Vector3<f64>; 2],
    pixel: u64,
) -> [u8; 3] {
    let mut n = hit.normal;
    if n.dot(dir) > 0.0 {
        n = -n;
    }
    // f32 sqrt/division: shorter latency, and shading needs no f64 precision.
    let to_light = (scene.light - p).cast::<f32>();
    let lambert = (n.cast::<f32>().dot(&to_light) / to_light.norm()).max(0.0);
    let gain = scene.ambient + scene.diffuse * lambert;
    let albedo = if scene.area_sampling {
        pixel_albedo(hit, p, dir, pixel_steps, pixel)
    } else {
        hit.texture.albedo(p)
    };
    // `as u8` saturates; +0.5 rounds without a libm call.
    albedo.map(|c| (c * gain * 255.0 + 0.5) as u8)
}

/// Most samples per pixel axis (16 per pixel) a fine texture gets.
pub const MAX_PIXEL_SAMPLES: usize = 4;

/// The albedo a camera pixel records: the texture averaged over the pixel's
/// footprint on the surface, as a sensor integrates light over its area.
/// Where the footprint is wider than half the texture's finest detail, an
/// n × n grid over the footprint (n ≤ `MAX_PIXEL_SAMPLES`), on the hit's
/// tangent plane, so no ray is cast again. Where it is narrower, one sample
/// at `p`, unless the texture has hard edges (cells, bands, mortar) and one
/// crosses the pixel (a footprint corner differs from the centre): then the
/// full grid, so the pixel holds the share of each side. Each sample is
/// jittered inside its cell (from `pixel`, so a pose always renders the
/// same): a regular grid finer than the cap allows would fall on one phase of
/// a periodic texture and alias again. Point-sampling fine stripes or wood
/// rings at a distance draws moiré, and point-sampling a checker edge at any
/// distance a staircase, that no real camera records and no 3D map can
/// reproduce from another view.
pub fn pixel_albedo(
    hit: &SurfaceHit,
    p: &Point3<f64>,
    dir: &Vector3<f64>,
    pixel_steps: [&Vector3<f64>; 2],
    pixel: u64,
) -> [f32; 3] {
    let feature = hit.texture.finest_feature_m();
    if !feature.is_finite() {
        return hit.texture.albedo(p);
    }
    // Surface displacement per pixel: d/dδ of the tangent-plane hit of
    // dir + δ·step is t·(step − dir·(n·step)/(n·dir)).
    let n_dir = hit.normal.dot(dir);
    if n_dir.abs() < 1e-9 {
        return hit.texture.albedo(p);
    }
    let axes = pixel_steps.map(|s| (s - dir * (hit.normal.dot(s) / n_dir)) * hit.t);
    let footprint = axes[0].norm().max(axes[1].norm());
    let mut n = ((2.0 * footprint / feature).ceil() as usize).clamp(1, MAX_PIXEL_SAMPLES);
    if n == 1 {
        let centre = hit.texture.albedo(p);
        if !hit.texture.has_hard_edges() {
            return centre;
        }
        // A feature at least twice the footprint cannot fit between the corners unseen.
        let flat = [(-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)]
            .iter()
            .all(|&(du, dv)| hit.texture.albedo(&(p + axes[0] * du + axes[1] * dv)) == centre);
        if flat {
            return centre;
        }
        n = MAX_PIXEL_SAMPLES;
    }
    let mut sum = [0.0f32; 3];
    let mut state = pixel.wrapping_mul(GOLDEN_GAMMA) ^ 0xD1B5_4A32_D192_ED03;
    let mut jitter = || {
        state = mix64(state.wrapping_add(GOLDEN_GAMMA));
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for i in 0..n {
        for j in 0..n {
            let du = (i as f64 + jitter()) / n as f64 - 0.5;
            let dv = (j as f64 + jitter()) / n as f64 - 0.5;
            let c = hit.texture.albedo(&(p + axes[0] * du + axes[1] * dv));
            for (s, c) in sum.iter_mut().zip(c) {
                *s += c;
            }
        }
    }
    let inv = 1.0 / (n * n) as f32;
    sum.map(|s| s * inv)
}

/// SplitMix64's increment (2^64 / φ).
const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's finaliser (Steele et al. 2014); chained on its own output plus
/// the increment it makes a cheap, well-mixed jitter stream.
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Conservative pixel rectangle of a part's bounding box clipped to the
/// near plane (so parts beside the camera do not cover the whole image);
/// `None` if entirely behind the camera or off screen.
fn screen_rect(part: &Part, k: &Intrinsics, pose: &Pose) -> Option<ScreenRect> {
    let (lo, hi) = part.shape.bounds();
    let world_to_cam = pose.inverse();
    let corners: Vec<Point3<f64>> = (0..8)
        .map(|c| {
            world_to_cam
                * Point3::new(
                    if c & 1 == 0 { lo.x } else { hi.x },
                    if c & 2 == 0 { lo.y } else { hi.y },
                    if c & 4 == 0 { lo.z } else { hi.z },
                )
        })
        .collect();
    // Box ∩ {z ≥ NEAR} is the hull of the front corners and the edge crossings.
    let mut visible: Vec<Point3<f64>> = corners.iter().copied().filter(|q| q.z >= NEAR).collect();
    for a in 0..8 {
        for bit in [1, 2, 4] {
            let b = a | bit;
            if b == a {
                continue;
            }
            let (p, q) = (corners[a], corners[b]);
            if (p.z < NEAR) != (q.z < NEAR) {
                let s = (NEAR - p.z) / (q.z - p.z);
                visible.push(p + (q - p) * s);
            }
        }
    }
    if visible.is_empty() {
        return None;
    }
    let (mut u0, mut u1, mut v0, mut v1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for q in &visible {
        let z = q.z.max(NEAR);
        let u = k.fx * q.x / z + k.cx;
        let v = k.fy * q.y / z + k.cy;
        u0 = u0.min(u);
        u1 = u1.max(u);
        v0 = v0.min(v);
        v1 = v1.max(v);
    }
    // Clamp in f64 first: near-plane points project very far away.
    let clamp = |x: f64, max: i64| x.clamp(-1.0, max as f64 + 1.0) as i64;
    let (w, h) = (k.width as i64, k.height as i64);
    let r = ScreenRect {
        u0: clamp(u0.floor() - 1.0, w).max(0),
        u1: clamp(u1.ceil() + 1.0, w).min(w - 1),
        v0: clamp(v0.floor() - 1.0, h).max(0),
        v1: clamp(v1.ceil() + 1.0, h).min(h - 1),
    };
    (r.u0 <= r.u1 && r.v0 <= r.v1).then_some(r)
}
