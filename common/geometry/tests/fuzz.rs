//! Property-based fuzz target (stable Rust, seeded RNG) for the PLY reader,
//! [`read_vertex_table`]: random bytes, header soup, and mutations of valid ascii, binary
//! little- and big-endian files (counts, property lists, formats, truncation, bytes).
//!
//! Properties: it never panics or hangs; a valid file reads back exactly; whatever it
//! accepts is a consistent table (`count × properties` values, required properties present,
//! no more vertices than the file has bytes).
//!
//! Quick size (20,000 inputs) in `cargo test`; full size:
//! `OPENGS_FUZZ_CASES=1000000 cargo test --release -p opengs-geometry --test fuzz -- --nocapture`.
//! A failure names its seed: `OPENGS_FUZZ_SEED=<seed> OPENGS_FUZZ_CASES=1` replays it.

use opengs_geometry::{read_vertex_table, PlyError, VertexTable};
use rand::Rng;

#[path = "../../../ipc_schema/tests/support/fuzz_driver.rs"]
mod fuzz_driver;
use fuzz_driver::{fuzz, pick, R};

// ---- A PLY model: elements, typed values, written as ascii or binary ----

const TYPES: [&str; 16] = [
    "char", "int8", "uchar", "uint8", "short", "int16", "ushort", "uint16", "int", "int32", "uint",
    "uint32", "float", "float32", "double", "float64",
];

#[derive(Clone, Copy, Debug)]
enum Val {
    I8(i8),
    U8(u8),
    I16(i16),
    U16(u16),
    I32(i32),
    U32(u32),
    F32(f32),
    F64(f64),
}

const F64_EDGES: [f64; 12] = [
    0.0,
    -0.0,
    1.0,
    -1.5,
    1e-3,
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::MIN_POSITIVE,
    1e-310,
    f64::MAX,
    f64::MIN,
];

impl Val {
    fn random(rng: &mut R, ty: &str) -> Val {
        let float = |rng: &mut R| match rng.gen_range(0..4) {
            0 => f64::from_bits(rng.gen()),
            1 => pick(rng, &F64_EDGES),
            _ => rng.gen_range(-100.0..100.0),
        };
        match ty {
            "char" | "int8" => Val::I8(rng.gen()),
            "uchar" | "uint8" => Val::U8(rng.gen()),
            "short" | "int16" => Val::I16(rng.gen()),
            "ushort" | "uint16" => Val::U16(rng.gen()),
            "int" | "int32" => Val::I32(rng.gen()),
            "uint" | "uint32" => Val::U32(rng.gen()),
            "float" | "float32" => Val::F32(float(rng) as f32),
            _ => Val::F64(float(rng)),
        }
    }

    /// A list length in the list's count type.
    fn count(ty: &str, n: u8) -> Val {
        match ty {
            "char" | "int8" => Val::I8(n as i8),
            "short" | "int16" => Val::I16(n as i16),
            "ushort" | "uint16" => Val::U16(n as u16),
            "int" | "int32" => Val::I32(n as i32),
            "uint" | "uint32" => Val::U32(n as u32),
            "float" | "float32" => Val::F32(n as f32),
            "double" | "float64" => Val::F64(n as f64),
            _ => Val::U8(n),
        }
    }

    fn text(self) -> String {
        match self {
            Val::I8(v) => v.to_string(),
            Val::U8(v) => v.to_string(),
            Val::I16(v) => v.to_string(),
            Val::U16(v) => v.to_string(),
            Val::I32(v) => v.to_string(),
            Val::U32(v) => v.to_string(),
            Val::F32(v) => v.to_string(),
            Val::F64(v) => v.to_string(),
        }
    }

    /// What the reader should return: the typed value, or the text as f64 in ascii files.
    fn expected(self, ascii: bool) -> f64 {
        if ascii {
            return self.text().parse().expect("Display of a number parses");
        }
        match self {
            Val::I8(v) => v as f64,
            Val::U8(v) => v as f64,
            Val::I16(v) => v as f64,
            Val::U16(v) => v as f64,
            Val::I32(v) => v as f64,
            Val::U32(v) => v as f64,
            Val::F32(v) => v as f64,
            Val::F64(v) => v,
        }
    }

    fn write(self, little: bool, out: &mut Vec<u8>) {
        macro_rules! put {
            ($v:expr) => {
                if little {
                    out.extend_from_slice(&$v.to_le_bytes())
                } else {
                    out.extend_from_slice(&$v.to_be_bytes())
                }
            };
        }
        match self {
            Val::I8(v) => put!(v),
            Val::U8(v) => put!(v),
            Val::I16(v) => put!(v),
            Val::U16(v) => put!(v),
            Val::I32(v) => put!(v),
            Val::U32(v) => put!(v),
            Val::F32(v) => put!(v),
            Val::F64(v) => put!(v),
        }
    }
}

struct Prop {
    name: String,
    ty: &'static str,
    /// Count type of a list property.
    list: Option<&'static str>,
}

struct Element {
    name: String,
    props: Vec<Prop>,
    /// Per row, per property, its values (one for scalars).
    rows: Vec<Vec<Vec<Val>>>,
}

#[derive(Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    Le,
    Be,
}

struct Ply {
    format: Format,
    elements: Vec<Element>,
    vertex: usize,
}

const NAMES: [&str; 12] = [
    "x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha", "label", "opacity",
];

impl Ply {
    fn random(rng: &mut R) -> Ply {
        let format = pick(rng, &[Format::Ascii, Format::Le, Format::Be]);
        let mut elements = Vec::new();
        let element = |rng: &mut R, name: &str, lists: bool, max_props: usize| {
            let props: Vec<Prop> = (0..rng.gen_range(0..=max_props))
                .map(|i| Prop {
                    name: if name == "vertex" && rng.gen_bool(0.8) {
                        NAMES[i % NAMES.len()].to_string()
                    } else {
                        format!("p{i}")
                    },
                    ty: pick(rng, &TYPES),
                    list: (lists && rng.gen_bool(0.5))
                        .then(|| pick(rng, &["uchar", "int", "uint16", "uint8"])),
                })
                .collect();
            let rows = (0..rng.gen_range(0..=if name == "vertex" { 12 } else { 4 }))
                .map(|_| {
                    props
                        .iter()
                        .map(|p| match p.list {
                            None => vec![Val::random(rng, p.ty)],
                            Some(cty) => {
                                let n = rng.gen_range(0..4u8);
                                std::iter::once(Val::count(cty, n))
                                    .chain((0..n).map(|_| Val::random(rng, p.ty)))
                                    .collect()
                            }
                        })
                        .collect()
                })
                .collect();
            Element {
                name: name.to_string(),
                props,
                rows,
            }
        };
        // Binary lists are only readable after the vertex element; ascii ones anywhere but in it.
        for i in 0..rng.gen_range(0..=2) {
            let lists = format == Format::Ascii;
            elements.push(element(rng, &format!("camera{i}"), lists, 3));
        }
        let vertex = elements.len();
        elements.push(element(rng, "vertex", false, 8));
        for name in ["face", "edge"].iter().take(rng.gen_range(0..=2)) {
            elements.push(element(rng, name, true, 3));
        }
        Ply {
            format,
            elements,
            vertex,
        }
    }

    fn header(&self, rng: &mut R) -> Vec<String> {
        let mut lines = vec!["ply".to_string()];
        let fmt = match self.format {
            Format::Ascii => "ascii",
            Format::Le => "binary_little_endian",
            Format::Be => "binary_big_endian",
        };
        lines.push(format!("format {fmt} 1.0"));
        if rng.gen_bool(0.3) {
            lines.push("comment made by the fuzzer".into());
        }
        for e in &self.elements {
            lines.push(format!("element {} {}", e.name, e.rows.len()));
            for p in &e.props {
                lines.push(match p.list {
                    None => format!("property {} {}", p.ty, p.name),
                    Some(c) => format!("property list {c} {} {}", p.ty, p.name),
                });
            }
        }
        if rng.gen_bool(0.1) {
            lines.push("obj_info x".into());
        }
        lines.push("end_header".into());
        lines
    }

    fn body(&self) -> Vec<u8> {
        let mut out = Vec::new();
        for e in &self.elements {
            for row in &e.rows {
                if self.format == Format::Ascii {
                    let toks: Vec<String> = row.iter().flatten().map(|v| v.text()).collect();
                    out.extend_from_slice(toks.join(" ").as_bytes());
                    out.push(b'\n');
                } else {
                    for v in row.iter().flatten() {
                        v.write(self.format == Format::Le, &mut out);
                    }
                }
            }
        }
        out
    }

    fn expected(&self) -> VertexTable {
        let v = &self.elements[self.vertex];
        let ascii = self.format == Format::Ascii;
        VertexTable {
            names: v.props.iter().map(|p| p.name.clone()).collect(),
            count: v.rows.len(),
            values: v
                .rows
                .iter()
                .flatten()
                .flatten()
                .map(|x| x.expected(ascii))
                .collect(),
        }
    }

    fn required<'a>(&'a self, rng: &mut R) -> Vec<&'a str> {
        self.elements[self.vertex]
            .props
            .iter()
            .filter(|_| rng.gen_bool(0.5))
            .map(|p| p.name.as_str())
            .collect()
    }
}

fn same(a: &VertexTable, b: &VertexTable) -> bool {
    a.names == b.names
        && a.count == b.count
        && a.values.len() == b.values.len()
        && a.values
            .iter()
            .zip(&b.values)
            .all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
}

// ---- Mutations ----

const COUNTS: [&str; 16] = [
    "0",
    "1",
    "2",
    "3",
    "13",
    "4000000000",
    "18446744073709551615",
    "18446744073709551616",
    "99999999999999999999999",
    "-1",
    "1e3",
    "0x10",
    "",
    "+4",
    "2 3",
    "９",
];

const WORDS: [&str; 24] = [
    "ply",
    "format ascii 1.0",
    "format binary_little_endian 1.0",
    "format binary_big_endian 1.0",
    "format binary_middle_endian 1.0",
    "format",
    "element vertex 3",
    "element face 1",
    "element",
    "element vertex",
    "property float x",
    "property list uchar int vertex_indices",
    "property list uchar",
    "property",
    "property float16 x",
    "property double",
    "end_header",
    "comment",
    "obj_info",
    "",
    "  ",
    "\r",
    "end_header extra",
    "ply ply",
];

fn junk_line(rng: &mut R) -> String {
    match rng.gen_range(0..4) {
        0 => {
            let n = rng.gen_range(0..12);
            (0..n).map(|_| rng.gen_range(' '..='~')).collect()
        }
        1 => format!(
            "element {} {}",
            pick(rng, &["vertex", "face", "v"]),
            pick(rng, &COUNTS)
        ),
        2 => format!(
            "property {} {}",
            pick(rng, &TYPES),
            pick(rng, &["x", "y", "z", "label", "x"])
        ),
        _ => pick(rng, &WORDS).to_string(),
    }
}

fn mutate_header(rng: &mut R, lines: &mut Vec<String>) {
    if lines.is_empty() {
        lines.push(junk_line(rng));
        return;
    }
    let i = rng.gen_range(0..lines.len());
    match rng.gen_range(0..9) {
        // An element count: beyond the data, below it, unparsable.
        0 | 1 => {
            let elements: Vec<usize> = (0..lines.len())
                .filter(|&j| lines[j].starts_with("element"))
                .collect();
            if let Some(&j) = elements.get(rng.gen_range(0..elements.len().max(1))) {
                let name = lines[j]
                    .split_whitespace()
                    .nth(1)
                    .unwrap_or("vertex")
                    .to_string();
                let count = if rng.gen_bool(0.3) {
                    let old: usize = lines[j]
                        .split_whitespace()
                        .nth(2)
                        .and_then(|c| c.parse().ok())
                        .unwrap_or(0);
                    (old as i64 + rng.gen_range(-2..=2)).to_string()
                } else {
                    pick(rng, &COUNTS).to_string()
                };
                lines[j] = format!("element {name} {count}");
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
        // A property's type: another scalar, a list, or no type at all.
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
                    1 => format!("property list uchar {} {name}", pick(rng, &TYPES)),
                    _ => format!("property {}", pick(rng, &["half", "", "list", "float"])),
                };
            }
        }
        6 => lines.insert(i, junk_line(rng)),
        7 => lines[i] = lines[i].to_uppercase(),
        _ => {
            let fmt = pick(
                rng,
                &["ascii", "binary_little_endian", "binary_big_endian", "x"],
            );
            if let Some(l) = lines.iter_mut().find(|l| l.starts_with("format")) {
                *l = format!("format {fmt} 1.0");
            }
        }
    }
}

fn mutate_bytes(rng: &mut R, data: &mut Vec<u8>, body: usize) {
    let len = data.len();
    // Most mutations land in the body; some anywhere.
    let at = |rng: &mut R| {
        if len > body && rng.gen_bool(0.7) {
            rng.gen_range(body..len)
        } else {
            rng.gen_range(0..len.max(1))
        }
    };
    match rng.gen_range(0..7) {
        0 => data.truncate(at(rng)),
        1 if len > 0 => {
            let i = at(rng).min(len - 1);
            data[i] ^= 1 << rng.gen_range(0..8);
        }
        2 if len > 0 => {
            let i = at(rng).min(len - 1);
            data[i] = pick(rng, &[b'\n', b'\r', b' ', 0, 0xff, b'-', b'.', b'e', b'#']);
        }
        3 => {
            let i = at(rng).min(len);
            let junk = pick(
                rng,
                &[
                    " 1", " nan", " inf", " -", " 1e999", " 0x1", "\n", "\n\n", " \u{e9}", "\u{0}",
                ],
            );
            data.splice(i..i, junk.bytes());
        }
        4 => {
            let extra = rng.gen_range(1..24);
            for _ in 0..extra {
                data.push(rng.gen());
            }
        }
        5 => data.extend_from_slice(b"1 2 3\n"),
        _ => {
            let i = at(rng).min(len);
            let n = rng.gen_range(0..16).min(len - i);
            data.drain(i..i + n);
        }
    }
}

/// The accepted table's invariants; returns whether it was accepted.
fn check(data: &[u8], required: &[&str], result: Result<VertexTable, PlyError>) -> bool {
    let t = match result {
        Ok(t) => t,
        Err(e) => {
            // Every error renders a message (naming what is wrong).
            assert!(!e.to_string().is_empty());
            return false;
        }
    };
    let n = t.names.len();
    assert_eq!(t.values.len(), t.count * n, "count × properties values");
    for name in required {
        assert!(t.column(name).is_some(), "required '{name}' missing");
    }
    if n > 0 {
        // Every vertex with properties takes at least one byte of the file.
        assert!(t.count <= data.len());
        assert_eq!(t.rows().count(), t.count);
        if t.count > 0 {
            assert_eq!(t.row(t.count - 1).len(), n);
        }
    }
    true
}

/// One input: random bytes, a header soup, or a valid PLY mutated 0–4 times.
fn ply_case(rng: &mut R) -> bool {
    match rng.gen_range(0..10) {
        0 => {
            let mut data = vec![0u8; rng.gen_range(0..200)];
            rng.fill(&mut data[..]);
            if rng.gen_bool(0.5) {
                data.splice(0..0, b"ply\n".iter().copied());
            }
            let r = read_vertex_table(&data, &[]);
            check(&data, &[], r)
        }
        1 => {
            let mut lines = vec!["ply".to_string()];
            for _ in 0..rng.gen_range(0..10) {
                lines.push(junk_line(rng));
            }
            lines.push("end_header".into());
            let mut data = (lines.join("\n") + "\n").into_bytes();
            let mut body = vec![0u8; rng.gen_range(0..64)];
            rng.fill(&mut body[..]);
            data.extend_from_slice(&body);
            let r = read_vertex_table(&data, &["x"]);
            check(&data, &["x"], r)
        }
        _ => {
            let ply = Ply::random(rng);
            let mut header = ply.header(rng);
            let mut body = ply.body();
            let required = ply.required(rng);
            let mutations = rng.gen_range(0..=4);
            let mut bytes_mutated = 0;
            for _ in 0..mutations {
                if rng.gen_bool(0.5) {
                    mutate_header(rng, &mut header);
                } else {
                    bytes_mutated += 1;
                }
            }
            let newline = if rng.gen_bool(0.1) { "\r\n" } else { "\n" };
            let mut data = (header.join(newline) + newline).into_bytes();
            let body_at = data.len();
            data.append(&mut body);
            for _ in 0..bytes_mutated {
                mutate_bytes(rng, &mut data, body_at);
            }
            let r = read_vertex_table(&data, &required);
            if mutations == 0 {
                match &r {
                    Ok(t) => assert!(same(t, &ply.expected()), "valid PLY read back wrong"),
                    Err(e) => panic!("valid PLY refused: {e}"),
                }
            }
            check(&data, &required, r)
        }
    }
}

#[test]
fn fuzz_read_vertex_table() {
    fuzz("read_vertex_table", ply_case);
}
