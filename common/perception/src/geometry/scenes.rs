//! Hand-built RGB-D test scenes: planes, boxes and spheres ray-cast into a
//! pinhole camera, with the id of the primitive seen at every pixel.

use opengs_geometry::Intrinsics;

pub const WIDTH: u32 = 320;
pub const HEIGHT: u32 = 240;
pub const DEPTH_SCALE: f32 = 1000.0;

/// Surface colour as a function of the world point.
#[derive(Debug, Clone, Copy)]
pub enum Paint {
    Plain([u8; 3]),
    /// Squares of `size` metres alternating between two colours (x, z).
    Checker(f32, [u8; 3], [u8; 3]),
}

#[derive(Debug, Clone, Copy)]
pub enum Shape {
    /// Points p with n·p = offset (the visible side is either).
    Plane {
        normal: [f32; 3],
        offset: f32,
    },
    /// Axis-aligned box.
    Cuboid {
        min: [f32; 3],
        max: [f32; 3],
    },
    Sphere {
        centre: [f32; 3],
        radius: f32,
    },
}

/// World frame: y up. The camera sits at `eye`, looks along +z pitched
/// down by `pitch` radians.
pub struct Scene {
    pub eye: [f32; 3],
    pub pitch: f32,
    pub objects: Vec<(Shape, Paint)>,
}

/// A rendered frame and the object index per pixel (`usize::MAX` = nothing).
pub struct Rendered {
    pub rgb: Vec<u8>,
    pub depth: Vec<u16>,
    pub object: Vec<usize>,
    pub intrinsics: Intrinsics,
}

impl Scene {
    pub fn render(&self) -> Rendered {
        let k = Intrinsics::new(
            260.0,
            260.0,
            (WIDTH as f64 - 1.0) / 2.0,
            (HEIGHT as f64 - 1.0) / 2.0,
            WIDTH,
            HEIGHT,
        );
        let (s, c) = self.pitch.sin_cos();
        // Camera axes in the world: right, down, forward.
        let (right, down, forward) = ([1.0, 0.0, 0.0], [0.0, -c, -s], [0.0, -s, c]);
        let n = (WIDTH * HEIGHT) as usize;
        let mut out = Rendered {
            rgb: vec![0; n * 3],
            depth: vec![0; n],
            object: vec![usize::MAX; n],
            intrinsics: k,
        };
        for i in 0..n {
            let (u, v) = ((i % WIDTH as usize) as f32, (i / WIDTH as usize) as f32);
            let (a, b) = (
                (u - k.cx as f32) / k.fx as f32,
                (v - k.cy as f32) / k.fy as f32,
            );
            // Unit camera z: the hit parameter t is the pixel's depth.
            let dir: [f32; 3] = std::array::from_fn(|j| a * right[j] + b * down[j] + forward[j]);
            let hit = self
                .objects
                .iter()
                .enumerate()
                .filter_map(|(o, (shape, _))| intersect(shape, self.eye, dir).map(|t| (t, o)))
                .min_by(|x, y| x.0.total_cmp(&y.0));
            if let Some((t, o)) = hit {
                let p: [f32; 3] = std::array::from_fn(|j| self.eye[j] + t * dir[j]);
                out.depth[i] = (t * DEPTH_SCALE).round() as u16;
                out.rgb[i * 3..i * 3 + 3].copy_from_slice(&paint(self.objects[o].1, p));
                out.object[i] = o;
            }
        }
        out
    }
}

fn paint(paint: Paint, p: [f32; 3]) -> [u8; 3] {
    match paint {
        Paint::Plain(c) => c,
        Paint::Checker(size, a, b) => {
            let cell = (p[0] / size).floor() as i64 + (p[2] / size).floor() as i64;
            if cell.rem_euclid(2) == 0 {
                a
            } else {
                b
            }
        }
    }
}

/// Nearest positive ray parameter of the hit, if any.
fn intersect(shape: &Shape, o: [f32; 3], d: [f32; 3]) -> Option<f32> {
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let t = match *shape {
        Shape::Plane { normal, offset } => {
            let den = dot(normal, d);
            (den.abs() > 1e-9).then(|| (offset - dot(normal, o)) / den)?
        }
        Shape::Cuboid { min, max } => {
            let (mut near, mut far) = (f32::NEG_INFINITY, f32::INFINITY);
            for j in 0..3 {
                let (a, b) = ((min[j] - o[j]) / d[j], (max[j] - o[j]) / d[j]);
                near = near.max(a.min(b));
                far = far.min(a.max(b));
            }
            (near <= far).then_some(near)?
        }
        Shape::Sphere { centre, radius } => {
            let oc: [f32; 3] = std::array::from_fn(|j| o[j] - centre[j]);
            let (a, b, c) = (dot(d, d), dot(oc, d), dot(oc, oc) - radius * radius);
            let disc = b * b - a * c;
            (disc >= 0.0).then(|| (-b - disc.sqrt()) / a)?
        }
    };
    (t > 1e-3).then_some(t)
}

pub const GREY: [u8; 3] = [128, 128, 128];
pub const WOOD: [u8; 3] = [150, 110, 70];
pub const BLACK: [u8; 3] = [20, 20, 20];
pub const WHITE: [u8; 3] = [235, 235, 235];

/// The floor y = 0.
pub fn floor(paint: Paint) -> (Shape, Paint) {
    (
        Shape::Plane {
            normal: [0.0, 1.0, 0.0],
            offset: 0.0,
        },
        paint,
    )
}

/// A camera 1.2 m above the floor, looking 40° down at a point 1.4 m ahead.
pub fn desk_view(objects: Vec<(Shape, Paint)>) -> Scene {
    Scene {
        eye: [0.0, 1.2, 0.0],
        pitch: 0.7,
        objects,
    }
}
