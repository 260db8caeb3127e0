//! Property-based fuzz target (stable Rust, seeded RNG) for the Gaussian map's PLY reader,
//! [`read_ply_counted`] / [`read_ply`]: random bytes, and mutations of valid 3DGS files
//! (ours from `write_ply`, and ascii / binary little- and big-endian ones with other scalar
//! types, extra properties and elements) in their counts, property lists and bytes.
//!
//! Properties: it never panics or hangs; an unmutated file gives exactly the Gaussians,
//! dropped count or refusal its values call for; every accepted map is finite, with unit
//! rotations and as many entries in each column.
//!
//! Quick size (20,000 inputs) in `cargo test`; full size:
//! `OPENGS_FUZZ_CASES=1000000 cargo test --release -p opengs-splat --test fuzz_ply -- --nocapture`.
//! A failure names its seed: `OPENGS_FUZZ_SEED=<seed> OPENGS_FUZZ_CASES=1` replays it.

use opengs_splat::{
    read_ply, read_ply_counted, write_ply, Gaussian, GaussianMap, PlyError, PlyMap,
};
use rand::Rng;

#[path = "../../../ipc_schema/tests/support/fuzz_driver.rs"]
mod fuzz_driver;
use fuzz_driver::{fuzz, pick, R};

const REQUIRED: [&str; 14] = [
    "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
    "rot_0", "rot_1", "rot_2", "rot_3",
];

const EXTRA: [&str; 6] = ["nx", "ny", "nz", "f_rest_0", "f_rest_1", "red"];

const TYPES: [&str; 8] = [
    "float", "double", "float32", "float64", "int", "uchar", "short", "uint",
];

/// A value of a PLY scalar type, kept as the f64 the reader returns for it.
fn value(rng: &mut R, ty: &str, name: &str) -> f64 {
    let float = match rng.gen_range(0..40) {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => -1e39, // finite as f64, infinite as f32
        3 => 0.0,
        4 => f64::from_bits(rng.gen()),
        5 => 1e-44,
        _ if name == "label" => rng.gen_range(0..1000) as f64,
        _ => rng.gen_range(-5.0..5.0),
    };
    match ty {
        "float" | "float32" => float as f32 as f64,
        "double" | "float64" => float,
        "int" => rng.gen::<i32>() as f64,
        "uchar" => rng.gen::<u8>() as f64,
        "short" => rng.gen::<i16>() as f64,
        _ => rng.gen::<u32>() as f64,
    }
}

fn write_value(ty: &str, v: f64, little: bool, out: &mut Vec<u8>) {
    macro_rules! put {
        ($x:expr) => {
            if little {
                out.extend_from_slice(&$x.to_le_bytes())
            } else {
                out.extend_from_slice(&$x.to_be_bytes())
            }
        };
    }
    match ty {
        "float" | "float32" => put!(v as f32),
        "double" | "float64" => put!(v),
        "int" => put!(v as i32),
        "uchar" => put!(v as u8),
        "short" => put!(v as i16),
        _ => put!(v as u32),
    }
}

/// What reading a generated file must give: (Gaussians, left out) or the vertex refused.
#[derive(Debug, PartialEq)]
enum Outcome {
    Read { kept: usize, non_finite: usize },
    Refused { vertex: usize },
}

/// A 3DGS vertex table with the reader's verdict on it, written as ascii or binary.
struct Gen {
    header: Vec<String>,
    body: Vec<u8>,
    outcome: Outcome,
}

fn generate(rng: &mut R) -> Gen {
    let mut props: Vec<(&str, &str)> = REQUIRED
        .iter()
        .map(|&n| {
            let ty = if rng.gen_bool(0.8) {
                "float"
            } else {
                pick(rng, &TYPES)
            };
            (n, ty)
        })
        .collect();
    for &n in EXTRA.iter().take(rng.gen_range(0..=EXTRA.len())) {
        props.push((n, pick(rng, &TYPES)));
    }
    if rng.gen_bool(0.6) {
        props.push((
            "label",
            pick(rng, &["uint", "float", "double", "int", "uchar"]),
        ));
    }
    // Any property order.
    for i in (1..props.len()).rev() {
        props.swap(i, rng.gen_range(0..=i));
    }
    let format = rng.gen_range(0..3);
    let fmt = ["ascii", "binary_little_endian", "binary_big_endian"][format];
    let count = rng.gen_range(0..10);
    let rows: Vec<Vec<f64>> = (0..count)
        .map(|_| {
            props
                .iter()
                .map(|&(name, ty)| value(rng, ty, name))
                .collect()
        })
        .collect();
    let faces = rng.gen_bool(0.2);
    let mut header = vec!["ply".to_string(), format!("format {fmt} 1.0")];
    header.push(format!("element vertex {count}"));
    for (name, ty) in &props {
        header.push(format!("property {ty} {name}"));
    }
    if faces {
        header.push("element face 1".into());
        header.push("property list uchar int vertex_indices".into());
    }
    header.push("end_header".into());
    let mut body = Vec::new();
    for row in &rows {
        if format == 0 {
            let toks: Vec<String> = row.iter().map(f64::to_string).collect();
            body.extend_from_slice(toks.join(" ").as_bytes());
            body.push(b'\n');
        } else {
            for (&(_, ty), &v) in props.iter().zip(row) {
                write_value(ty, v, format == 1, &mut body);
            }
        }
    }
    if faces {
        if format == 0 {
            body.extend_from_slice(b"3 0 1 2\n");
        } else {
            body.push(3);
            for i in 0..3i32 {
                write_value("int", i as f64, format == 1, &mut body);
            }
        }
    }
    // The reader's verdict, row by row: non-finite (as f32) rows are left out; then a label
    // that is not a u32 or a rotation without a norm refuses the file.
    let col = |name: &str| props.iter().position(|&(n, _)| n == name);
    let mut outcome = Outcome::Read {
        kept: 0,
        non_finite: 0,
    };
    for (v, row) in rows.iter().enumerate() {
        let Outcome::Read { kept, non_finite } = &mut outcome else {
            break;
        };
        if REQUIRED
            .iter()
            .any(|n| !(row[col(n).expect("required")] as f32).is_finite())
        {
            *non_finite += 1;
            continue;
        }
        let label_ok = col("label").is_none_or(|i| {
            let l = row[i];
            l >= 0.0 && l <= u32::MAX as f64 && l.fract() == 0.0
        });
        let n2: f64 = ["rot_0", "rot_1", "rot_2", "rot_3"]
            .iter()
            .map(|n| {
                let q = row[col(n).expect("rot")] as f32 as f64;
                q * q
            })
            .sum();
        let rotation_ok = n2.is_finite() && n2 > 0.0;
        if !(label_ok && rotation_ok) {
            outcome = Outcome::Refused { vertex: v };
            break;
        }
        *kept += 1;
    }
    Gen {
        header,
        body,
        outcome,
    }
}

/// A map from our writer: its round trip is bit-exact (rotations up to normalisation).
fn written_map(rng: &mut R) -> GaussianMap {
    let mut map = GaussianMap::new();
    for _ in 0..rng.gen_range(0..8) {
        let r: [f32; 4] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
        let n = r.iter().map(|q| q * q).sum::<f32>().sqrt().max(1e-3);
        map.push(Gaussian {
            mean: std::array::from_fn(|_| rng.gen_range(-10.0..10.0)),
            rotation: r.map(|q| q / n),
            log_scale: std::array::from_fn(|_| rng.gen_range(-8.0..1.0)),
            opacity_logit: rng.gen_range(-5.0..5.0),
            sh_dc: std::array::from_fn(|_| rng.gen_range(-2.0..2.0)),
            label: rng.gen(),
        });
    }
    map
}

fn same_map(a: &GaussianMap, b: &GaussianMap) -> bool {
    let bits = |m: &GaussianMap| -> Vec<u32> {
        (0..m.len())
            .flat_map(|i| {
                let g = m.get(i);
                g.mean
                    .into_iter()
                    .chain(g.log_scale)
                    .chain([g.opacity_logit])
                    .chain(g.sh_dc)
                    .map(f32::to_bits)
                    .chain([g.label])
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    let rot_close = (0..a.len().min(b.len())).all(|i| {
        let (p, q) = (a.get(i).rotation, b.get(i).rotation);
        let dot: f32 = p.iter().zip(&q).map(|(x, y)| x * y).sum();
        (dot.abs() - 1.0).abs() < 1e-5
    });
    a.len() == b.len() && bits(a) == bits(b) && rot_close
}

// ---- Mutations ----

const COUNTS: [&str; 10] = [
    "0",
    "1",
    "4000000000",
    "18446744073709551615",
    "18446744073709551616",
    "-1",
    "",
    "1e3",
    "2",
    "11",
];

fn mutate_header(rng: &mut R, lines: &mut Vec<String>) {
    if lines.is_empty() {
        return;
    }
    let i = rng.gen_range(0..lines.len());
    match rng.gen_range(0..7) {
        0 | 1 => {
            if let Some(l) = lines.iter_mut().find(|l| l.starts_with("element vertex")) {
                *l = format!("element vertex {}", pick(rng, &COUNTS));
            }
        }
        2 => {
            lines.remove(i);
        }
        3 => {
            let l = lines[i].clone();
            lines.insert(i, l);
        }
        4 => {
            let j = rng.gen_range(0..lines.len());
            lines.swap(i, j);
        }
        5 => {
            let props: Vec<usize> = (0..lines.len())
                .filter(|&j| lines[j].starts_with("property"))
                .collect();
            if let Some(&j) = props.get(rng.gen_range(0..props.len().max(1))) {
                let name = lines[j]
                    .split_whitespace()
                    .last()
                    .unwrap_or("x")
                    .to_string();
                lines[j] = match rng.gen_range(0..3) {
                    0 => format!("property {} {name}", pick(rng, &TYPES)),
                    1 => format!("property list uchar float {name}"),
                    _ => format!(
                        "property float {}",
                        pick(rng, &["label", "x", "rot_0", "q"])
                    ),
                };
            }
        }
        _ => {
            let fmt = pick(rng, &["ascii", "binary_little_endian", "binary_big_endian"]);
            lines[1] = format!("format {fmt} 1.0");
        }
    }
}

fn mutate_bytes(rng: &mut R, data: &mut Vec<u8>, body: usize) {
    let len = data.len();
    let at = |rng: &mut R| {
        if len > body && rng.gen_bool(0.8) {
            rng.gen_range(body..len)
        } else {
            rng.gen_range(0..len.max(1))
        }
    };
    match rng.gen_range(0..6) {
        0 => data.truncate(at(rng)),
        1 if len > 0 => {
            let i = at(rng).min(len - 1);
            data[i] ^= 1 << rng.gen_range(0..8);
        }
        2 if len >= 4 => {
            // A float's bits: NaN, infinity, zero, a denormal.
            let i = at(rng).min(len - 4);
            let v = pick(rng, &[f32::NAN, f32::INFINITY, 0.0, 1e-44, -1.0, 4e9]);
            data[i..i + 4].copy_from_slice(&v.to_le_bytes());
        }
        3 => {
            let i = at(rng).min(len);
            let junk = pick(
                rng,
                &[" 1", " nan", " -inf", "\n", " 1e39", " 0.5", "\n0 0 0"],
            );
            data.splice(i..i, junk.bytes());
        }
        4 => {
            for _ in 0..rng.gen_range(1..80) {
                data.push(rng.gen());
            }
        }
        _ => {
            let i = at(rng).min(len);
            let n = rng.gen_range(0..16).min(len - i);
            data.drain(i..i + n);
        }
    }
}

/// The accepted map's invariants; returns whether it was accepted.
fn check(data: &[u8], result: &Result<PlyMap, PlyError>) -> bool {
    let m = match result {
        Ok(m) => m,
        Err(e) => {
            assert!(!e.to_string().is_empty());
            return false;
        }
    };
    let map = &m.map;
    let n = map.len();
    assert_eq!(
        [
            map.rotations.len(),
            map.log_scales.len(),
            map.opacity_logits.len(),
            map.sh_dc.len(),
            map.labels.len()
        ],
        [n; 5]
    );
    // 14 properties take at least 14 bytes a vertex.
    assert!((n + m.non_finite) * 14 <= data.len());
    assert_eq!(m.first_non_finite.is_some(), m.non_finite > 0);
    assert_eq!(m.dropped_message().is_some(), m.non_finite > 0);
    for i in 0..n {
        let g = map.get(i);
        let mut values = g
            .mean
            .iter()
            .chain(&g.rotation)
            .chain(&g.log_scale)
            .chain(&g.sh_dc)
            .chain([&g.opacity_logit]);
        assert!(values.all(|v| v.is_finite()), "vertex {i}: {g:?}");
        let n2: f32 = g.rotation.iter().map(|q| q * q).sum();
        assert!(
            (n2 - 1.0).abs() < 1e-3,
            "vertex {i}: rotation {:?}",
            g.rotation
        );
    }
    true
}

/// One input: random bytes, our writer's file, or a generated 3DGS file; mutated 0–4 times.
fn ply_case(rng: &mut R) -> bool {
    let kind = rng.gen_range(0..10);
    if kind == 0 {
        let mut data = vec![0u8; rng.gen_range(0..300)];
        rng.fill(&mut data[..]);
        if rng.gen_bool(0.5) {
            data.splice(
                0..0,
                b"ply\nformat ascii 1.0\nelement vertex 1\n".iter().copied(),
            );
        }
        let r = read_ply_counted(&data);
        return check(&data, &r);
    }
    let (header, body, oracle) = if kind <= 3 {
        let map = written_map(rng);
        let mut data = Vec::new();
        write_ply(&map, &mut data).expect("write to memory");
        let at = data
            .windows(11)
            .position(|w| w == b"end_header\n")
            .expect("header end")
            + 11;
        let body = data.split_off(at);
        let text = String::from_utf8(data).expect("header text");
        let header: Vec<String> = text.lines().map(str::to_string).collect();
        (header, body, Err(map))
    } else {
        let g = generate(rng);
        (g.header, g.body, Ok(g.outcome))
    };
    let mut header = header;
    let mutations = rng.gen_range(0..=4);
    let mut byte_mutations = 0;
    for _ in 0..mutations {
        if rng.gen_bool(0.5) {
            mutate_header(rng, &mut header);
        } else {
            byte_mutations += 1;
        }
    }
    let mut data = (header.join("\n") + "\n").into_bytes();
    let body_at = data.len();
    data.extend_from_slice(&body);
    for _ in 0..byte_mutations {
        mutate_bytes(rng, &mut data, body_at);
    }
    let r = read_ply_counted(&data);
    if mutations == 0 {
        match (&oracle, &r) {
            (Err(map), Ok(read)) => {
                assert!(same_map(map, &read.map), "round trip of write_ply");
                assert_eq!(read.non_finite, 0);
            }
            (Ok(Outcome::Read { kept, non_finite }), Ok(read)) => {
                assert_eq!((read.map.len(), read.non_finite), (*kept, *non_finite));
            }
            (Ok(Outcome::Refused { vertex }), Err(PlyError::Invalid { vertex: v, .. })) => {
                assert_eq!(v, vertex);
            }
            (want, got) => panic!("valid PLY: wanted {want:?}, got {got:?}"),
        }
    }
    if rng.gen_bool(0.05) {
        // The plain reader is the counted one's map.
        let plain = read_ply(&data);
        assert_eq!(
            plain.as_ref().map(GaussianMap::len).ok(),
            r.as_ref().map(|m| m.map.len()).ok()
        );
    }
    check(&data, &r)
}

/// An ascii 3DGS PLY of one Gaussian with rotation `rot`.
fn one_gaussian(rot: &str) -> Vec<u8> {
    let mut text = String::from("ply\nformat ascii 1.0\nelement vertex 1\n");
    for name in REQUIRED {
        text += &format!("property float {name}\n");
    }
    text += &format!("end_header\n0 0 0 0 0 0 0 -4 -4 -4 {rot}\n");
    text.into_bytes()
}

/// Found by `fuzz_read_ply`: tiny rotations were normalised with an f32 norm that had lost its
/// bits (norm 1.0014 after it), huge ones refused for an overflowing one.
#[test]
fn rotations_of_tiny_or_huge_components_are_normalised() {
    for rot in [
        "0 0 -1e-21 -5.5e-23",
        "4.8e-20 3.4e-13 -2e-20 -1e-21",
        "1e20 0 0 1e20",
    ] {
        let map = read_ply(&one_gaussian(rot)).expect(rot);
        let q = map.rotations[0];
        let n2: f32 = q.iter().map(|v| v * v).sum();
        assert!((n2 - 1.0).abs() < 1e-6, "{rot}: {q:?}");
    }
    let e = read_ply(&one_gaussian("0 0 0 1e-46")).expect_err("zero as f32");
    assert!(e.to_string().contains("zero or non-finite norm"), "{e}");
}

#[test]
fn fuzz_read_ply() {
    fuzz("read_ply_counted", ply_case);
}
