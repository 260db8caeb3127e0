//! A procedural room rendered to depth images: the fixed scene that the
//! tests and `opengs bench gicp` register against (no data set needed).

use nalgebra::{Isometry3, Point3, Vector3};
use opengs_geometry::Intrinsics;
use rayon::prelude::*;

/// Axis-aligned solid box (furniture).
#[derive(Debug, Clone, Copy)]
pub struct Cuboid {
    pub min: Point3<f64>,
    pub max: Point3<f64>,
}

/// Solid sphere (clutter with curvature).
#[derive(Debug, Clone, Copy)]
pub struct Sphere {
    pub centre: Point3<f64>,
    pub radius: f64,
}

/// A room seen from inside: walls, floor, ceiling, boxes and spheres.
/// World frame: y points down (like the camera), the floor is at y = +1.2.
#[derive(Debug, Clone)]
pub struct RoomScene {
    pub room_min: Point3<f64>,
    pub room_max: Point3<f64>,
    pub cuboids: Vec<Cuboid>,
    pub spheres: Vec<Sphere>,
}

impl Default for RoomScene {
    fn default() -> Self {
        let cuboid = |a: [f64; 3], b: [f64; 3]| Cuboid {
            min: Point3::from(a),
            max: Point3::from(b),
        };
        let sphere = |c: [f64; 3], r: f64| Sphere {
            centre: Point3::from(c),
            radius: r,
        };
        Self {
            room_min: Point3::new(-2.5, -1.3, -1.0),
            room_max: Point3::new(2.5, 1.2, 4.0),
            cuboids: vec![
                cuboid([-1.6, 0.4, 2.0], [-0.6, 1.2, 3.0]), // table-like block
                cuboid([0.8, -0.2, 2.6], [1.6, 1.2, 3.4]),  // cupboard
                cuboid([-0.3, 0.7, 1.4], [0.3, 1.2, 1.9]),  // low box
                cuboid([1.9, -0.8, 0.5], [2.5, 0.2, 1.6]),  // shelf on the right wall
            ],
            spheres: vec![
                sphere([-1.1, 0.15, 2.5], 0.25),
                sphere([0.1, 0.2, 3.2], 0.35),
                sphere([-2.0, -0.5, 3.5], 0.4),
            ],
        }
    }
}

/// TUM-like 640×480 camera.
pub fn tum_camera() -> Intrinsics {
    Intrinsics::new(525.0, 525.0, 319.5, 239.5, 640, 480)
}

/// Units per metre of the rendered depth (TUM's convention).
pub const DEPTH_UNITS_PER_METRE: f64 = 5000.0;

impl RoomScene {
    /// Depth along the camera's z axis of the first surface hit by the ray
    /// `o + t·d` (with `d` the world direction of a z = 1 camera ray, so the
    /// ray parameter *is* the depth).
    fn depth_along(&self, o: &Point3<f64>, d: &Vector3<f64>) -> Option<f64> {
        let mut best = room_exit(o, d, &self.room_min, &self.room_max);
        for c in &self.cuboids {
            if let Some(t) = cuboid_entry(o, d, c) {
                best = Some(best.map_or(t, |b: f64| b.min(t)));
            }
        }
        for s in &self.spheres {
            if let Some(t) = sphere_entry(o, d, s) {
                best = Some(best.map_or(t, |b: f64| b.min(t)));
            }
        }
        best
    }

    /// Renders a depth image (row-major, `units_per_metre`, 0 = no hit) from
    /// a camera-to-world pose.
    pub fn render_depth(
        &self,
        camera: &Intrinsics,
        camera_to_world: &Isometry3<f64>,
        units_per_metre: f64,
    ) -> Vec<u16> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let origin = Point3::from(camera_to_world.translation.vector);
        let mut depth = vec![0u16; w * h];
        depth.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
            for (u, px) in row.iter_mut().enumerate() {
                let ray = camera.backproject(u as f64, v as f64, 1.0).coords;
                let d = camera_to_world.rotation * ray;
                if let Some(z) = self.depth_along(&origin, &d) {
                    let raw = (z * units_per_metre).round();
                    if raw > 0.0 && raw < u16::MAX as f64 {
                        *px = raw as u16;
                    }
                }
            }
        });
        depth
    }
}

/// Parameter at which a ray starting inside a box leaves it.
fn room_exit(o: &Point3<f64>, d: &Vector3<f64>, lo: &Point3<f64>, hi: &Point3<f64>) -> Option<f64> {
    (0..3)
        .filter(|&i| d[i] != 0.0)
        .map(|i| ((lo[i] - o[i]) / d[i]).max((hi[i] - o[i]) / d[i]))
        .filter(|t| *t > 0.0)
        .min_by(f64::total_cmp)
}

/// Slab test: parameter at which a ray enters a box from outside.
fn cuboid_entry(o: &Point3<f64>, d: &Vector3<f64>, c: &Cuboid) -> Option<f64> {
    let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
    for i in 0..3 {
        let inv = 1.0 / d[i];
        let (a, b) = ((c.min[i] - o[i]) * inv, (c.max[i] - o[i]) * inv);
        near = near.max(a.min(b));
        far = far.min(a.max(b));
    }
    (near <= far && near > 0.0).then_some(near)
}

/// Smaller positive root of `|o + t d − c|² = r²`.
fn sphere_entry(o: &Point3<f64>, d: &Vector3<f64>, s: &Sphere) -> Option<f64> {
    let oc = o - s.centre;
    let (a, b, c) = (d.dot(d), 2.0 * oc.dot(d), oc.dot(&oc) - s.radius * s.radius);
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return None;
    }
    let t = (-b - disc.sqrt()) / (2.0 * a);
    (t > 0.0).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_hits_the_far_wall_or_an_object() {
        let scene = RoomScene::default();
        let cam = tum_camera();
        let depth = scene.render_depth(&cam, &Isometry3::identity(), DEPTH_UNITS_PER_METRE);
        assert!(
            depth.iter().all(|&d| d > 0),
            "a closed room has depth everywhere"
        );
        // Along +z from the origin: the sphere, entered at 3.2 − √(0.35² − 0.1² − 0.2²).
        let centre = depth[240 * 640 + 320] as f64 / DEPTH_UNITS_PER_METRE;
        assert!((centre - 2.9307).abs() < 0.01, "centre depth {centre}");
    }
}
