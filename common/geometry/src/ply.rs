//! The vertex table of a PLY file (ascii, binary little- or big-endian; every scalar type;
//! other elements skipped): the one PLY reader of the workspace, under the Gaussian map
//! (`opengs-splat`) and the point clouds of registration (`opengs-gicp`).
//!
//! Hand-written: the layout is a flat table, and ply-rs (unmaintained) reports errors
//! without saying which element, property or line is wrong.

#[derive(Debug, thiserror::Error)]
pub enum PlyError {
    #[error("cannot access {path}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("PLY header line {line}: {msg}")]
    Header { line: usize, msg: String },
    #[error("PLY has no 'vertex' element")]
    NoVertexElement,
    #[error("PLY vertex element lacks required property '{0}'")]
    MissingProperty(String),
    #[error(
        "PLY data truncated: file ends inside vertex {vertex} of {count} (property '{property}')"
    )]
    Truncated {
        vertex: usize,
        count: usize,
        property: String,
    },
    #[error("PLY line {line}: {msg}")]
    Ascii { line: usize, msg: String },
    #[error("PLY vertex {vertex}: {msg}")]
    Invalid { vertex: usize, msg: String },
    #[error("PLY: {0}")]
    Unsupported(String),
    #[error(
        "PLY header declares {count} '{element}' entries, but the {bytes} bytes of data after \
         the header hold at most {fits}"
    )]
    CountExceedsFile {
        element: String,
        count: usize,
        bytes: usize,
        fits: usize,
    },
    #[error("PLY: {0}")]
    TooLarge(String),
    #[error("PLY has data beyond its header's counts: {0}")]
    ExtraData(String),
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn read(self, b: &[u8], little: bool) -> f64 {
        macro_rules! rd {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().expect("slice length checked");
                (if little {
                    <$t>::from_le_bytes(a)
                } else {
                    <$t>::from_be_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => rd!(i16, 2),
            Scalar::U16 => rd!(u16, 2),
            Scalar::I32 => rd!(i32, 4),
            Scalar::U32 => rd!(u32, 4),
            Scalar::F32 => rd!(f32, 4),
            Scalar::F64 => rd!(f64, 8),
        }
    }
}

#[derive(Debug)]
struct Property {
    name: String,
    /// `None` for list properties (only allowed in elements we skip in ASCII files).
    kind: Option<Scalar>,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

#[derive(Debug, PartialEq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Byte offset of the body and the number of header lines.
    body: usize,
    lines: usize,
}

fn parse_header(data: &[u8]) -> Result<Header, PlyError> {
    let mut pos = 0;
    let mut line_no = 0;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        line_no += 1;
        let err = |msg: String| PlyError::Header { line: line_no, msg };
        let Some(nl) = data[pos..].iter().position(|&c| c == b'\n') else {
            return Err(err("header ends before 'end_header'".into()));
        };
        let line = std::str::from_utf8(&data[pos..pos + nl])
            .map_err(|_| err("header line is not text".into()))?
            .trim_end_matches('\r');
        pos += nl + 1;
        let words: Vec<&str> = line.split_whitespace().collect();
        if line_no == 1 {
            if line != "ply" {
                return Err(err(format!("expected 'ply' magic, found '{line}'")));
            }
            continue;
        }
        match words.first().copied() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                format = Some(match words.get(1).copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::BinaryLe,
                    Some("binary_big_endian") => Format::BinaryBe,
                    other => return Err(err(format!("unknown format {other:?}"))),
                });
            }
            Some("element") => {
                let (Some(name), Some(count)) = (words.get(1), words.get(2)) else {
                    return Err(err("expected 'element NAME COUNT'".into()));
                };
                let count = count
                    .parse()
                    .map_err(|_| err(format!("element '{name}': bad count '{count}'")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(err("property before any element".into()));
                };
                let prop = if words.get(1) == Some(&"list") {
                    let Some(name) = words.get(4) else {
                        return Err(err("expected 'property list T T NAME'".into()));
                    };
                    Property {
                        name: name.to_string(),
                        kind: None,
                    }
                } else {
                    let (Some(ty), Some(name)) = (words.get(1), words.get(2)) else {
                        return Err(err("expected 'property TYPE NAME'".into()));
                    };
                    let kind = Scalar::parse(ty)
                        .ok_or_else(|| err(format!("property '{name}': unknown type '{ty}'")))?;
                    Property {
                        name: name.to_string(),
                        kind: Some(kind),
                    }
                };
                el.props.push(prop);
            }
            Some("end_header") => break,
            Some(other) => return Err(err(format!("unknown header keyword '{other}'"))),
        }
    }
    let format = format.ok_or(PlyError::Header {
        line: line_no,
        msg: "no 'format' line".into(),
    })?;
    Ok(Header {
        format,
        elements,
        body: pos,
        lines: line_no,
    })
}

/// The `vertex` element: one row of values (as f64) per vertex, in property order.
#[derive(Debug, Clone, PartialEq)]
pub struct VertexTable {
    pub names: Vec<String>,
    pub count: usize,
    /// Row-major, `count × names.len()`.
    pub values: Vec<f64>,
}

impl VertexTable {
    /// Column of property `name`.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Column of property `name`, or an error naming it.
    pub fn require(&self, name: &str) -> Result<usize, PlyError> {
        self.column(name)
            .ok_or_else(|| PlyError::MissingProperty(name.to_string()))
    }

    /// Vertex `v`'s values.
    pub fn row(&self, v: usize) -> &[f64] {
        let n = self.names.len();
        &self.values[v * n..(v + 1) * n]
    }

    pub fn rows(&self) -> impl Iterator<Item = &[f64]> {
        // A table without properties has no values: every row is empty.
        let n = self.names.len().max(1);
        self.values.chunks_exact(n)
    }
}

/// Reads the `vertex` element of a PLY file's bytes; a property of `required` that the header
/// lacks is an error before any data is read. The header's counts are checked against the
/// file's length and the memory budget before anything is allocated, and data beyond what
/// they declare is an error (a count lower than the data).
pub fn read_vertex_table(data: &[u8], required: &[&str]) -> Result<VertexTable, PlyError> {
    let header = parse_header(data)?;
    let vi = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or(PlyError::NoVertexElement)?;
    let vertex = &header.elements[vi];
    if let Some(name) = required
        .iter()
        .find(|&&name| !vertex.props.iter().any(|p| p.name == name))
    {
        return Err(PlyError::MissingProperty(name.to_string()));
    }
    let body = data.get(header.body..).unwrap_or(&[]);
    let n_props = vertex.props.len();
    let rows = match header.format {
        // An ASCII row takes at least a character and a separator per value: no more rows
        // than that fit are allocated; reading finds where the file really ends.
        Format::Ascii => vertex.count.min((body.len() + 1) / (2 * n_props).max(1)),
        Format::BinaryLe | Format::BinaryBe => {
            check_counts(&header, vi, body.len())?;
            vertex.count
        }
    };
    // Both bounds keep rows × props below the file's length.
    let n_values = rows.saturating_mul(n_props);
    crate::memory::check_memory(
        &format!("the PLY's vertex table ({rows} vertices × {n_props} properties)"),
        n_values as u128 * std::mem::size_of::<f64>() as u128,
    )
    .map_err(PlyError::TooLarge)?;
    let mut values_out = Vec::with_capacity(n_values);
    let mut values = vec![0.0f64; n_props];
    match header.format {
        Format::Ascii => {
            let text = std::str::from_utf8(body).map_err(|_| PlyError::Ascii {
                line: header.lines + 1,
                msg: "body is not text".into(),
            })?;
            let mut lines = text
                .lines()
                .enumerate()
                .map(|(i, l)| (header.lines + 1 + i, l));
            let skip = header.elements[..vi]
                .iter()
                .fold(0usize, |acc, e| acc.saturating_add(e.count));
            for _ in 0..skip {
                if lines.next().is_none() {
                    break;
                }
            }
            for v in 0..vertex.count {
                let Some((line, text)) = lines.next() else {
                    return Err(PlyError::Truncated {
                        vertex: v,
                        count: vertex.count,
                        property: vertex
                            .props
                            .first()
                            .map_or(String::new(), |p| p.name.clone()),
                    });
                };
                let mut toks = text.split_whitespace();
                for (k, prop) in vertex.props.iter().enumerate() {
                    let Some(tok) = toks.next() else {
                        return Err(PlyError::Ascii {
                            line,
                            msg: format!("vertex {v}: missing value for property '{}'", prop.name),
                        });
                    };
                    values[k] = tok.parse().map_err(|_| PlyError::Ascii {
                        line,
                        msg: format!(
                            "vertex {v}: property '{}': '{tok}' is not a number",
                            prop.name
                        ),
                    })?;
                }
                if toks.next().is_some() {
                    return Err(PlyError::Ascii {
                        line,
                        msg: format!("vertex {v}: more than {n_props} values"),
                    });
                }
                values_out.extend_from_slice(&values);
            }
            // Later elements are not bounded by check_counts: a huge count just skips all.
            let after = header.elements[vi + 1..]
                .iter()
                .fold(0usize, |acc, e| acc.saturating_add(e.count));
            for _ in 0..after {
                if lines.next().is_none() {
                    break;
                }
            }
            if let Some((line, _)) = lines.find(|(_, l)| !l.trim().is_empty()) {
                return Err(PlyError::ExtraData(format!(
                    "line {line} is beyond the {} entries the header declares ({})",
                    (skip + vertex.count).saturating_add(after),
                    declared(&header.elements)
                )));
            }
        }
        Format::BinaryLe | Format::BinaryBe => {
            let little = header.format == Format::BinaryLe;
            // check_counts made these sums and products fit in the body.
            let mut offset = 0;
            for e in &header.elements[..vi] {
                offset += record_size(e)? * e.count;
            }
            let stride = record_size(vertex)?;
            let body = &body[offset..];
            let needed = stride * vertex.count;
            let kinds: Vec<Scalar> = vertex.props.iter().filter_map(|p| p.kind).collect();
            for rec in body[..needed].chunks_exact(stride.max(1)) {
                let mut o = 0;
                for (k, kind) in kinds.iter().enumerate() {
                    values[k] = kind.read(&rec[o..], little);
                    o += kind.size();
                }
                values_out.extend_from_slice(&values);
            }
            // Later elements of fixed size (no lists) tell where the data must end.
            let rest: Option<u128> = header.elements[vi + 1..]
                .iter()
                .map(|e| record_size(e).ok().map(|s| s as u128 * e.count as u128))
                .sum();
            if let Some(rest) = rest {
                let extra = (body.len() as u128).saturating_sub(needed as u128 + rest);
                if extra > 0 {
                    return Err(PlyError::ExtraData(format!(
                        "{extra} bytes after the data the header declares ({})",
                        declared(&header.elements)
                    )));
                }
            }
        }
    }
    Ok(VertexTable {
        names: vertex.props.iter().map(|p| p.name.clone()).collect(),
        count: vertex.count,
        values: values_out,
    })
}

/// Bytes of one binary record of `e`; lists have no fixed size.
fn record_size(e: &Element) -> Result<usize, PlyError> {
    e.props.iter().try_fold(0, |acc, p| match p.kind {
        Some(k) => Ok(acc + k.size()),
        None => Err(PlyError::Unsupported(format!(
            "list property '{}' in binary element '{}' before/in vertex",
            p.name, e.name
        ))),
    })
}

/// `vertex 10, face 2`: the element counts of a header.
fn declared(elements: &[Element]) -> String {
    elements
        .iter()
        .map(|e| format!("{} {}", e.name, e.count))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Refuses binary counts that the `body_len` bytes after the header cannot hold, up to and
/// including the vertex element (index `vi`). Done in u128, so no product overflows.
fn check_counts(header: &Header, vi: usize, body_len: usize) -> Result<(), PlyError> {
    let mut before: u128 = 0;
    for (i, e) in header.elements[..=vi].iter().enumerate() {
        let per = record_size(e)?;
        let bytes = e.count as u128 * per as u128;
        if before + bytes <= body_len as u128 {
            before += bytes;
            continue;
        }
        let left = (body_len as u128).saturating_sub(before) as usize;
        if i == vi {
            // Which vertex and property the file ends in, as a truncated download shows.
            let v = left / per.max(1);
            let mut within = left - v * per;
            let mut property = String::new();
            for p in &e.props {
                property = p.name.clone();
                let size = p.kind.map_or(0, Scalar::size);
                if within < size {
                    break;
                }
                within -= size;
            }
            return Err(PlyError::Truncated {
                vertex: v,
                count: e.count,
                property,
            });
        }
        return Err(PlyError::CountExceedsFile {
            element: e.name.clone(),
            count: e.count,
            bytes: body_len,
            fits: left / per.max(1),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn binary(count: &str, rows: usize) -> Vec<u8> {
        let mut data = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {count}\nproperty float x\n\
             property float y\nproperty float z\nend_header\n"
        )
        .into_bytes();
        for i in 0..rows * 3 {
            data.extend_from_slice(&(i as f32).to_le_bytes());
        }
        data
    }

    #[test]
    fn counts_beyond_the_file_are_refused_before_allocating() {
        // 4e9 × 12 bytes would be 48 GB: refused from the file's length, nothing allocated.
        match read_vertex_table(&binary("4000000000", 1), &["x"]) {
            Err(PlyError::Truncated {
                vertex: 1,
                count: 4_000_000_000,
                ..
            }) => {}
            other => panic!("{other:?}"),
        }
        // A count whose byte size overflows 64 bits.
        assert!(read_vertex_table(&binary("18446744073709551615", 1), &["x"]).is_err());
        let ascii = "ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nend_header\n1\n2\n";
        let e = read_vertex_table(ascii.as_bytes(), &["x"]).expect_err("ascii");
        assert!(
            matches!(
                e,
                PlyError::Truncated {
                    vertex: 2,
                    count: 4_000_000_000,
                    ..
                }
            ),
            "{e}"
        );
        // An element before the vertices with more entries than lines: skipped to the end.
        let ascii = "ply
format ascii 1.0
element camera 99999999999999
property float f
element vertex 1
property float x
end_header
1
";
        assert!(read_vertex_table(ascii.as_bytes(), &["x"]).is_err());
        let before = "ply\nformat binary_little_endian 1.0\nelement camera 99999999999\nproperty float f\nelement vertex 1\nproperty float x\nend_header\n";
        let e = read_vertex_table(before.as_bytes(), &["x"]).expect_err("camera");
        assert!(e.to_string().contains("'camera'"), "{e}");
    }

    #[test]
    fn data_beyond_the_declared_counts_is_refused() {
        let ok = read_vertex_table(&binary("2", 2), &["x"]).expect("exact");
        assert_eq!((ok.count, ok.values.len()), (2, 6));
        let e = read_vertex_table(&binary("1", 2), &["x"]).expect_err("binary");
        assert!(e.to_string().contains("12 bytes after"), "{e}");
        let ascii =
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n2\n\n";
        let e = read_vertex_table(ascii.as_bytes(), &["x"]).expect_err("ascii");
        assert!(e.to_string().contains("line 7"), "{e}");
        // Lines of a later element are not extra data; a trailing blank line is fine.
        let faces = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n1\n3 0 0 0\n\n";
        assert!(read_vertex_table(faces.as_bytes(), &["x"]).is_ok());
    }
}
