//! Point clouds on disk: PLY (ascii, binary_little_endian; vertex x y z as
//! float or double, other properties ignored) and plain `x y z` text.

use nalgebra::Point3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A cloud file that could not be read or written; names the file and line.
#[derive(Debug, thiserror::Error)]
pub enum CloudIoError {
    // The I/O error is part of the message (not a `source`) so it prints once.
    #[error("{path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// Binary PLY data has no lines: the message names the vertex instead.
    #[error("{path}: {message}")]
    Binary { path: PathBuf, message: String },
}

fn binary_error(path: &Path, message: impl Into<String>) -> CloudIoError {
    CloudIoError::Binary {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn parse_error(path: &Path, line: usize, message: impl Into<String>) -> CloudIoError {
    CloudIoError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// Reads a `.ply` file as PLY and anything else as `x y z` text.
pub fn read_cloud(path: &Path) -> Result<Vec<Point3<f64>>, CloudIoError> {
    let bytes = std::fs::read(path).map_err(|error| CloudIoError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    let is_ply = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"))
        || bytes.starts_with(b"ply\n")
        || bytes.starts_with(b"ply\r\n");
    if is_ply {
        parse_ply(&bytes, path)
    } else {
        let text = std::str::from_utf8(&bytes)
            .map_err(|e| parse_error(path, 1, format!("not UTF-8 text: {e}")))?;
        parse_xyz(text, path)
    }
}

/// `x y z` per line; blank lines and `#` comments skipped; extra columns ignored.
pub fn parse_xyz(text: &str, path: &Path) -> Result<Vec<Point3<f64>>, CloudIoError> {
    let mut points = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let content = line.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let mut xyz = [0.0; 3];
        let mut fields = content
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|f| !f.is_empty());
        for (k, v) in xyz.iter_mut().enumerate() {
            let field = fields.next().ok_or_else(|| {
                parse_error(
                    path,
                    i + 1,
                    format!("expected 3 numbers (x y z), found {k}"),
                )
            })?;
            *v = field
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    parse_error(path, i + 1, format!("'{field}' is not a finite number"))
                })?;
        }
        points.push(Point3::from(xyz));
    }
    Ok(points)
}

/// Writes `x y z` text, one point per line.
pub fn write_xyz(path: &Path, points: &[Point3<f64>]) -> Result<(), CloudIoError> {
    let mut text = String::with_capacity(points.len() * 32);
    text.push_str("# x y z\n");
    for p in points {
        // Writing to a String cannot fail.
        let _ = writeln!(text, "{:.9} {:.9} {:.9}", p.x, p.y, p.z);
    }
    std::fs::write(path, text).map_err(|error| CloudIoError::Io {
        path: path.to_path_buf(),
        error,
    })
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Encoding {
    Ascii,
    BinaryLittleEndian,
}

/// One scalar property of an element: its byte size and, for x/y/z, which axis.
#[derive(Debug, Clone)]
struct Property {
    size: usize,
    kind: String,
    axis: Option<usize>,
    is_list: bool,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

fn scalar_size(kind: &str) -> Option<usize> {
    Some(match kind {
        "char" | "uchar" | "int8" | "uint8" => 1,
        "short" | "ushort" | "int16" | "uint16" => 2,
        "int" | "uint" | "float" | "int32" | "uint32" | "float32" => 4,
        "double" | "float64" => 8,
        _ => return None,
    })
}

/// Parses a whole PLY file; only the `vertex` element's x, y, z are kept.
pub fn parse_ply(bytes: &[u8], path: &Path) -> Result<Vec<Point3<f64>>, CloudIoError> {
    // Header: text lines up to `end_header`.
    let mut offset = 0;
    let mut line_no = 0;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let rest = &bytes[offset..];
        let Some(end) = rest.iter().position(|&b| b == b'\n') else {
            return Err(parse_error(
                path,
                line_no + 1,
                "header has no end_header line",
            ));
        };
        line_no += 1;
        let line = String::from_utf8_lossy(&rest[..end]).trim().to_string();
        offset += end + 1;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["ply"] if line_no == 1 => {}
            _ if line_no == 1 => {
                return Err(parse_error(
                    path,
                    1,
                    "not a PLY file (first line is not 'ply')",
                ))
            }
            ["format", "ascii", _] => encoding = Some(Encoding::Ascii),
            ["format", "binary_little_endian", _] => encoding = Some(Encoding::BinaryLittleEndian),
            ["format", other, ..] => {
                return Err(parse_error(
                    path,
                    line_no,
                    format!("unsupported PLY format '{other}'"),
                ))
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            ["element", name, count] => {
                let count = count.parse().map_err(|_| {
                    parse_error(path, line_no, format!("bad element count '{count}'"))
                })?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", "list", _, _, _name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| parse_error(path, line_no, "property before any element"))?;
                element.properties.push(Property {
                    size: 0,
                    kind: "list".into(),
                    axis: None,
                    is_list: true,
                });
            }
            ["property", kind, name] => {
                let size = scalar_size(kind).ok_or_else(|| {
                    parse_error(path, line_no, format!("unknown property type '{kind}'"))
                })?;
                let element = elements
                    .last_mut()
                    .ok_or_else(|| parse_error(path, line_no, "property before any element"))?;
                let axis = match *name {
                    "x" => Some(0),
                    "y" => Some(1),
                    "z" => Some(2),
                    _ => None,
                };
                element.properties.push(Property {
                    size,
                    kind: kind.to_string(),
                    axis,
                    is_list: false,
                });
            }
            ["end_header"] => break,
            _ => {
                return Err(parse_error(
                    path,
                    line_no,
                    format!("unexpected header line '{line}'"),
                ))
            }
        }
    }
    let encoding =
        encoding.ok_or_else(|| parse_error(path, line_no, "header has no format line"))?;
    let vertex_index = elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| parse_error(path, line_no, "no 'vertex' element"))?;
    let vertex = &elements[vertex_index];
    for axis in 0..3 {
        let p = vertex.properties.iter().find(|p| p.axis == Some(axis));
        match p {
            Some(p)
                if p.kind == "float"
                    || p.kind == "float32"
                    || p.kind == "double"
                    || p.kind == "float64" => {}
            Some(p) => {
                return Err(parse_error(
                    path,
                    line_no,
                    format!(
                        "vertex {} is '{}', expected float or double",
                        ["x", "y", "z"][axis],
                        p.kind
                    ),
                ))
            }
            None => {
                return Err(parse_error(
                    path,
                    line_no,
                    format!("vertex has no '{}' property", ["x", "y", "z"][axis]),
                ))
            }
        }
    }
    match encoding {
        Encoding::Ascii => {
            parse_ply_ascii(&bytes[offset..], line_no, &elements, vertex_index, path)
        }
        Encoding::BinaryLittleEndian => {
            parse_ply_binary(&bytes[offset..], &elements, vertex_index, path)
        }
    }
}

fn parse_ply_ascii(
    body: &[u8],
    header_lines: usize,
    elements: &[Element],
    vertex_index: usize,
    path: &Path,
) -> Result<Vec<Point3<f64>>, CloudIoError> {
    let text = std::str::from_utf8(body)
        .map_err(|e| parse_error(path, header_lines + 1, format!("not UTF-8 text: {e}")))?;
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (header_lines + i + 1, l));
    // Elements before the vertices take one line per item.
    let skip: usize = elements[..vertex_index].iter().map(|e| e.count).sum();
    for _ in 0..skip {
        lines.next();
    }
    let vertex = &elements[vertex_index];
    let mut points = Vec::with_capacity(vertex.count);
    for k in 0..vertex.count {
        let (line_no, line) = lines.next().ok_or_else(|| {
            parse_error(
                path,
                header_lines + skip + k + 1,
                format!("file ends after {k} of {} vertices", vertex.count),
            )
        })?;
        let fields: Vec<&str> = line.split_whitespace().collect();
        let mut xyz = [0.0; 3];
        for (i, p) in vertex.properties.iter().enumerate() {
            if p.is_list {
                return Err(parse_error(
                    path,
                    line_no,
                    "list properties on vertices are not supported",
                ));
            }
            let Some(axis) = p.axis else { continue };
            let field = fields.get(i).ok_or_else(|| {
                parse_error(
                    path,
                    line_no,
                    format!(
                        "expected {} values, found {}",
                        vertex.properties.len(),
                        fields.len()
                    ),
                )
            })?;
            xyz[axis] = field
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    parse_error(path, line_no, format!("'{field}' is not a finite number"))
                })?;
        }
        points.push(Point3::from(xyz));
    }
    Ok(points)
}

fn parse_ply_binary(
    body: &[u8],
    elements: &[Element],
    vertex_index: usize,
    path: &Path,
) -> Result<Vec<Point3<f64>>, CloudIoError> {
    let mut offset = 0;
    for e in &elements[..vertex_index] {
        if e.properties.iter().any(|p| p.is_list) {
            return Err(binary_error(path, format!("binary element '{e}' with list properties before the vertices is not supported", e = e.name)));
        }
        offset += e.count * e.properties.iter().map(|p| p.size).sum::<usize>();
    }
    let vertex = &elements[vertex_index];
    if vertex.properties.iter().any(|p| p.is_list) {
        return Err(binary_error(
            path,
            "list properties on vertices are not supported",
        ));
    }
    let stride: usize = vertex.properties.iter().map(|p| p.size).sum();
    let mut points = Vec::with_capacity(vertex.count);
    for k in 0..vertex.count {
        let start = offset + k * stride;
        let record = body.get(start..start + stride).ok_or_else(|| {
            binary_error(
                path,
                format!("binary data ends inside vertex {k} of {}", vertex.count),
            )
        })?;
        let mut xyz = [0.0; 3];
        let mut at = 0;
        for p in &vertex.properties {
            if let Some(axis) = p.axis {
                let raw = &record[at..at + p.size];
                xyz[axis] = match raw {
                    [a, b, c, d] => f32::from_le_bytes([*a, *b, *c, *d]) as f64,
                    [a, b, c, d, e, f, g, h] => {
                        f64::from_le_bytes([*a, *b, *c, *d, *e, *f, *g, *h])
                    }
                    _ => unreachable!("x, y, z checked to be float or double"),
                };
                if !xyz[axis].is_finite() {
                    return Err(binary_error(
                        path,
                        format!("vertex {k} has a non-finite coordinate"),
                    ));
                }
            }
            at += p.size;
        }
        points.push(Point3::from(xyz));
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("cloud.xyz")
    }

    #[test]
    fn xyz_text_with_comments() {
        let pts = parse_xyz("# header\n1 2 3\n\n4 5 6 # trailing\n", p()).expect("valid");
        assert_eq!(
            pts,
            vec![Point3::new(1.0, 2.0, 3.0), Point3::new(4.0, 5.0, 6.0)]
        );
    }

    #[test]
    fn xyz_errors_name_file_and_line() {
        let e = parse_xyz("1 2 3\n4 five 6\n", p())
            .expect_err("bad number")
            .to_string();
        assert_eq!(e, "cloud.xyz:2: 'five' is not a finite number");
        let e = parse_xyz("1 2 3\n\n4 5\n", p())
            .expect_err("short line")
            .to_string();
        assert_eq!(e, "cloud.xyz:3: expected 3 numbers (x y z), found 2");
    }

    #[test]
    fn ascii_ply_ignores_other_properties() {
        let text = "ply\nformat ascii 1.0\ncomment test\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n1 2 3 255\n4 5 6 0\n";
        let pts = parse_ply(text.as_bytes(), Path::new("a.ply")).expect("valid");
        assert_eq!(
            pts,
            vec![Point3::new(1.0, 2.0, 3.0), Point3::new(4.0, 5.0, 6.0)]
        );
    }

    #[test]
    fn ascii_ply_error_names_the_line() {
        let text = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 x 6\n";
        let e = parse_ply(text.as_bytes(), Path::new("a.ply"))
            .expect_err("bad")
            .to_string();
        assert_eq!(e, "a.ply:9: 'x' is not a finite number");
        let e = parse_ply(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty blob x\n",
            Path::new("a.ply"),
        )
        .expect_err("bad type")
        .to_string();
        assert_eq!(e, "a.ply:4: unknown property type 'blob'");
    }

    #[test]
    fn binary_ply_mixed_float_and_double() {
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty double x\nproperty float y\nproperty uchar flag\nproperty double z\nend_header\n".to_vec();
        for (x, y, z) in [(1.0f64, 2.0f32, 3.0f64), (-4.5, 0.25, 1e3)] {
            bytes.extend(x.to_le_bytes());
            bytes.extend(y.to_le_bytes());
            bytes.push(7);
            bytes.extend(z.to_le_bytes());
        }
        let pts = parse_ply(&bytes, Path::new("b.ply")).expect("valid");
        assert_eq!(
            pts,
            vec![Point3::new(1.0, 2.0, 3.0), Point3::new(-4.5, 0.25, 1e3)]
        );
        let e = parse_ply(&bytes[..bytes.len() - 3], Path::new("b.ply"))
            .expect_err("truncated")
            .to_string();
        assert!(e.contains("vertex 1 of 2"), "{e}");
    }

    #[test]
    fn xyz_round_trip_through_a_file() {
        let dir = std::env::temp_dir().join(format!("opengs-gicp-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("c.xyz");
        let pts = vec![Point3::new(0.1, -2.0, 3.5)];
        write_xyz(&path, &pts).expect("write");
        assert_eq!(read_cloud(&path).expect("read"), pts);
        let missing = read_cloud(&dir.join("missing.ply"))
            .expect_err("missing")
            .to_string();
        assert!(missing.contains("missing.ply"), "{missing}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
