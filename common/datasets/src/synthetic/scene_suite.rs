//! The scene suite: rooms drawn from a seed (1, 2, …) and furnished where the
//! camera goes and looks, so SLAM can be tuned on some seeds and reported on
//! others. Seed 0 is the fixed room of [`super::scene::indoor_room`], not made here.
//!
//! A room is fitted around a recorded trajectory ([`room_around_trajectory`])
//! or drawn with a loop path around its table ([`room_with_loop`]). The main
//! table goes where the camera looks, with small, thin, stacked and touching
//! objects on it; furniture stands against the walls the camera sees and on
//! the floor where its views reach. Nothing comes within
//! [`CAMERA_CLEARANCE`] of a camera centre.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use nalgebra::{Point3, Vector3};
use opengs_geometry::Pose;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::path::{view_direction, LoopPath};
use super::scene::{Room, Scene, SceneBuilder};
use super::shape::Shape;
use super::texture::{Rgb, Texture};

/// No object comes closer than this to any camera centre of the path (metres).
pub const CAMERA_CLEARANCE: f64 = 0.3;
/// Rooms hold at least this many object instances (walls, floor, ceiling not counted).
pub const MIN_OBJECTS: usize = 12;
/// Camera centres closer than this to the last kept one are not checked
/// one by one; the clearance grows by the same amount to cover them.
const PATH_STEP: f64 = 0.03;
/// Placements are tried this many times before the object is left out.
const ATTEMPTS: usize = 40;
/// Overlaps thinner than this count as touching, not colliding (metres).
const TOUCH: f64 = 1e-6;

// ---------------------------------------------------------------------------
// What a room holds.

/// Catalogue objects; each builds itself in its own frame (x along its
/// width, back towards −y, front towards +y, z up from its support).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Object {
    Monitor,
    Keyboard,
    Cup,
    BookStack,
    BallOnBox,
    DeskPlant,
    DeskLamp,
    Chair,
    Bookshelf,
    Cabinet,
    Sofa,
    Picture,
    BoxStack,
    Ball,
    Bin,
    Plant,
    FloorLamp,
}

/// Where an object stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Site {
    /// On the main table's top.
    Desk,
    /// On the floor at a long side of the main table, facing it.
    BesideDesk,
    /// On the floor with its back against a wall the camera sees.
    Wall,
    /// Hanging on a wall the camera sees.
    OnWall,
    /// On the floor where the camera's views reach it.
    Floor,
}

/// Every room's furnishing, placed in this order: object, site, how many (at least, at most).
const PLAN: &[(Object, Site, usize, usize)] = &[
    (Object::Monitor, Site::Desk, 1, 1),
    (Object::Keyboard, Site::Desk, 0, 1),
    (Object::BookStack, Site::Desk, 1, 1),
    (Object::BallOnBox, Site::Desk, 1, 1),
    (Object::Cup, Site::Desk, 1, 2),
    (Object::DeskPlant, Site::Desk, 0, 1),
    (Object::DeskLamp, Site::Desk, 0, 1),
    (Object::Bookshelf, Site::Wall, 1, 1),
    (Object::Cabinet, Site::Wall, 0, 1),
    (Object::Sofa, Site::Wall, 0, 1),
    (Object::Chair, Site::BesideDesk, 1, 2),
    (Object::BoxStack, Site::Floor, 1, 2),
    (Object::Ball, Site::Floor, 1, 1),
    (Object::Bin, Site::Floor, 0, 1),
    (Object::Plant, Site::Floor, 0, 1),
    (Object::FloorLamp, Site::Floor, 0, 1),
    (Object::Picture, Site::OnWall, 1, 2),
];

/// Drawn in turn until the room holds [`MIN_OBJECTS`].
const FILLERS: &[(Object, Site)] = &[
    (Object::Ball, Site::Floor),
    (Object::BoxStack, Site::Floor),
    (Object::Cup, Site::Desk),
    (Object::Bin, Site::Floor),
    (Object::Picture, Site::OnWall),
];

/// Main table: width, depth, height ranges (metres).
const DESK_WIDTH: (f64, f64) = (1.2, 2.0);
const DESK_DEPTH: (f64, f64) = (0.7, 1.1);
const DESK_HEIGHT: (f64, f64) = (0.70, 0.78);

impl Object {
    /// The object with freshly drawn sizes and materials, in its own frame.
    fn build(self, d: &mut Draw) -> Model {
        match self {
            Object::Monitor => monitor(d),
            Object::Keyboard => keyboard(d),
            Object::Cup => cup(d),
            Object::BookStack => book_stack(d),
            Object::BallOnBox => ball_on_box(d),
            Object::DeskPlant => plant(d, (0.05, 0.07), (0.08, 0.12), (0.08, 0.13)),
            Object::DeskLamp => lamp(d, 0.07, (0.3, 0.45), (0.07, 0.1)),
            Object::Chair => chair(d),
            Object::Bookshelf => bookshelf(d),
            Object::Cabinet => cabinet(d),
            Object::Sofa => sofa(d),
            Object::Picture => picture(d),
            Object::BoxStack => box_stack(d),
            Object::Ball => floor_ball(d),
            Object::Bin => bin(d),
            Object::Plant => plant(d, (0.12, 0.2), (0.25, 0.4), (0.2, 0.35)),
            Object::FloorLamp => lamp(d, 0.15, (1.3, 1.6), (0.15, 0.22)),
        }
    }
}

// ---------------------------------------------------------------------------
// The catalogue: each object in its own frame.

/// One object instance: its class and its primitives.
#[derive(Debug, Clone)]
struct Piece {
    class: &'static str,
    parts: Vec<(Shape, Texture)>,
}

/// What one placement puts down: one or more instances that belong
/// together (a shelf and its books, a stack of boxes).
#[derive(Debug, Clone, Default)]
struct Model {
    pieces: Vec<Piece>,
}

impl Model {
    fn one(class: &'static str, texture: Texture, shapes: Vec<Shape>) -> Self {
        let mut m = Model::default();
        m.push(class, shapes.into_iter().map(|s| (s, texture)).collect());
        m
    }

    fn push(&mut self, class: &'static str, parts: Vec<(Shape, Texture)>) {
        self.pieces.push(Piece { class, parts });
    }

    /// Half extents of the footprint in the model's frame, about its origin.
    fn half(&self) -> (f64, f64) {
        let mut h: (f64, f64) = (0.0, 0.0);
        for (shape, _) in self.pieces.iter().flat_map(|p| &p.parts) {
            let (lo, hi) = shape.bounds();
            h.0 = h.0.max(lo.x.abs()).max(hi.x.abs());
            h.1 = h.1.max(lo.y.abs()).max(hi.y.abs());
        }
        h
    }
}

/// Box centred at `c` with half extents `h`, turned by `yaw` about z.
fn block(c: [f64; 3], h: [f64; 3], yaw: f64) -> Shape {
    Shape::cuboid(Point3::from(c), Vector3::from(h), yaw)
}

fn cylinder(base: [f64; 3], radius: f64, height: f64) -> Shape {
    Shape::Cylinder {
        base: Point3::from(base),
        radius,
        height,
    }
}

fn sphere(c: [f64; 3], radius: f64) -> Shape {
    Shape::Sphere {
        centre: Point3::from(c),
        radius,
    }
}

/// Ellipsoid round in plan (so any yaw leaves it unchanged).
fn dome(c: [f64; 3], radius: f64, half_height: f64) -> Shape {
    Shape::Ellipsoid {
        centre: Point3::from(c),
        radii: Vector3::new(radius, radius, half_height),
    }
}

const CORNERS: [(f64, f64); 4] = [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)];

fn table(d: &mut Draw, width: f64, depth: f64, height: f64) -> Model {
    let top = d.range(0.03, 0.05);
    let leg = d.range(0.025, 0.045);
    let (inset_x, inset_y) = (width / 2.0 - leg - 0.03, depth / 2.0 - leg - 0.03);
    let mut shapes = vec![block(
        [0.0, 0.0, height - top / 2.0],
        [width / 2.0, depth / 2.0, top / 2.0],
        0.0,
    )];
    let leg_half = (height - top) / 2.0;
    for (sx, sy) in CORNERS {
        shapes.push(block(
            [sx * inset_x, sy * inset_y, leg_half],
            [leg, leg, leg_half],
            0.0,
        ));
    }
    let texture = d.material();
    Model::one("table", texture, shapes)
}

fn monitor(d: &mut Draw) -> Model {
    let (w, h, t) = (
        d.range(0.45, 0.65),
        d.range(0.28, 0.38),
        d.range(0.025, 0.04),
    );
    let neck = d.range(0.1, 0.16);
    let frame = d.material();
    let screen = d.material();
    let mut m = Model::default();
    m.push(
        "monitor",
        vec![
            (block([0.0, 0.0, 0.008], [0.11, 0.08, 0.008], 0.0), frame),
            (
                block(
                    [0.0, -0.03, 0.016 + neck / 2.0],
                    [0.025, 0.012, neck / 2.0],
                    0.0,
                ),
                frame,
            ),
            (
                block(
                    [0.0, -0.03 + 0.012 + t / 2.0, 0.016 + neck + h / 2.0 - 0.05],
                    [w / 2.0, t / 2.0, h / 2.0],
                    0.0,
                ),
                screen,
            ),
        ],
    );
    m
}

/// Thin: at most 2 cm tall.
fn keyboard(d: &mut Draw) -> Model {
    let t = d.range(0.012, 0.02);
    let shape = block(
        [0.0, 0.0, t / 2.0],
        [d.range(0.19, 0.23), d.range(0.06, 0.08), t / 2.0],
        0.0,
    );
    let texture = d.material();
    Model::one("keyboard", texture, vec![shape])
}

/// Small: under 10 cm.
fn cup(d: &mut Draw) -> Model {
    let shape = cylinder([0.0; 3], d.range(0.03, 0.045), d.range(0.07, 0.1));
    let texture = d.material();
    Model::one("cup", texture, vec![shape])
}

/// Two or three flat books lying on each other, each its own instance.
fn book_stack(d: &mut Draw) -> Model {
    let mut m = Model::default();
    let mut z = 0.0;
    for _ in 0..d.count(2, 3) {
        let t = d.range(0.012, 0.035);
        let shape = block(
            [0.0, 0.0, z + t / 2.0],
            [d.range(0.07, 0.11), d.range(0.095, 0.14), t / 2.0],
            d.range(-0.3, 0.3),
        );
        let texture = d.material();
        m.push("book", vec![(shape, texture)]);
        z += t;
    }
    m
}

/// A small box with a small ball resting on it.
fn ball_on_box(d: &mut Draw) -> Model {
    let half = [d.range(0.05, 0.1), d.range(0.05, 0.1), d.range(0.04, 0.08)];
    let r = d.range(0.03, 0.05);
    let mut m = Model::default();
    let box_texture = d.material();
    m.push(
        "box",
        vec![(
            block([0.0, 0.0, half[2]], half, d.range(0.0, PI)),
            box_texture,
        )],
    );
    let ball_texture = d.material();
    m.push(
        "ball",
        vec![(sphere([0.0, 0.0, 2.0 * half[2] + r], r), ball_texture)],
    );
    m
}

/// Pot and foliage; sizes in metres: pot radius, pot height, foliage radius.
fn plant(d: &mut Draw, pot_r: (f64, f64), pot_h: (f64, f64), leaves_r: (f64, f64)) -> Model {
    let (r, h, leaves) = (
        d.range(pot_r.0, pot_r.1),
        d.range(pot_h.0, pot_h.1),
        d.range(leaves_r.0, leaves_r.1),
    );
    let half_height = leaves * d.range(1.0, 1.4);
    let pot = d.material();
    let foliage = d.foliage();
    let mut m = Model::default();
    m.push(
        "plant",
        vec![
            (cylinder([0.0; 3], r, h), pot),
            (
                dome([0.0, 0.0, h + 0.85 * half_height], leaves, half_height),
                foliage,
            ),
        ],
    );
    m
}

/// Base, pole and shade; `base_r` and the pole height and shade radius ranges in metres.
fn lamp(d: &mut Draw, base_r: f64, pole: (f64, f64), shade_r: (f64, f64)) -> Model {
    let (h, shade) = (d.range(pole.0, pole.1), d.range(shade_r.0, shade_r.1));
    let metal = d.material();
    let cloth = d.material();
    let mut m = Model::default();
    m.push(
        "lamp",
        vec![
            (cylinder([0.0; 3], base_r, 0.02), metal),
            (cylinder([0.0, 0.0, 0.02], base_r * 0.15, h), metal),
            (dome([0.0, 0.0, 0.02 + h], shade, shade * 0.7), cloth),
        ],
    );
    m
}

/// Seat, back (at −y) and four legs; the sitter faces +y.
fn chair(d: &mut Draw) -> Model {
    let (s, seat_h, back_h) = (d.range(0.18, 0.23), d.range(0.42, 0.48), d.range(0.35, 0.5));
    let leg = 0.018;
    let mut shapes = vec![
        block([0.0, 0.0, seat_h], [s, s, 0.02], 0.0),
        block(
            [0.0, -s + 0.02, seat_h + 0.02 + back_h / 2.0],
            [s, 0.02, back_h / 2.0],
            0.0,
        ),
    ];
    let leg_half = (seat_h - 0.02) / 2.0;
    for (sx, sy) in CORNERS {
        shapes.push(block(
            [sx * (s - leg), sy * (s - leg), leg_half],
            [leg, leg, leg_half],
            0.0,
        ));
    }
    let texture = d.material();
    Model::one("chair", texture, shapes)
}

/// Sides, back, boards, and a row of standing books on some boards (one
/// "books" instance per row).
fn bookshelf(d: &mut Draw) -> Model {
    let (w, depth, h) = (d.range(0.7, 1.2), d.range(0.28, 0.38), d.range(1.2, 2.0));
    let levels = ((h / 0.4).floor() as usize).max(3);
    let spacing = (h - 0.03) / levels as f64;
    let wood = d.material();
    let mut shapes = vec![
        block(
            [-(w / 2.0 - 0.015), 0.0, h / 2.0],
            [0.015, depth / 2.0, h / 2.0],
            0.0,
        ),
        block(
            [w / 2.0 - 0.015, 0.0, h / 2.0],
            [0.015, depth / 2.0, h / 2.0],
            0.0,
        ),
        block(
            [0.0, -depth / 2.0 + 0.008, h / 2.0],
            [w / 2.0 - 0.03, 0.008, h / 2.0],
            0.0,
        ),
    ];
    for k in 0..=levels {
        shapes.push(block(
            [0.0, 0.0, 0.015 + k as f64 * spacing],
            [w / 2.0 - 0.03, depth / 2.0, 0.015],
            0.0,
        ));
    }
    let mut m = Model::one("bookshelf", wood, shapes);
    for k in 0..levels {
        if !d.chance(0.6) {
            continue;
        }
        let floor = 0.03 + k as f64 * spacing;
        let mut x = -w / 2.0 + 0.04;
        let mut row = Vec::new();
        while x < w / 2.0 - 0.1 {
            let (t, bh, bd) = (
                d.range(0.02, 0.05),
                d.range(0.15, (spacing - 0.05).max(0.16)),
                d.range(0.15, depth - 0.04),
            );
            let cover = d.material();
            row.push((
                block(
                    [
                        x + t / 2.0,
                        -depth / 2.0 + 0.02 + bd / 2.0,
                        floor + bh / 2.0,
                    ],
                    [t / 2.0, bd / 2.0, bh / 2.0],
                    0.0,
                ),
                cover,
            ));
            x += t + d.range(0.0, 0.01);
        }
        m.push("books", row);
    }
    m
}

/// A box against the wall, sometimes with a vase on top.
fn cabinet(d: &mut Draw) -> Model {
    let (w, depth, h) = (d.range(0.6, 1.2), d.range(0.35, 0.5), d.range(0.7, 1.1));
    let texture = d.material();
    let mut m = Model::one(
        "cabinet",
        texture,
        vec![block(
            [0.0, 0.0, h / 2.0],
            [w / 2.0, depth / 2.0, h / 2.0],
            0.0,
        )],
    );
    if d.chance(0.7) {
        let (r, half_height) = (d.range(0.06, 0.1), d.range(0.1, 0.18));
        let x = d.range(-w / 4.0, w / 4.0);
        let glaze = d.material();
        m.push(
            "vase",
            vec![(dome([x, 0.0, h + half_height], r, half_height), glaze)],
        );
    }
    m
}

fn sofa(d: &mut Draw) -> Model {
    let (w, depth) = (d.range(1.4, 2.0), d.range(0.75, 0.9));
    let texture = d.material();
    Model::one(
        "sofa",
        texture,
        vec![
            block(
                [0.0, 0.05, 0.21],
                [w / 2.0 - 0.12, depth / 2.0 - 0.05, 0.21],
                0.0,
            ),
            block([0.0, -depth / 2.0 + 0.1, 0.4], [w / 2.0, 0.1, 0.4], 0.0),
            block([-(w / 2.0 - 0.06), 0.0, 0.3], [0.06, depth / 2.0, 0.3], 0.0),
            block([w / 2.0 - 0.06, 0.0, 0.3], [0.06, depth / 2.0, 0.3], 0.0),
        ],
    )
}

/// Thin (1–2 cm) frame hanging on a wall.
fn picture(d: &mut Draw) -> Model {
    let t = d.range(0.01, 0.02);
    let (w, h) = (d.range(0.3, 0.9), d.range(0.25, 0.6));
    let shape = block(
        [0.0, 0.0, d.range(1.2, 1.7)],
        [w / 2.0, t / 2.0, h / 2.0],
        0.0,
    );
    let texture = d.material();
    Model::one("picture", texture, vec![shape])
}

/// One to three boxes stacked (touching), each its own instance, sometimes a ball on top.
fn box_stack(d: &mut Draw) -> Model {
    let mut m = Model::default();
    let mut half = [d.range(0.15, 0.3), d.range(0.15, 0.3), d.range(0.1, 0.25)];
    let mut z = 0.0;
    for _ in 0..d.count(1, 3) {
        let texture = d.material();
        m.push(
            "box",
            vec![(
                block([0.0, 0.0, z + half[2]], half, d.range(-0.4, 0.4)),
                texture,
            )],
        );
        z += 2.0 * half[2];
        let shrink = d.range(0.6, 0.9);
        half = [
            half[0] * shrink,
            half[1] * shrink,
            half[2] * d.range(0.6, 1.0),
        ];
    }
    if d.chance(0.4) {
        let r = d.range(0.06, 0.12);
        let texture = d.material();
        m.push("ball", vec![(sphere([0.0, 0.0, z + r], r), texture)]);
    }
    m
}

fn floor_ball(d: &mut Draw) -> Model {
    let r = d.range(0.1, 0.25);
    let texture = d.material();
    Model::one("ball", texture, vec![sphere([0.0, 0.0, r], r)])
}

fn bin(d: &mut Draw) -> Model {
    let shape = cylinder([0.0; 3], d.range(0.12, 0.2), d.range(0.3, 0.5));
    let texture = d.material();
    Model::one("bin", texture, vec![shape])
}

// ---------------------------------------------------------------------------
// Random draws: sizes, colours, materials.

/// The room's random stream, with the draws the catalogue needs.
struct Draw {
    rng: ChaCha8Rng,
}

impl Draw {
    fn new(seed: u64) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// Uniform in [lo, hi) (lo when the range is empty, never a panic).
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo).max(0.0) * self.rng.gen::<f64>()
    }

    fn chance(&mut self, p: f64) -> bool {
        self.rng.gen::<f64>() < p
    }

    /// Uniform integer in [lo, hi].
    fn count(&mut self, lo: usize, hi: usize) -> usize {
        lo + self.rng.gen_range(0..=hi.saturating_sub(lo))
    }

    fn colour(&mut self) -> Rgb {
        let (h, s, v) = (
            self.range(0.0, 1.0),
            self.range(0.15, 0.85),
            self.range(0.3, 0.95),
        );
        hsv(h, s, v)
    }

    /// A colour whose luminance differs from `a` by at least 0.25 (so
    /// patterns stay visible to photometric tracking).
    fn contrasting(&mut self, a: Rgb) -> Rgb {
        let mut b = self.colour();
        for _ in 0..20 {
            if (luminance(a) - luminance(b)).abs() >= 0.25 {
                break;
            }
            b = self.colour();
        }
        if (luminance(a) - luminance(b)).abs() < 0.25 {
            // Give up drawing: pick the far end of the grey scale.
            b = if luminance(a) > 0.5 {
                [0.1; 3]
            } else {
                [0.9; 3]
            };
        }
        b
    }

    /// Plain, fine noise (1–3 cm), stripes, checkers or wood.
    fn material(&mut self) -> Texture {
        let a = self.colour();
        let b = self.contrasting(a);
        match self.rng.gen_range(0..11) {
            0..=1 => Texture::Solid(a),
            2..=4 => Texture::Noise {
                scale: self.range(33.0, 100.0),
                a,
                b,
            },
            5..=6 => {
                let axis = Vector3::new(
                    self.range(-1.0, 1.0),
                    self.range(-1.0, 1.0),
                    self.range(-1.0, 1.0),
                )
                .try_normalize(1e-6)
                .unwrap_or_else(Vector3::z);
                Texture::Stripes {
                    axis: [axis.x, axis.y, axis.z],
                    frequency: self.range(4.0, 25.0),
                    a,
                    b,
                }
            }
            7..=8 => Texture::Checker {
                frequency: self.range(4.0, 20.0),
                a,
                b,
            },
            _ => Texture::Wood {
                centre: [self.range(-5.0, 5.0), self.range(-5.0, 5.0)],
                rings: self.range(15.0, 50.0),
                a,
                b,
            },
        }
    }

    /// Any material, or bricks.
    fn wall_material(&mut self) -> Texture {
        if self.chance(0.2) {
            let brick = self.colour();
            let mortar = self.contrasting(brick);
            Texture::Bricks {
                columns_per_m: self.range(3.0, 5.0),
                rows_per_m: self.range(10.0, 15.0),
                brick,
                mortar,
            }
        } else {
            self.material()
        }
    }

    /// Green leaves with fine noise.
    fn foliage(&mut self) -> Texture {
        let a = hsv(
            self.range(0.22, 0.4),
            self.range(0.5, 0.9),
            self.range(0.25, 0.45),
        );
        let b = hsv(
            self.range(0.2, 0.35),
            self.range(0.4, 0.8),
            self.range(0.7, 0.95),
        );
        Texture::Noise {
            scale: self.range(33.0, 100.0),
            a,
            b,
        }
    }
}

fn hsv(h: f64, s: f64, v: f64) -> Rgb {
    let sector = (h.rem_euclid(1.0) * 6.0).min(5.999_999);
    let f = sector.fract();
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match sector as u8 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [r as f32, g as f32, b as f32]
}

fn luminance(c: Rgb) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

// ---------------------------------------------------------------------------
// Placement geometry.

/// Where a model goes: its origin in the world and its yaw about z.
#[derive(Debug, Clone, Copy)]
struct Frame {
    origin: Point3<f64>,
    yaw: f64,
}

impl Frame {
    fn new(origin: Point3<f64>, yaw: f64) -> Self {
        Self { origin, yaw }
    }

    /// World point of model-frame point (x, y, z).
    fn point(&self, x: f64, y: f64, z: f64) -> Point3<f64> {
        let (s, c) = self.yaw.sin_cos();
        self.origin + Vector3::new(c * x - s * y, s * x + c * y, z)
    }

    /// The frame moved to model-frame point (x, y, z) and turned by `yaw`.
    fn child(&self, x: f64, y: f64, z: f64, yaw: f64) -> Frame {
        Frame::new(self.point(x, y, z), self.yaw + yaw)
    }

    /// `shape` (in this frame) in world coordinates.
    fn place(&self, shape: &Shape) -> Shape {
        let at = |p: &Point3<f64>| self.point(p.x, p.y, p.z);
        match *shape {
            Shape::Cuboid {
                centre,
                half,
                yaw_cos_sin: [c, s],
            } => cuboid_turned(at(&centre), half, s.atan2(c) + self.yaw),
            Shape::Sphere { centre, radius } => Shape::Sphere {
                centre: at(&centre),
                radius,
            },
            Shape::Cylinder {
                base,
                radius,
                height,
            } => Shape::Cylinder {
                base: at(&base),
                radius,
                height,
            },
            // The catalogue's ellipsoids are round in plan, so yaw leaves them be.
            Shape::Ellipsoid { centre, radii } => Shape::Ellipsoid {
                centre: at(&centre),
                radii,
            },
        }
    }
}

/// A box turned by `yaw`; quarter turns become axis-aligned boxes (exact
/// faces, and the renderer's cheaper unrotated test).
fn cuboid_turned(centre: Point3<f64>, half: Vector3<f64>, yaw: f64) -> Shape {
    let (s, c) = yaw.sin_cos();
    if s.abs() < 1e-9 {
        Shape::cuboid(centre, half, 0.0)
    } else if c.abs() < 1e-9 {
        Shape::cuboid(centre, Vector3::new(half.y, half.x, half.z), 0.0)
    } else {
        Shape::cuboid(centre, half, yaw)
    }
}

/// Collision volume of a part: a box turned about z (exact for boxes,
/// the bounding box for round shapes).
#[derive(Debug, Clone, Copy)]
struct Solid {
    centre: [f64; 2],
    half: [f64; 2],
    cos_sin: [f64; 2],
    z: [f64; 2],
}

impl Solid {
    fn of(shape: &Shape) -> Self {
        match *shape {
            Shape::Cuboid {
                centre,
                half,
                yaw_cos_sin,
            } => Solid {
                centre: [centre.x, centre.y],
                half: [half.x, half.y],
                cos_sin: yaw_cos_sin,
                z: [centre.z - half.z, centre.z + half.z],
            },
            _ => {
                let (lo, hi) = shape.bounds();
                Solid {
                    centre: [(lo.x + hi.x) / 2.0, (lo.y + hi.y) / 2.0],
                    half: [(hi.x - lo.x) / 2.0, (hi.y - lo.y) / 2.0],
                    cos_sin: [1.0, 0.0],
                    z: [lo.z, hi.z],
                }
            }
        }
    }

    /// Whether the two volumes share more than a touching face.
    fn overlaps(&self, other: &Solid) -> bool {
        if self.z[1].min(other.z[1]) - self.z[0].max(other.z[0]) <= TOUCH {
            return false;
        }
        let d = [
            other.centre[0] - self.centre[0],
            other.centre[1] - self.centre[1],
        ];
        let axes = |s: &Solid| {
            let [c, si] = s.cos_sin;
            [[c, si], [-si, c]]
        };
        let (a, b) = (axes(self), axes(other));
        // Separating axis test over both boxes' edge directions.
        a.iter().chain(b.iter()).all(|u| {
            let reach = |s: &Solid, ax: &[[f64; 2]; 2]| {
                s.half[0] * (u[0] * ax[0][0] + u[1] * ax[0][1]).abs()
                    + s.half[1] * (u[0] * ax[1][0] + u[1] * ax[1][1]).abs()
            };
            let gap = (d[0] * u[0] + d[1] * u[1]).abs();
            reach(self, &a) + reach(other, &b) - gap > TOUCH
        })
    }
}

/// Distance from `p` to the box [lo, hi] (0 inside).
fn box_distance(lo: &Point3<f64>, hi: &Point3<f64>, p: &Point3<f64>) -> f64 {
    let d = Vector3::from_fn(|i, _| (lo[i] - p[i]).max(p[i] - hi[i]).max(0.0));
    d.norm()
}

// ---------------------------------------------------------------------------
// What the camera does.

/// Where the camera goes and what it looks at, as the generator needs it.
struct Views {
    /// Camera centres, thinned to one per [`PATH_STEP`].
    centres: Vec<Point3<f64>>,
    /// How far a real camera centre may be from the nearest listed one.
    slack: f64,
    /// Optical axes (origin, unit direction) of a subsample of the poses.
    axes: Vec<(Point3<f64>, Vector3<f64>)>,
    /// The optical axes plus rays towards the image corners.
    rays: Vec<(Point3<f64>, Vector3<f64>)>,
}

/// Normalised image coordinates of the rays cast per pose (centre and near the corners).
const VIEW_RAYS: [(f64, f64); 5] = [
    (0.0, 0.0),
    (-0.5, -0.35),
    (0.5, -0.35),
    (-0.5, 0.35),
    (0.5, 0.35),
];
/// At most this many poses are used to find where the camera looks.
const MAX_VIEW_POSES: usize = 800;

impl Views {
    /// From camera-to-world poses already in the room's frame.
    fn from_poses(poses: &[Pose]) -> Self {
        let mut centres: Vec<Point3<f64>> = Vec::new();
        for p in poses {
            let c = Point3::from(p.translation.vector);
            if centres.last().is_none_or(|l| (l - c).norm() > PATH_STEP) {
                centres.push(c);
            }
        }
        let stride = poses.len().div_ceil(MAX_VIEW_POSES).max(1);
        let mut axes = Vec::new();
        let mut rays = Vec::new();
        for p in poses.iter().step_by(stride) {
            let o = Point3::from(p.translation.vector);
            axes.push((o, view_direction(p).into_inner()));
            for (x, y) in VIEW_RAYS {
                rays.push((o, (p.rotation * Vector3::new(x, y, 1.0)).normalize()));
            }
        }
        Self {
            centres,
            slack: PATH_STEP,
            axes,
            rays,
        }
    }

    /// Where the view rays leave the empty room: floor points and, per wall
    /// (−x, +x, −y, +y), the coordinate along the wall.
    fn room_hits(&self, min: &Point3<f64>, max: &Point3<f64>) -> (Vec<[f64; 2]>, [Vec<f64>; 4]) {
        let mut floor = Vec::new();
        let mut walls: [Vec<f64>; 4] = Default::default();
        for (o, d) in &self.rays {
            let mut best = (f64::INFINITY, 6);
            for i in 0..3 {
                let (t, face) = if d[i] > 1e-9 {
                    ((max[i] - o[i]) / d[i], 2 * i + 1)
                } else if d[i] < -1e-9 {
                    ((min[i] - o[i]) / d[i], 2 * i)
                } else {
                    continue;
                };
                if t < best.0 {
                    best = (t, face);
                }
            }
            let (t, face) = best;
            if !t.is_finite() || t < 0.0 {
                continue;
            }
            let p = o + d * t;
            match face {
                0 | 1 => walls[face].push(p.y),
                2 | 3 => walls[face].push(p.x),
                4 => floor.push([p.x, p.y]),
                _ => {}
            }
        }
        (floor, walls)
    }

    /// Where the optical axes cross the plane z = `height` (within 4 m of
    /// the camera), or 1.5 m along the axis when they do not.
    fn look_points(&self, height: f64) -> Vec<[f64; 2]> {
        self.axes
            .iter()
            .map(|(o, d)| {
                let s = if d.z < -0.05 {
                    (height - o.z) / d.z
                } else {
                    f64::NAN
                };
                let s = if s > 0.2 && s < 4.0 { s } else { 1.5 };
                let p = o + d * s;
                [p.x, p.y]
            })
            .collect()
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => 0.0,
        n => v[n / 2],
    }
}

fn quantile(v: &[f64], q: f64) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(((v.len().saturating_sub(1)) as f64 * q).round() as usize)
        .copied()
        .unwrap_or(0.0)
}

// ---------------------------------------------------------------------------
// Furnishing.

/// The main table: where it stands and its size.
#[derive(Debug, Clone, Copy)]
struct Desk {
    frame: Frame,
    width: f64,
    depth: f64,
    height: f64,
}

struct Furnisher<'v> {
    draw: Draw,
    min: Point3<f64>,
    max: Point3<f64>,
    views: &'v Views,
    builder: SceneBuilder,
    solids: Vec<Solid>,
    objects: usize,
    desk: Option<Desk>,
    floor_hits: Vec<[f64; 2]>,
    wall_hits: [Vec<f64>; 4],
}

impl<'v> Furnisher<'v> {
    /// Puts `model` down at `frame` if it stays inside the room, collides
    /// with nothing placed and keeps clear of every camera centre.
    fn place(&mut self, model: &Model, frame: Frame) -> bool {
        let world: Vec<(&'static str, Vec<(Shape, Texture)>)> = model
            .pieces
            .iter()
            .map(|p| {
                let parts = p.parts.iter().map(|(s, t)| (frame.place(s), *t)).collect();
                (p.class, parts)
            })
            .collect();
        let shapes: Vec<Shape> = world
            .iter()
            .flat_map(|(_, parts)| parts.iter().map(|(s, _)| *s))
            .collect();
        let bounds: Vec<(Point3<f64>, Point3<f64>)> = shapes.iter().map(Shape::bounds).collect();
        let eps = 1e-9;
        let inside = bounds.iter().all(|(lo, hi)| {
            (0..3).all(|i| lo[i] >= self.min[i] - eps && hi[i] <= self.max[i] + eps)
        });
        if !inside {
            return false;
        }
        let clearance = CAMERA_CLEARANCE + self.views.slack;
        let (lo, hi) = bounds.iter().fold(
            (Point3::from([f64::MAX; 3]), Point3::from([f64::MIN; 3])),
            |(a, b), (lo, hi)| (a.inf(lo), b.sup(hi)),
        );
        let clear = self.views.centres.iter().all(|c| {
            box_distance(&lo, &hi, c) >= clearance
                || bounds
                    .iter()
                    .all(|(l, h)| box_distance(l, h, c) >= clearance)
        });
        if !clear {
            return false;
        }
        let solids: Vec<Solid> = shapes.iter().map(Solid::of).collect();
        if solids
            .iter()
            .any(|s| self.solids.iter().any(|o| s.overlaps(o)))
        {
            return false;
        }
        self.solids.extend(solids);
        for (class, parts) in world {
            let id = self.builder.instance(class);
            for (shape, texture) in parts {
                self.builder.add(id, texture, &[shape]);
            }
            self.objects += 1;
        }
        true
    }

    /// Tries `object` at `site` until it fits; whether it was placed.
    fn place_at(&mut self, object: Object, site: Site) -> bool {
        for _ in 0..ATTEMPTS {
            let model = object.build(&mut self.draw);
            let Some(frame) = self.site_frame(site, &model) else {
                continue;
            };
            if self.place(&model, frame) {
                return true;
            }
        }
        false
    }

    /// A random frame for `model` at `site`; `None` when the site does not exist.
    fn site_frame(&mut self, site: Site, model: &Model) -> Option<Frame> {
        let (hx, hy) = model.half();
        match site {
            Site::Desk => {
                let desk = self.desk?;
                let yaw = self.draw.range(-PI, PI);
                let (s, c) = yaw.sin_cos();
                // Footprint extents along the desk's axes once turned.
                let (ex, ey) = (c.abs() * hx + s.abs() * hy, s.abs() * hx + c.abs() * hy);
                let (rx, ry) = (desk.width / 2.0 - ex, desk.depth / 2.0 - ey);
                if rx < 0.0 || ry < 0.0 {
                    return None;
                }
                let (u, v) = (self.draw.range(-rx, rx), self.draw.range(-ry, ry));
                Some(desk.frame.child(u, v, desk.height, yaw))
            }
            Site::BesideDesk => {
                let desk = self.desk?;
                let side = if self.draw.chance(0.5) { 1.0 } else { -1.0 };
                let u = self
                    .draw
                    .range(-desk.width / 2.0 + hx, desk.width / 2.0 - hx);
                let v = side * (desk.depth / 2.0 + hy + self.draw.range(0.02, 0.2));
                // The chair's front (+y) faces the desk.
                let yaw = if side > 0.0 { PI } else { 0.0 } + self.draw.range(-0.25, 0.25);
                Some(desk.frame.child(u, v, 0.0, yaw))
            }
            Site::Wall | Site::OnWall => {
                let wall = self.pick_wall();
                let hits = &self.wall_hits[wall];
                let axis = if wall < 2 { 1 } else { 0 };
                let (lo, hi) = (self.min[axis] + hx, self.max[axis] - hx);
                if lo > hi {
                    return None;
                }
                let along = if hits.is_empty() {
                    self.draw.range(lo, hi)
                } else {
                    let i = self.draw.rng.gen_range(0..hits.len());
                    hits[i] + self.draw.range(-0.5, 0.5)
                }
                .clamp(lo, hi);
                // Yaw that turns the model's front (+y) into the room.
                let (x, y, yaw) = match wall {
                    0 => (self.min.x + hy, along, -FRAC_PI_2),
                    1 => (self.max.x - hy, along, FRAC_PI_2),
                    2 => (along, self.min.y + hy, 0.0),
                    _ => (along, self.max.y - hy, PI),
                };
                Some(Frame::new(Point3::new(x, y, 0.0), yaw))
            }
            Site::Floor => {
                let margin = hx.max(hy);
                let (x, y) = if self.floor_hits.is_empty() || self.draw.chance(0.15) {
                    (
                        self.draw.range(self.min.x + margin, self.max.x - margin),
                        self.draw.range(self.min.y + margin, self.max.y - margin),
                    )
                } else {
                    let i = self.draw.rng.gen_range(0..self.floor_hits.len());
                    let [x, y] = self.floor_hits[i];
                    (
                        x + self.draw.range(-0.3, 0.3),
                        y + self.draw.range(-0.3, 0.3),
                    )
                };
                Some(Frame::new(Point3::new(x, y, 0.0), self.draw.range(-PI, PI)))
            }
        }
    }

    /// A wall, more likely the more the camera looks at it.
    fn pick_wall(&mut self) -> usize {
        let weights: Vec<f64> = self
            .wall_hits
            .iter()
            .map(|h| h.len() as f64 + 1.0)
            .collect();
        let mut x = self.draw.range(0.0, weights.iter().sum());
        for (i, w) in weights.iter().enumerate() {
            if x < *w {
                return i;
            }
            x -= w;
        }
        3
    }

    /// The main table at `desk`, shrunk or moved until it fits; the desk kept.
    fn place_desk(&mut self, desk: Desk) {
        for attempt in 0..ATTEMPTS {
            let k = attempt as f64;
            let shrink = (1.0 - 0.05 * k).max(0.6);
            let reach = 0.1 * k;
            let mut d = Desk {
                width: desk.width * shrink,
                depth: desk.depth * shrink,
                ..desk
            };
            // Late attempts try a coffee table (a camera that passes low over the desk).
            if attempt >= ATTEMPTS / 2 {
                d.height = 0.45;
            }
            d.frame = desk.frame.child(
                self.draw.range(-reach, reach),
                self.draw.range(-reach, reach),
                0.0,
                0.0,
            );
            let model = table(&mut self.draw, d.width, d.depth, d.height);
            if self.place(&model, d.frame) {
                self.desk = Some(d);
                return;
            }
        }
    }

    /// Everything of [`PLAN`], then fillers up to [`MIN_OBJECTS`].
    fn furnish(&mut self, desk: Desk) {
        self.place_desk(desk);
        for &(object, site, lo, hi) in PLAN {
            for _ in 0..self.draw.count(lo, hi) {
                self.place_at(object, site);
            }
        }
        for &(object, site) in FILLERS.iter().cycle().take(4 * FILLERS.len()) {
            if self.objects >= MIN_OBJECTS {
                break;
            }
            self.place_at(object, site);
        }
    }
}

/// Walls, floor and ceiling of the room [min, max]: instance ids 1 (floor),
/// 2 (ceiling), 3–6 (walls −x, +x, −y, +y) as in the fixed room.
fn structure(
    draw: &mut Draw,
    builder: &mut SceneBuilder,
    min: Point3<f64>,
    max: Point3<f64>,
) -> Room {
    let floor = builder.instance("floor");
    let ceiling = builder.instance("ceiling");
    let walls = [
        builder.instance("wall"),
        builder.instance("wall"),
        builder.instance("wall"),
        builder.instance("wall"),
    ];
    Room {
        min,
        max,
        faces: [
            (walls[0], draw.wall_material()),
            (walls[1], draw.wall_material()),
            (walls[2], draw.wall_material()),
            (walls[3], draw.wall_material()),
            (floor, draw.material()),
            (ceiling, draw.material()),
        ],
    }
}

/// Builds the furnished scene of room [min, max] seen along `views`.
fn furnished(
    mut draw: Draw,
    min: Point3<f64>,
    max: Point3<f64>,
    views: &Views,
    desk: Desk,
) -> Scene {
    let mut builder = SceneBuilder::default();
    let room = structure(&mut draw, &mut builder, min, max);
    let (floor_hits, wall_hits) = views.room_hits(&min, &max);
    let light = Point3::new(
        draw.range(min.x + 0.5, max.x - 0.5),
        draw.range(min.y + 0.5, max.y - 0.5),
        draw.range(max.z - 0.5, max.z - 0.15),
    );
    let (ambient, diffuse) = (draw.range(0.25, 0.45), draw.range(0.6, 0.9));
    let mut f = Furnisher {
        draw,
        min,
        max,
        views,
        builder,
        solids: Vec::new(),
        objects: 0,
        desk: None,
        floor_hits,
        wall_hits,
    };
    f.furnish(desk);
    Scene {
        room,
        parts: f.builder.parts,
        classes: f.builder.classes,
        light,
        ambient: ambient as f32,
        diffuse: diffuse as f32,
        area_sampling: true,
    }
}

// ---------------------------------------------------------------------------
// The two kinds of room.

/// A generated room around a recorded trajectory.
#[derive(Debug, Clone, PartialEq)]
pub struct FittedRoom {
    pub scene: Scene,
    /// Added to every camera centre of the trajectory to put it in the
    /// room (a pure translation: the mocap frame's z stays up).
    pub shift: Vector3<f64>,
}

/// Room of scene `seed` (≥ 1) fitted around all of `poses` (camera-to-world,
/// in their own z-up frame): the box of the camera centres grown by 1–2.2 m
/// per side, ceiling 2.4–3.2 m; the main table where the camera looks.
/// Deterministic for (seed, poses); no poses give an empty 5 × 4 m room.
pub fn room_around_trajectory(seed: u64, poses: &[Pose]) -> FittedRoom {
    if poses.is_empty() {
        return FittedRoom {
            scene: Scene::empty_room(Vector3::new(5.0, 4.0, 2.8)),
            shift: Vector3::zeros(),
        };
    }
    let mut draw = Draw::new(seed);
    let (lo, hi) = poses.iter().fold(
        (Point3::from([f64::MAX; 3]), Point3::from([f64::MIN; 3])),
        |(a, b), p| {
            let c = Point3::from(p.translation.vector);
            (a.inf(&c), b.sup(&c))
        },
    );
    // TUM mocap frames are z up with the floor near z = 0; other paths are
    // lifted so the camera is at hand height above the floor.
    let dz = if lo.z >= 0.3 && hi.z <= 2.6 {
        0.0
    } else {
        1.4 - (lo.z + hi.z) / 2.0
    };
    let margins = [
        draw.range(1.0, 2.2),
        draw.range(1.0, 2.2),
        draw.range(1.0, 2.2),
        draw.range(1.0, 2.2),
    ];
    let shift = Vector3::new(margins[0] - lo.x, margins[2] - lo.y, dz);
    let ceiling = draw.range(2.4, 3.2).max(hi.z + dz + 0.5);
    let min = Point3::origin();
    let max = Point3::new(
        hi.x - lo.x + margins[0] + margins[1],
        hi.y - lo.y + margins[2] + margins[3],
        ceiling,
    );
    let moved: Vec<Pose> = poses
        .iter()
        .map(|p| {
            let mut q = *p;
            q.translation.vector += shift;
            q
        })
        .collect();
    let views = Views::from_poses(&moved);
    let height = draw.range(DESK_HEIGHT.0, DESK_HEIGHT.1);
    let desk = desk_where_looked(&mut draw, &views, height, &min, &max);
    let scene = furnished(draw, min, max, &views, desk);
    FittedRoom { scene, shift }
}

/// The main table centred on the median of where the camera looks, turned
/// along the spread of those points and sized to cover most of them.
fn desk_where_looked(
    draw: &mut Draw,
    views: &Views,
    height: f64,
    min: &Point3<f64>,
    max: &Point3<f64>,
) -> Desk {
    let points = views.look_points(height);
    let centre = [
        median(points.iter().map(|p| p[0]).collect()),
        median(points.iter().map(|p| p[1]).collect()),
    ];
    // Principal axis of the looked-at points.
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for p in &points {
        let (x, y) = (p[0] - centre[0], p[1] - centre[1]);
        sxx += x * x;
        syy += y * y;
        sxy += x * y;
    }
    let yaw = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let (s, c) = yaw.sin_cos();
    let along: Vec<f64> = points
        .iter()
        .map(|p| c * (p[0] - centre[0]) + s * (p[1] - centre[1]))
        .collect();
    let across: Vec<f64> = points
        .iter()
        .map(|p| -s * (p[0] - centre[0]) + c * (p[1] - centre[1]))
        .collect();
    let spread = |v: &[f64]| quantile(v, 0.75) - quantile(v, 0.25);
    let width = (1.2 * spread(&along) + draw.range(0.2, 0.5)).clamp(DESK_WIDTH.0, DESK_WIDTH.1);
    let depth = (1.2 * spread(&across) + draw.range(0.1, 0.3)).clamp(DESK_DEPTH.0, DESK_DEPTH.1);
    // Keep the whole desk inside the room.
    let reach = 0.5 * width.hypot(depth) + 0.05;
    let clamp = |x: f64, lo: f64, hi: f64| {
        if lo + reach > hi - reach {
            (lo + hi) / 2.0
        } else {
            x.clamp(lo + reach, hi - reach)
        }
    };
    let origin = Point3::new(
        clamp(centre[0], min.x, max.x),
        clamp(centre[1], min.y, max.y),
        0.0,
    );
    Desk {
        frame: Frame::new(origin, yaw),
        width,
        depth,
        height,
    }
}

/// A generated room and the loop path around its table.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopRoom {
    pub scene: Scene,
    pub path: LoopPath,
}

/// Room of scene `seed` (≥ 1) for the generated loop: 4–7 × 3.5–6 m (larger
/// when the loop needs it), ceiling 2.4–3.2 m, the table near the middle
/// and the loop around it, 0.9–1.4 m from the walls.
pub fn room_with_loop(seed: u64) -> LoopRoom {
    let mut draw = Draw::new(seed);
    let (width, depth, height) = (
        draw.range(1.0, 1.4),
        draw.range(0.6, 0.9),
        draw.range(DESK_HEIGHT.0, DESK_HEIGHT.1),
    );
    let radius_x = width / 2.0 + draw.range(0.7, 1.1);
    let radius_y = depth / 2.0 + draw.range(0.6, 1.0);
    let wall_gap = draw.range(0.9, 1.4);
    let (need_x, need_y) = (radius_x + wall_gap, radius_y + wall_gap);
    let size_x = draw.range(4.0, 7.0).max(2.0 * need_x);
    let size_y = draw.range(3.5, 6.0).max(2.0 * need_y);
    let ceiling = draw.range(2.4, 3.2);
    let centre = Point3::new(
        (size_x / 2.0 + draw.range(-0.3, 0.3)).clamp(need_x, size_x - need_x),
        (size_y / 2.0 + draw.range(-0.3, 0.3)).clamp(need_y, size_y - need_y),
        0.0,
    );
    let path = LoopPath {
        centre,
        radius_x,
        radius_y,
        height: draw.range(1.3, 1.6),
        target: Point3::new(centre.x, centre.y, height + 0.05),
        ..LoopPath::default()
    };
    let desk = Desk {
        frame: Frame::new(centre, draw.range(-0.15, 0.15)),
        width,
        depth,
        height,
    };
    let (min, max) = (Point3::origin(), Point3::new(size_x, size_y, ceiling));
    let views = loop_views(&path);
    let scene = furnished(draw, min, max, &views, desk);
    LoopRoom { scene, path }
}

/// The loop's nominal ellipse (any jitter seed stays within the slack) and
/// the views of one loop.
fn loop_views(path: &LoopPath) -> Views {
    // Height swing of the loop plus the sum of its position wobbles (1 + 1/2 + 1/3).
    let wobble = path.jitter * (1.0 + 0.5 + 1.0 / 3.0) * 3f64.sqrt();
    let mut views = Views::from_poses(&path.poses(600, 30.0, 0));
    views.centres = (0..1440)
        .map(|i| {
            let a = TAU * i as f64 / 1440.0;
            Point3::new(
                path.centre.x + path.radius_x * a.cos(),
                path.centre.y + path.radius_y * a.sin(),
                path.height + 0.12 * (2.0 * a).sin(),
            )
        })
        .collect();
    // Ellipse samples are under 1 cm apart; the wobble moves any seed's path off them.
    views.slack = 0.01 + wobble;
    views
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn touching_is_not_overlapping() {
        let a = Solid::of(&block([0.0, 0.0, 0.5], [0.5, 0.5, 0.5], 0.0));
        let on_top = Solid::of(&block([0.1, 0.0, 1.2], [0.2, 0.2, 0.2], 0.7));
        let beside = Solid::of(&block([1.0, 0.0, 0.5], [0.5, 0.5, 0.5], 0.0));
        let inside = Solid::of(&block([0.4, 0.4, 0.5], [0.2, 0.2, 0.2], 0.7));
        assert!(!a.overlaps(&on_top) && !a.overlaps(&beside));
        assert!(a.overlaps(&inside) && inside.overlaps(&a));
        // Turned 45°, a unit box reaches 0.707 along x: it overlaps a box 1.2 away.
        let turned = Solid::of(&block([1.2, 0.0, 0.5], [0.5, 0.5, 0.5], PI / 4.0));
        assert!(a.overlaps(&turned));
        let far = Solid::of(&block([1.25, 0.0, 0.5], [0.5, 0.5, 0.5], PI / 4.0));
        assert!(!a.overlaps(&far));
    }

    #[test]
    fn quarter_turns_become_axis_aligned() {
        let f = Frame::new(Point3::new(1.0, 2.0, 0.0), FRAC_PI_2);
        let s = f.place(&block([1.0, 0.0, 0.5], [0.3, 0.1, 0.5], 0.0));
        let Shape::Cuboid {
            centre,
            half,
            yaw_cos_sin,
        } = s
        else {
            panic!("a box stays a box");
        };
        assert_eq!(yaw_cos_sin, [1.0, 0.0]);
        assert!((centre - Point3::new(1.0, 3.0, 0.5)).norm() < 1e-12);
        assert_eq!(half, Vector3::new(0.1, 0.3, 0.5));
    }

    #[test]
    fn colours_contrast() {
        let mut d = Draw::new(3);
        for _ in 0..200 {
            let a = d.colour();
            let b = d.contrasting(a);
            assert!((luminance(a) - luminance(b)).abs() >= 0.25);
        }
    }
}
