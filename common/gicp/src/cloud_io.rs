//! Point clouds on disk: PLY (the vertex element's x y z, other properties ignored; read
//! by the workspace's one PLY reader) and plain `x y z` text.

use nalgebra::Point3;
use opengs_geometry::{read_vertex_table, PlyError};
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
    #[error("{path}: {error}")]
    Ply { path: PathBuf, error: PlyError },
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

/// Parses a whole PLY file; only the `vertex` element's x, y, z are kept.
pub fn parse_ply(bytes: &[u8], path: &Path) -> Result<Vec<Point3<f64>>, CloudIoError> {
    let ply_error = |error: PlyError| CloudIoError::Ply {
        path: path.to_path_buf(),
        error,
    };
    let table = read_vertex_table(bytes, &["x", "y", "z"]).map_err(ply_error)?;
    let axes = [
        table.require("x").map_err(ply_error)?,
        table.require("y").map_err(ply_error)?,
        table.require("z").map_err(ply_error)?,
    ];
    let mut points = Vec::with_capacity(table.count);
    for (v, row) in table.rows().enumerate() {
        let xyz = axes.map(|a| row[a]);
        if !xyz.iter().all(|c| c.is_finite()) {
            return Err(ply_error(PlyError::Invalid {
                vertex: v,
                msg: "non-finite coordinate".into(),
            }));
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
        assert_eq!(
            e,
            "a.ply: PLY line 9: vertex 1: property 'y': 'x' is not a number"
        );
        let e = parse_ply(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty blob x\n",
            Path::new("a.ply"),
        )
        .expect_err("bad type")
        .to_string();
        assert_eq!(
            e,
            "a.ply: PLY header line 4: property 'x': unknown type 'blob'"
        );
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
