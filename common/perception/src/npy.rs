//! Reads a 2-D float32 `.npy` file (what `numpy.save` writes for a `float32` matrix), e.g.
//! the detector's text feature per tag, through ndarray-npy.

use std::path::Path;

use ndarray::Array2;
use ndarray_npy::{ReadNpyError, ReadNpyExt};

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

/// Parses the bytes of a 2-D float32 `.npy` file (ndarray-npy reads the format).
pub fn parse_f32_matrix(bytes: &[u8]) -> Result<Matrix, String> {
    let array = Array2::<f32>::read_npy(bytes).map_err(|e| {
        let what = match e {
            ReadNpyError::WrongDescriptor(_) | ReadNpyError::WrongNdim(..) => {
                "not a 2-D float32 .npy matrix (numpy.save of a float32 array)"
            }
            _ => "not a readable .npy file",
        };
        format!("{what}: {e}")
    })?;
    let (rows, cols) = array.dim();
    let data = array.as_standard_layout().iter().copied().collect();
    Ok(Matrix { rows, cols, data })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(header: &str, data: &[f32]) -> Vec<u8> {
        let mut h = header.to_string();
        while !(10 + h.len() + 1).is_multiple_of(64) {
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
        assert!(parse_f32_matrix(&short).is_err());
        assert!(parse_f32_matrix(b"hello").is_err());
    }
}
