//! Reads a 2-D little-endian float32 `.npy` file (what `numpy.save` writes
//! for a `float32` matrix), e.g. the detector's text feature per tag.

use std::path::Path;

use crate::PerceptionError;

/// A row-major matrix.
#[derive(Debug, Clone, PartialEq)]
pub struct Matrix {
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f32>,
}

impl Matrix {
    pub fn row(&self, r: usize) -> &[f32] {
        &self.data[r * self.cols..(r + 1) * self.cols]
    }
}

/// Loads `path`; errors name the file and what is wrong with it.
pub fn read_f32_matrix(path: &Path) -> Result<Matrix, PerceptionError> {
    let bytes = std::fs::read(path).map_err(|e| file_error(path, e))?;
    parse_f32_matrix(&bytes).map_err(|m| file_error(path, m))
}

fn file_error(path: &Path, e: impl std::fmt::Display) -> PerceptionError {
    PerceptionError::File {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Parses `.npy` bytes (format versions 1–3).
pub fn parse_f32_matrix(bytes: &[u8]) -> Result<Matrix, String> {
    const MAGIC: &[u8] = b"\x93NUMPY";
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err("not a .npy file (no \\x93NUMPY magic)".into());
    }
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!("unsupported .npy format version {v}")),
    };
    let header = bytes
        .get(start..start + header_len)
        .ok_or("truncated .npy header")?;
    let header = std::str::from_utf8(header).map_err(|_| "header is not text")?;
    let descr = dict_value(header, "descr").ok_or("header has no 'descr'")?;
    if !matches!(descr.trim_matches(['\'', '"']), "<f4" | "=f4" | "f4") {
        return Err(format!(
            "dtype {descr}: expected little-endian float32 ('<f4'); save with np.float32"
        ));
    }
    let fortran = dict_value(header, "fortran_order").ok_or("header has no 'fortran_order'")?;
    if fortran != "False" {
        return Err("Fortran-ordered array: save a C-ordered array (np.ascontiguousarray)".into());
    }
    let shape = dict_value(header, "shape").ok_or("header has no 'shape'")?;
    let dims: Vec<usize> = shape
        .trim_matches(['(', ')'])
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| format!("bad shape {shape}")))
        .collect::<Result<_, _>>()?;
    let [rows, cols] = dims[..] else {
        return Err(format!("shape {shape}: expected a 2-D array [tags, dim]"));
    };
    let payload = &bytes[start + header_len..];
    if payload.len() != rows * cols * 4 {
        return Err(format!(
            "shape {shape} needs {} bytes of data, file has {}",
            rows * cols * 4,
            payload.len()
        ));
    }
    let data = payload
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Ok(Matrix { rows, cols, data })
}

/// The raw text of `key`'s value in the header's Python dict literal.
fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let at = header
        .find(&format!("'{key}'"))
        .or_else(|| header.find(&format!("\"{key}\"")))?;
    let rest = header[at + key.len() + 2..].trim_start();
    let rest = rest.strip_prefix(':')?.trim_start();
    let end = if rest.starts_with('(') {
        rest.find(')')? + 1
    } else {
        rest.find([',', '}']).unwrap_or(rest.len())
    };
    Some(rest[..end].trim())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(header: &str, data: &[f32]) -> Vec<u8> {
        let mut h = header.to_string();
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(' ');
        }
        h.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(h.len() as u16).to_le_bytes());
        out.extend_from_slice(h.as_bytes());
        for v in data {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out
    }

    #[test]
    fn reads_a_float32_matrix() {
        let bytes = npy(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }",
            &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        );
        let m = parse_f32_matrix(&bytes).expect("parse");
        assert_eq!((m.rows, m.cols), (2, 3));
        assert_eq!(m.row(1), &[4.0, 5.0, 6.0]);
    }

    #[test]
    fn rejects_wrong_dtype_shape_and_length() {
        let f8 = npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 1), }",
            &[0.0, 0.0],
        );
        assert!(parse_f32_matrix(&f8).unwrap_err().contains("float32"));
        let one_d = npy(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (3,), }",
            &[0.0; 3],
        );
        assert!(parse_f32_matrix(&one_d).unwrap_err().contains("2-D"));
        let short = npy(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2), }",
            &[0.0; 3],
        );
        assert!(parse_f32_matrix(&short)
            .unwrap_err()
            .contains("needs 16 bytes"));
        assert!(parse_f32_matrix(b"hello").is_err());
    }
}
