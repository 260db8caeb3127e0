//! Analytic primitives and their ray intersections. Rays are `o + t·d` with
//! an unnormalised `d`, so `t` is whatever the caller's parametrisation is
//! (the renderer uses camera-z = 1, making `t` the z-depth directly).

use nalgebra::{Point3, Vector3};

/// Hits closer than this are ignored (avoids self-hits at grazing angles).
const T_MIN: f64 = 1e-6;

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// Box rotated about the world z axis by the angle whose (cos, sin) is
    /// `yaw_cos_sin` (precomputed: the renderer tests millions of rays).
    Cuboid {
        centre: Point3<f64>,
        half: Vector3<f64>,
        yaw_cos_sin: [f64; 2],
    },
    Sphere {
        centre: Point3<f64>,
        radius: f64,
    },
    /// Capped cylinder with a vertical axis standing on `base`.
    Cylinder {
        base: Point3<f64>,
        radius: f64,
        height: f64,
    },
    /// Axis-aligned ellipsoid.
    Ellipsoid {
        centre: Point3<f64>,
        radii: Vector3<f64>,
    },
}

/// A ray `origin + t·dir` with its componentwise inverse direction
/// precomputed once per pixel (saves divisions in every box test).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: Point3<f64>,
    pub dir: Vector3<f64>,
    pub inv_dir: Vector3<f64>,
}

impl Ray {
    pub fn new(origin: Point3<f64>, dir: Vector3<f64>) -> Self {
        Self {
            origin,
            dir,
            inv_dir: dir.map(|x| 1.0 / x),
        }
    }
}

/// Nearest intersection: ray parameter and outward unit normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeHit {
    pub t: f64,
    pub normal: Vector3<f64>,
}

impl Shape {
    /// Box with half-extents `half`, rotated by `yaw` radians about world z.
    pub fn cuboid(centre: Point3<f64>, half: Vector3<f64>, yaw: f64) -> Self {
        let (s, c) = yaw.sin_cos();
        Shape::Cuboid {
            centre,
            half,
            yaw_cos_sin: [c, s],
        }
    }

    /// Nearest hit with `T_MIN < t < t_max`.
    pub fn intersect(&self, ray: &Ray, t_max: f64) -> Option<ShapeHit> {
        let (o, d) = (&ray.origin, &ray.dir);
        match *self {
            Shape::Cuboid {
                centre,
                half,
                yaw_cos_sin: [c, s],
            } => {
                let rel = o - centre;
                let (t, axis, sign) = if s == 0.0 {
                    slab_entry(&rel, &ray.inv_dir, &half, t_max)?
                } else {
                    // World → box frame is a rotation by −yaw about z.
                    let lo = Vector3::new(c * rel.x + s * rel.y, -s * rel.x + c * rel.y, rel.z);
                    let ld = Vector3::new(c * d.x + s * d.y, -s * d.x + c * d.y, d.z);
                    slab_entry(&lo, &ld.map(|x| 1.0 / x), &half, t_max)?
                };
                let mut n_local = Vector3::zeros();
                n_local[axis] = sign;
                let normal = Vector3::new(
                    c * n_local.x - s * n_local.y,
                    s * n_local.x + c * n_local.y,
                    n_local.z,
                );
                Some(ShapeHit { t, normal })
            }
            Shape::Sphere { centre, radius } => {
                let t = sphere_root(&(o - centre), d, radius, t_max)?;
                // |p − c| = radius on the surface.
                let normal = ((o + d * t) - centre) * (1.0 / radius);
                Some(ShapeHit { t, normal })
            }
            Shape::Ellipsoid { centre, radii } => {
                let t = quadric_root(&(o - centre), d, &radii, t_max)?;
                let p = (o + d * t) - centre;
                let g = Vector3::new(
                    p.x / (radii.x * radii.x),
                    p.y / (radii.y * radii.y),
                    p.z / (radii.z * radii.z),
                );
                Some(ShapeHit {
                    t,
                    normal: g.normalize(),
                })
            }
            Shape::Cylinder {
                base,
                radius,
                height,
            } => cylinder_hit(&(o - base), d, radius, height, t_max),
        }
    }

    /// World-space axis-aligned bounds (for screen-space culling).
    pub fn bounds(&self) -> (Point3<f64>, Point3<f64>) {
        match *self {
            Shape::Cuboid {
                centre,
                half,
                yaw_cos_sin: [c, s],
            } => {
                let ex = Vector3::new(
                    c.abs() * half.x + s.abs() * half.y,
                    s.abs() * half.x + c.abs() * half.y,
                    half.z,
                );
                (centre - ex, centre + ex)
            }
            Shape::Sphere { centre, radius } => {
                let r = Vector3::repeat(radius);
                (centre - r, centre + r)
            }
            Shape::Ellipsoid { centre, radii } => (centre - radii, centre + radii),
            Shape::Cylinder {
                base,
                radius,
                height,
            } => (
                base - Vector3::new(radius, radius, 0.0),
                base + Vector3::new(radius, radius, height),
            ),
        }
    }
}

/// Entry into an origin-centred box: (t, axis, normal sign). Infinite
/// components of `inv` (axis-parallel rays) fall out of the min/max logic.
fn slab_entry(
    o: &Vector3<f64>,
    inv: &Vector3<f64>,
    half: &Vector3<f64>,
    t_max: f64,
) -> Option<(f64, usize, f64)> {
    let mut t_near = f64::NEG_INFINITY;
    let mut t_far = t_max;
    let mut axis = 0;
    let mut sign = 1.0;
    for i in 0..3 {
        let ta = (-half[i] - o[i]) * inv[i];
        let tb = (half[i] - o[i]) * inv[i];
        // Entering through the −face when moving towards +.
        let (t0, t1, s) = if ta < tb {
            (ta, tb, -1.0)
        } else {
            (tb, ta, 1.0)
        };
        if t0 > t_near {
            t_near = t0;
            axis = i;
            sign = s;
        }
        if t1 < t_far {
            t_far = t1;
        }
    }
    (t_near <= t_far && t_near > T_MIN).then_some((t_near, axis, sign))
}

/// Nearest root of |o + t d|² = r², with a single division on a hit.
fn sphere_root(o: &Vector3<f64>, d: &Vector3<f64>, r: f64, t_max: f64) -> Option<f64> {
    nearest_root(d.dot(d), o.dot(d), o.dot(o) - r * r, t_max)
}

/// Nearest root in (T_MIN, t_max) of a t² + 2 b t + c = 0.
fn nearest_root(a: f64, b: f64, c: f64, t_max: f64) -> Option<f64> {
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    let inv_a = 1.0 / a;
    let t0 = (-b - sq) * inv_a;
    let t = if t0 > T_MIN { t0 } else { (-b + sq) * inv_a };
    (t > T_MIN && t < t_max).then_some(t)
}

/// Nearest root of |(o + t d) / radii|² = 1.
fn quadric_root(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    radii: &Vector3<f64>,
    t_max: f64,
) -> Option<f64> {
    let inv = radii.map(|r| 1.0 / r);
    let os = o.component_mul(&inv);
    let ds = d.component_mul(&inv);
    nearest_root(ds.dot(&ds), os.dot(&ds), os.dot(&os) - 1.0, t_max)
}

/// Capped vertical cylinder with origin at the centre of its bottom cap.
fn cylinder_hit(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    r: f64,
    h: f64,
    t_max: f64,
) -> Option<ShapeHit> {
    let mut best: Option<ShapeHit> = None;
    let mut consider = |t: f64, normal: Vector3<f64>| {
        if t > T_MIN && t < best.map_or(t_max, |b| b.t) {
            best = Some(ShapeHit { t, normal });
        }
    };
    let a = d.x * d.x + d.y * d.y;
    if a > 1e-15 {
        let b = o.x * d.x + o.y * d.y;
        let c = o.x * o.x + o.y * o.y - r * r;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            let inv_a = 1.0 / a;
            for t in [(-b - sq) * inv_a, (-b + sq) * inv_a] {
                let z = o.z + t * d.z;
                if (0.0..=h).contains(&z) {
                    let p = o + d * t;
                    consider(t, Vector3::new(p.x, p.y, 0.0) * (1.0 / r));
                }
            }
        }
    }
    if d.z.abs() > 1e-15 {
        let inv_dz = 1.0 / d.z;
        for (z, nz) in [(0.0, -1.0), (h, 1.0)] {
            let t = (z - o.z) * inv_dz;
            let p = o + d * t;
            if p.x * p.x + p.y * p.y <= r * r {
                consider(t, Vector3::new(0.0, 0.0, nz));
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn sphere_front_hit() {
        let s = Shape::Sphere {
            centre: Point3::new(0.0, 0.0, 5.0),
            radius: 1.0,
        };
        let h = s
            .intersect(&Ray::new(Point3::origin(), Vector3::z()), f64::INFINITY)
            .expect("hit");
        assert_relative_eq!(h.t, 4.0, epsilon = 1e-12);
        assert_relative_eq!(h.normal, -Vector3::z(), epsilon = 1e-12);
    }

    #[test]
    fn rotated_box_hit() {
        let b = Shape::cuboid(
            Point3::new(3.0, 0.0, 0.0),
            Vector3::new(0.5, 0.5, 0.5),
            std::f64::consts::FRAC_PI_4,
        );
        let h = b
            .intersect(&Ray::new(Point3::origin(), Vector3::x()), f64::INFINITY)
            .expect("hit");
        // A 45° box presents its edge: 0.5·√2 in front of the centre.
        assert_relative_eq!(h.t, 3.0 - 0.5 * 2f64.sqrt(), epsilon = 1e-12);
    }

    #[test]
    fn axis_aligned_box_hit_and_miss() {
        let b = Shape::cuboid(Point3::new(0.0, 0.0, 4.0), Vector3::new(1.0, 1.0, 1.0), 0.0);
        let h = b
            .intersect(
                &Ray::new(Point3::origin(), Vector3::new(0.1, 0.0, 1.0)),
                f64::INFINITY,
            )
            .expect("hit");
        assert_relative_eq!(h.t, 3.0, epsilon = 1e-12);
        assert_relative_eq!(h.normal, -Vector3::z(), epsilon = 1e-12);
        assert!(b
            .intersect(
                &Ray::new(Point3::new(2.0, 0.0, 0.0), Vector3::z()),
                f64::INFINITY
            )
            .is_none());
        assert!(b
            .intersect(&Ray::new(Point3::origin(), Vector3::z()), 2.5)
            .is_none());
    }

    #[test]
    fn cylinder_side_and_cap() {
        let c = Shape::Cylinder {
            base: Point3::new(2.0, 0.0, 0.0),
            radius: 0.5,
            height: 1.0,
        };
        let side = c
            .intersect(
                &Ray::new(Point3::new(0.0, 0.0, 0.5), Vector3::x()),
                f64::INFINITY,
            )
            .expect("side");
        assert_relative_eq!(side.t, 1.5, epsilon = 1e-12);
        let cap = c
            .intersect(
                &Ray::new(Point3::new(2.0, 0.0, 3.0), -Vector3::z()),
                f64::INFINITY,
            )
            .expect("cap");
        assert_relative_eq!(cap.t, 2.0, epsilon = 1e-12);
        assert_relative_eq!(cap.normal, Vector3::z(), epsilon = 1e-12);
    }

    #[test]
    fn ellipsoid_hit() {
        let e = Shape::Ellipsoid {
            centre: Point3::new(0.0, 0.0, 0.0),
            radii: Vector3::new(2.0, 1.0, 0.5),
        };
        let h = e
            .intersect(
                &Ray::new(Point3::new(-5.0, 0.0, 0.0), Vector3::x()),
                f64::INFINITY,
            )
            .expect("hit");
        assert_relative_eq!(h.t, 3.0, epsilon = 1e-12);
    }
}
