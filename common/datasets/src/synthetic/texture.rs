//! Procedural solid textures evaluated at world positions, so every surface
//! has photometric detail for tracking and splatting without image assets.

use nalgebra::Point3;

pub type Rgb = [f32; 3];

/// Offset that keeps lattice boundaries off the room's axis-aligned faces
/// (a face exactly on a boundary would flicker between two cells).
const LATTICE_OFFSET: f64 = 0.371;

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Texture {
    Solid(Rgb),
    /// 3D checkerboard, `frequency` cells per metre.
    Checker {
        frequency: f64,
        a: Rgb,
        b: Rgb,
    },
    /// Bands perpendicular to `axis`; `frequency` in bands per metre (not a
    /// period: saves a division per pixel).
    Stripes {
        axis: [f64; 3],
        frequency: f64,
        a: Rgb,
        b: Rgb,
    },
    /// Two-octave value noise blending `a` and `b`.
    Noise {
        scale: f64,
        a: Rgb,
        b: Rgb,
    },
    /// Growth rings around a vertical axis through `centre`, warped by
    /// noise; `rings` per metre.
    Wood {
        centre: [f64; 2],
        rings: f64,
        a: Rgb,
        b: Rgb,
    },
    /// Running-bond bricks for walls (horizontal coordinate x + y).
    Bricks {
        /// Bricks per metre along the wall and rows per metre up it.
        columns_per_m: f64,
        rows_per_m: f64,
        brick: Rgb,
        mortar: Rgb,
    },
}

impl Texture {
    /// Width (m) of the finest detail the texture draws: a band, a cell, a
    /// mortar line, the second noise octave's lattice. A camera pixel whose
    /// footprint is wider than half of it must average several samples
    /// (`raycast::pixel_albedo`). Infinite for a solid colour.
    pub fn finest_feature_m(&self) -> f64 {
        match *self {
            Texture::Solid(_) => f64::INFINITY,
            Texture::Checker { frequency, .. } => 1.0 / frequency,
            Texture::Stripes { frequency, .. } => 0.5 / frequency,
            Texture::Noise { scale, .. } => 1.0 / (2.7 * scale),
            // A quarter ring: the ring profile's ramps and its flat band.
            Texture::Wood { rings, .. } => 0.25 / rings,
            Texture::Bricks {
                columns_per_m,
                rows_per_m,
                ..
            } => (0.08 / rows_per_m).min(0.04 / columns_per_m),
        }
    }

    /// Whether the colour jumps (checker cells, bands, mortar lines) rather than blends
    /// (noise, wood rings): a pixel across such an edge must average its footprint at
    /// any distance (`raycast::pixel_albedo`).
    pub fn has_hard_edges(&self) -> bool {
        matches!(
            self,
            Texture::Checker { .. } | Texture::Stripes { .. } | Texture::Bricks { .. }
        )
    }

    /// Surface colour (linear 0..1) at world point `p`.
    pub fn albedo(&self, p: &Point3<f64>) -> Rgb {
        match *self {
            Texture::Solid(c) => c,
            Texture::Checker { frequency, a, b } => {
                let cell = |x: f64| floor(x * frequency + LATTICE_OFFSET) as i64;
                if (cell(p.x) + cell(p.y) + cell(p.z)).rem_euclid(2) == 0 {
                    a
                } else {
                    b
                }
            }
            Texture::Stripes {
                axis,
                frequency,
                a,
                b,
            } => {
                let s = p.x * axis[0] + p.y * axis[1] + p.z * axis[2];
                let phase = fract(s * frequency + LATTICE_OFFSET);
                if phase < 0.5 {
                    a
                } else {
                    b
                }
            }
            Texture::Noise { scale, a, b } => {
                let q = [p.x * scale, p.y * scale, p.z * scale];
                let n = 0.65 * value_noise(q)
                    + 0.35 * value_noise([q[0] * 2.7, q[1] * 2.7, q[2] * 2.7]);
                mix(a, b, n as f32)
            }
            Texture::Wood {
                centre,
                rings,
                a,
                b,
            } => {
                let r = ((p.x - centre[0]).powi(2) + (p.y - centre[1]).powi(2)).sqrt();
                let warp = value_noise([p.x * 3.0, p.y * 3.0, p.z * 9.0]);
                let phase = fract(r * rings + 0.8 * warp);
                let t = smoothstep(0.2, 0.55, phase) - smoothstep(0.65, 1.0, phase);
                mix(a, b, t as f32)
            }
            Texture::Bricks {
                columns_per_m,
                rows_per_m,
                brick,
                mortar,
            } => {
                let row_f = p.z * rows_per_m + LATTICE_OFFSET;
                let row = floor(row_f);
                let odd_row = (row as i64).rem_euclid(2) as f64;
                let along = (p.x + p.y) * columns_per_m + LATTICE_OFFSET + 0.5 * odd_row;
                let col = floor(along);
                let in_mortar = row_f - row < 0.08 || along - col < 0.04;
                if in_mortar {
                    return mortar;
                }
                // Per-brick brightness so neighbouring bricks differ photometrically.
                let shade = 0.8 + 0.4 * hash3(col as i64, row as i64, 17);
                [brick[0] * shade, brick[1] * shade, brick[2] * shade]
            }
        }
    }
}

/// `f64::floor` without the libm call the baseline x86-64 target emits
/// (it dominated texture cost); exact for |x| < 2^52.
#[inline]
fn floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

#[inline]
fn fract(x: f64) -> f64 {
    x - floor(x)
}

fn mix(a: Rgb, b: Rgb, t: f32) -> Rgb {
    let t = t.clamp(0.0, 1.0);
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Deterministic lattice hash in [0, 1).
fn hash3(x: i64, y: i64, z: i64) -> f32 {
    let mut h = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (z as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 31;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 29;
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Trilinear value noise in [0, 1).
fn value_noise(q: [f64; 3]) -> f64 {
    let (fx, fy, fz) = (floor(q[0]), floor(q[1]), floor(q[2]));
    let (ix, iy, iz) = (fx as i64, fy as i64, fz as i64);
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (tx, ty, tz) = (s(q[0] - fx), s(q[1] - fy), s(q[2] - fz));
    let h = |dx: i64, dy: i64, dz: i64| hash3(ix + dx, iy + dy, iz + dz) as f64;
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(h(0, 0, 0), h(1, 0, 0), tx);
    let x10 = lerp(h(0, 1, 0), h(1, 1, 0), tx);
    let x01 = lerp(h(0, 0, 1), h(1, 0, 1), tx);
    let x11 = lerp(h(0, 1, 1), h(1, 1, 1), tx);
    lerp(lerp(x00, x10, ty), lerp(x01, x11, ty), tz)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_and_deterministic() {
        for i in 0..1000 {
            let q = [i as f64 * 0.137, i as f64 * -0.291, i as f64 * 0.05];
            let n = value_noise(q);
            assert!((0.0..1.0).contains(&n));
            assert_eq!(n, value_noise(q));
        }
    }

    #[test]
    fn fast_floor_matches_std() {
        for x in [-2.5, -2.0, -0.3, -0.0, 0.0, 0.7, 1.0, 3.9999, 1e9 + 0.5] {
            assert_eq!(floor(x), x.floor(), "{x}");
        }
    }

    #[test]
    fn checker_alternates() {
        let t = Texture::Checker {
            frequency: 1.0,
            a: [1.0; 3],
            b: [0.0; 3],
        };
        let c0 = t.albedo(&Point3::new(0.0, 0.0, 0.0));
        let c1 = t.albedo(&Point3::new(1.0, 0.0, 0.0));
        assert_ne!(c0, c1);
    }
}
