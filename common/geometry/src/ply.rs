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
/// lacks is an error before any data is read.
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
    let mut values_out = Vec::with_capacity(vertex.count.min(1 << 24) * vertex.props.len());
    let mut values = vec![0.0f64; vertex.props.len()];
    match header.format {
        Format::Ascii => {
            let text = std::str::from_utf8(&data[header.body..]).map_err(|_| PlyError::Ascii {
                line: header.lines + 1,
                msg: "body is not text".into(),
            })?;
            let mut lines = text
                .lines()
                .enumerate()
                .map(|(i, l)| (header.lines + 1 + i, l));
            let skip: usize = header.elements[..vi].iter().map(|e| e.count).sum();
            for _ in 0..skip {
                lines.next();
            }
            for v in 0..vertex.count {
                let Some((line, text)) = lines.next() else {
                    return Err(PlyError::Truncated {
                        vertex: v,
                        count: vertex.count,
                        property: vertex.props[0].name.clone(),
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
                        msg: format!("vertex {v}: more than {} values", vertex.props.len()),
                    });
                }
                values_out.extend_from_slice(&values);
            }
        }
        Format::BinaryLe | Format::BinaryBe => {
            let little = header.format == Format::BinaryLe;
            let record_size = |e: &Element| -> Result<usize, PlyError> {
                e.props.iter().try_fold(0, |acc, p| match p.kind {
                    Some(k) => Ok(acc + k.size()),
                    None => Err(PlyError::Unsupported(format!(
                        "list property '{}' in binary element '{}' before/in vertex",
                        p.name, e.name
                    ))),
                })
            };
            let mut offset = header.body;
            for e in &header.elements[..vi] {
                offset += record_size(e)? * e.count;
            }
            let stride = record_size(vertex)?;
            let body = data.get(offset..).unwrap_or(&[]);
            let needed = stride * vertex.count;
            if body.len() < needed {
                let v = body.len() / stride.max(1);
                let mut within = body.len() - v * stride;
                let mut property = String::new();
                for p in &vertex.props {
                    property = p.name.clone();
                    let size = p.kind.map_or(0, Scalar::size);
                    if within < size {
                        break;
                    }
                    within -= size;
                }
                return Err(PlyError::Truncated {
                    vertex: v,
                    count: vertex.count,
                    property,
                });
            }
            let kinds: Vec<Scalar> = vertex.props.iter().filter_map(|p| p.kind).collect();
            for rec in body[..needed].chunks_exact(stride) {
                let mut o = 0;
                for (k, kind) in kinds.iter().enumerate() {
                    values[k] = kind.read(&rec[o..], little);
                    o += kind.size();
                }
                values_out.extend_from_slice(&values);
            }
        }
    }
    Ok(VertexTable {
        names: vertex.props.iter().map(|p| p.name.clone()).collect(),
        count: vertex.count,
        values: values_out,
    })
}
