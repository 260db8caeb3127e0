//! The embedded indoor room: walls, floor, ceiling and a dozen furnished
//! objects at several depths so tracking is constrained in all 6 DoF.

use nalgebra::{Point3, Vector3};

use super::shape::Shape;
use super::texture::Texture;
use crate::InstanceClass;

/// One primitive belonging to an instance (an object may have many parts).
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    pub shape: Shape,
    pub texture: Texture,
    pub instance: u16,
}

/// Axis-aligned room seen from inside; faces ordered −x, +x, −y, +y, −z, +z.
#[derive(Debug, Clone, PartialEq)]
pub struct Room {
    pub min: Point3<f64>,
    pub max: Point3<f64>,
    pub faces: [(u16, Texture); 6],
}

#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    pub room: Room,
    pub parts: Vec<Part>,
    pub classes: Vec<InstanceClass>,
    /// Point light position (world, metres).
    pub light: Point3<f64>,
    pub ambient: f32,
    pub diffuse: f32,
    /// A pixel's colour is the texture averaged over the pixel's footprint, as a sensor
    /// integrates light over its area (`raycast::pixel_albedo`); otherwise the texture at
    /// the pixel centre. Off for scene 0, so the reference room renders as it always has
    /// and its live 30 Hz sensor stays cheap; on for the scene suite.
    pub area_sampling: bool,
}

/// Classes of the room's own faces (ids 1–6); every other instance is an object.
pub const STRUCTURAL_CLASSES: [&str; 3] = ["floor", "ceiling", "wall"];

impl Scene {
    /// Instances that are not walls, floor or ceiling.
    pub fn object_count(&self) -> usize {
        self.classes
            .iter()
            .filter(|c| !STRUCTURAL_CLASSES.contains(&c.class.as_str()))
            .count()
    }

    /// Room size (metres along x, y, z).
    pub fn room_size(&self) -> Vector3<f64> {
        self.room.max - self.room.min
    }

    /// Empty room with the given size and uniform walls (used by tests).
    pub fn empty_room(size: Vector3<f64>) -> Self {
        let wall = Texture::Solid([0.6, 0.6, 0.6]);
        Scene {
            room: Room {
                min: Point3::origin(),
                max: Point3::from(size),
                faces: [
                    (3, wall),
                    (4, wall),
                    (5, wall),
                    (6, wall),
                    (1, wall),
                    (2, wall),
                ],
            },
            parts: Vec::new(),
            area_sampling: false,
            classes: Vec::new(),
            light: Point3::new(size.x / 2.0, size.y / 2.0, size.z - 0.2),
            ambient: 0.35,
            diffuse: 0.75,
        }
    }
}

const fn rgb(r: u8, g: u8, b: u8) -> [f32; 3] {
    [r as f32 / 255.0, g as f32 / 255.0, b as f32 / 255.0]
}

fn p(x: f64, y: f64, z: f64) -> Point3<f64> {
    Point3::new(x, y, z)
}

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

fn cuboid(centre: Point3<f64>, half: Vector3<f64>, yaw: f64) -> Shape {
    Shape::cuboid(centre, half, yaw)
}

/// Builder that hands out instance ids in order and records class names.
#[derive(Debug, Default)]
pub(crate) struct SceneBuilder {
    pub(crate) parts: Vec<Part>,
    pub(crate) classes: Vec<InstanceClass>,
}

impl SceneBuilder {
    pub(crate) fn instance(&mut self, class: &str) -> u16 {
        let id = self.classes.len() as u16 + 1;
        self.classes.push(InstanceClass {
            id,
            class: class.to_string(),
        });
        id
    }

    fn object(&mut self, class: &str, texture: Texture, shapes: &[Shape]) -> u16 {
        let id = self.instance(class);
        self.add(id, texture, shapes);
        id
    }

    pub(crate) fn add(&mut self, instance: u16, texture: Texture, shapes: &[Shape]) {
        self.parts.extend(shapes.iter().map(|&shape| Part {
            shape,
            texture,
            instance,
        }));
    }
}

/// The default synthetic room, 5 × 4 × 2.8 m, z up, origin at a floor corner.
pub fn indoor_room() -> Scene {
    let mut b = SceneBuilder {
        parts: Vec::new(),
        classes: Vec::new(),
    };
    let floor = b.instance("floor");
    let ceiling = b.instance("ceiling");
    let walls = [
        b.instance("wall"),
        b.instance("wall"),
        b.instance("wall"),
        b.instance("wall"),
    ];
    let room = Room {
        min: p(0.0, 0.0, 0.0),
        max: p(5.0, 4.0, 2.8),
        faces: [
            (
                walls[0],
                Texture::Bricks {
                    columns_per_m: 4.0,
                    rows_per_m: 12.5,
                    brick: rgb(170, 80, 60),
                    mortar: rgb(210, 205, 195),
                },
            ),
            (
                walls[1],
                Texture::Stripes {
                    axis: [0.0, 1.0, 0.6],
                    frequency: 3.3,
                    a: rgb(200, 190, 150),
                    b: rgb(120, 140, 170),
                },
            ),
            (
                walls[2],
                Texture::Noise {
                    scale: 4.0,
                    a: rgb(90, 150, 110),
                    b: rgb(220, 230, 200),
                },
            ),
            (
                walls[3],
                Texture::Checker {
                    frequency: 3.0,
                    a: rgb(230, 225, 210),
                    b: rgb(150, 110, 140),
                },
            ),
            (
                floor,
                Texture::Wood {
                    centre: [-3.0, -7.0],
                    rings: 22.0,
                    a: rgb(160, 110, 60),
                    b: rgb(95, 60, 30),
                },
            ),
            (
                ceiling,
                Texture::Noise {
                    scale: 2.5,
                    a: rgb(235, 235, 230),
                    b: rgb(175, 180, 190),
                },
            ),
        ],
    };

    // Table: top and four legs, one instance.
    let oak = Texture::Wood {
        centre: [1.1, -0.4],
        rings: 33.3,
        a: rgb(190, 140, 85),
        b: rgb(120, 75, 40),
    };
    let mut table = vec![cuboid(p(2.5, 2.0, 0.74), v(0.6, 0.4, 0.03), 0.0)];
    for (sx, sy) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
        table.push(cuboid(
            p(2.5 + sx * 0.54, 2.0 + sy * 0.34, 0.355),
            v(0.03, 0.03, 0.355),
            0.0,
        ));
    }
    b.object("table", oak, &table);
    b.object(
        "box",
        Texture::Checker {
            frequency: 16.0,
            a: rgb(230, 200, 40),
            b: rgb(40, 60, 160),
        },
        &[cuboid(p(2.3, 1.9, 0.87), v(0.15, 0.12, 0.1), 0.3)],
    );
    b.object(
        "ball",
        Texture::Stripes {
            axis: [0.3, 0.2, 1.0],
            frequency: 25.0,
            a: rgb(220, 40, 40),
            b: rgb(250, 250, 250),
        },
        &[Shape::Sphere {
            centre: p(2.85, 2.15, 0.85),
            radius: 0.08,
        }],
    );
    b.object(
        "ball",
        Texture::Checker {
            frequency: 8.0,
            a: rgb(40, 170, 80),
            b: rgb(240, 240, 240),
        },
        &[Shape::Sphere {
            centre: p(1.5, 3.3, 0.25),
            radius: 0.25,
        }],
    );
    // A stack of two cardboard-like boxes in a corner.
    let cardboard = Texture::Noise {
        scale: 12.0,
        a: rgb(200, 160, 110),
        b: rgb(150, 110, 70),
    };
    b.object(
        "box",
        cardboard,
        &[cuboid(p(4.3, 0.45, 0.2), v(0.25, 0.25, 0.2), 0.15)],
    );
    b.object(
        "box",
        Texture::Stripes {
            axis: [1.0, 0.0, 0.0],
            frequency: 14.0,
            a: rgb(60, 120, 200),
            b: rgb(240, 240, 240),
        },
        &[cuboid(p(4.28, 0.47, 0.55), v(0.18, 0.16, 0.15), 0.55)],
    );
    b.object(
        "bin",
        Texture::Stripes {
            axis: [0.0, 0.0, 1.0],
            frequency: 17.0,
            a: rgb(80, 80, 90),
            b: rgb(200, 200, 60),
        },
        &[Shape::Cylinder {
            base: p(0.5, 3.4, 0.0),
            radius: 0.18,
            height: 0.45,
        }],
    );
    // Bookshelf against the +x wall: two sides, back, four boards.
    let shelf_wood = Texture::Wood {
        centre: [7.0, 3.0],
        rings: 50.0,
        a: rgb(110, 70, 45),
        b: rgb(70, 40, 25),
    };
    let mut shelf = vec![
        cuboid(p(4.82, 1.42, 0.95), v(0.17, 0.02, 0.95), 0.0),
        cuboid(p(4.82, 2.58, 0.95), v(0.17, 0.02, 0.95), 0.0),
        cuboid(p(4.98, 2.0, 0.95), v(0.015, 0.56, 0.95), 0.0),
    ];
    for z in [0.05, 0.65, 1.25, 1.88] {
        shelf.push(cuboid(p(4.82, 2.0, z), v(0.17, 0.56, 0.02), 0.0));
    }
    b.object("bookshelf", shelf_wood, &shelf);
    let books = b.instance("books");
    let book_colours = [
        rgb(180, 30, 30),
        rgb(30, 90, 170),
        rgb(230, 200, 60),
        rgb(40, 140, 70),
        rgb(120, 50, 140),
        rgb(220, 120, 40),
    ];
    for (i, c) in book_colours.iter().enumerate() {
        let y = 1.55 + i as f64 * 0.075;
        let h = 0.2 + 0.03 * (i % 3) as f64;
        b.add(
            books,
            Texture::Stripes {
                axis: [0.0, 0.0, 1.0],
                frequency: 11.0,
                a: *c,
                b: [c[0] * 0.6, c[1] * 0.6, c[2] * 0.6],
            },
            &[cuboid(
                p(4.84, y, 0.67 + h / 2.0),
                v(0.11, 0.03, h / 2.0),
                0.0,
            )],
        );
    }
    // Chair: seat, back, four legs.
    let mut chair = vec![
        cuboid(p(2.5, 2.78, 0.45), v(0.2, 0.2, 0.025), 0.0),
        cuboid(p(2.5, 2.96, 0.72), v(0.2, 0.02, 0.25), 0.0),
    ];
    for (sx, sy) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
        chair.push(cuboid(
            p(2.5 + sx * 0.17, 2.78 + sy * 0.17, 0.21),
            v(0.02, 0.02, 0.21),
            0.0,
        ));
    }
    b.object(
        "chair",
        Texture::Noise {
            scale: 20.0,
            a: rgb(50, 50, 60),
            b: rgb(110, 120, 140),
        },
        &chair,
    );
    // Floor lamp in a corner: base, pole, shade.
    let lamp = b.object(
        "lamp",
        Texture::Solid(rgb(60, 60, 60)),
        &[
            Shape::Cylinder {
                base: p(0.35, 0.35, 0.0),
                radius: 0.15,
                height: 0.03,
            },
            Shape::Cylinder {
                base: p(0.35, 0.35, 0.03),
                radius: 0.02,
                height: 1.5,
            },
        ],
    );
    b.add(
        lamp,
        Texture::Stripes {
            axis: [0.0, 0.0, 1.0],
            frequency: 20.0,
            a: rgb(250, 240, 200),
            b: rgb(230, 200, 150),
        },
        &[Shape::Ellipsoid {
            centre: p(0.35, 0.35, 1.6),
            radii: v(0.2, 0.2, 0.14),
        }],
    );
    b.object(
        "cabinet",
        Texture::Checker {
            frequency: 10.0,
            a: rgb(240, 240, 235),
            b: rgb(200, 60, 50),
        },
        &[cuboid(p(3.6, 3.75, 0.5), v(0.45, 0.25, 0.5), 0.0)],
    );
    b.object(
        "vase",
        Texture::Stripes {
            axis: [0.0, 0.0, 1.0],
            frequency: 33.3,
            a: rgb(40, 120, 160),
            b: rgb(230, 230, 250),
        },
        &[Shape::Ellipsoid {
            centre: p(3.45, 3.75, 1.15),
            radii: v(0.08, 0.08, 0.15),
        }],
    );
    b.object(
        "sofa",
        Texture::Noise {
            scale: 9.0,
            a: rgb(120, 40, 50),
            b: rgb(190, 90, 90),
        },
        &[
            cuboid(p(0.45, 2.0, 0.22), v(0.4, 0.8, 0.22), 0.0),
            cuboid(p(0.12, 2.0, 0.6), v(0.1, 0.8, 0.35), 0.0),
        ],
    );
    b.object(
        "picture",
        Texture::Checker {
            frequency: 20.0,
            a: rgb(20, 20, 20),
            b: rgb(240, 180, 40),
        },
        &[cuboid(p(2.5, 0.02, 1.6), v(0.4, 0.02, 0.3), 0.0)],
    );
    let plant = b.object(
        "plant",
        Texture::Stripes {
            axis: [0.0, 0.0, 1.0],
            frequency: 20.0,
            a: rgb(170, 90, 50),
            b: rgb(130, 60, 35),
        },
        &[Shape::Cylinder {
            base: p(4.5, 3.5, 0.0),
            radius: 0.18,
            height: 0.4,
        }],
    );
    b.add(
        plant,
        Texture::Noise {
            scale: 15.0,
            a: rgb(30, 110, 40),
            b: rgb(120, 200, 80),
        },
        &[Shape::Ellipsoid {
            centre: p(4.5, 3.5, 0.78),
            radii: v(0.28, 0.28, 0.38),
        }],
    );

    Scene {
        room,
        parts: b.parts,
        classes: b.classes,
        light: p(2.3, 1.8, 2.6),
        ambient: 0.35,
        diffuse: 0.75,
        area_sampling: false,
    }
}
