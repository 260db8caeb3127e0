//! Colour beyond SH band 0: a 3DGS PLY of degree d carries 3((d+1)² − 1) `f_rest_*` values per
//! Gaussian. The map keeps band 0 only, so an edited map written from such a file would lose
//! its view-dependent colour, and a rotated object would need those bands turned; edits refuse
//! these files rather than write something that looks different.

use crate::error::{ObjectError, Result};

/// SH degree of a 3DGS PLY from its header (0 when it has no `f_rest_*` property).
pub fn ply_sh_degree(data: &[u8]) -> Result<u32, String> {
    let mut rest = 0usize;
    for line in data.split(|&c| c == b'\n') {
        let line = String::from_utf8_lossy(line);
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => return degree_of(rest),
            ["property", _, name] if name.starts_with("f_rest_") => rest += 1,
            _ => {}
        }
    }
    Err("PLY header has no 'end_header'".into())
}

fn degree_of(rest: usize) -> Result<u32, String> {
    (0..=4u32)
        .find(|d| 3 * ((d + 1) * (d + 1) - 1) as usize == rest)
        .ok_or_else(|| format!("{rest} f_rest_* properties is no SH degree (9, 24 or 45 expected)"))
}

/// Refuses to write an edited map from a file (`path`) of SH degree `degree` > 0.
pub fn refuse_higher_bands(path: &std::path::Path, degree: u32, edit: &str) -> Result<()> {
    if degree == 0 {
        return Ok(());
    }
    Err(ObjectError::file(
        path,
        format!(
            "has SH degree {degree} colour ({} f_rest values per Gaussian), but opengs maps keep \
             degree 0 only: {edit} would write the map without its view-dependent colour{}; refusing",
            3 * ((degree + 1) * (degree + 1) - 1),
            if edit == "rotate" {
                ", and turning the object would need those bands rotated too"
            } else {
                ""
            }
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(rest: usize) -> Vec<u8> {
        let mut h = String::from(
            "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\n",
        );
        for i in 0..rest {
            h += &format!("property float f_rest_{i}\n");
        }
        h += "property float opacity\nend_header\n";
        h.into_bytes()
    }

    #[test]
    fn degree_from_the_header() {
        assert_eq!(ply_sh_degree(&header(0)), Ok(0));
        assert_eq!(ply_sh_degree(&header(9)), Ok(1));
        assert_eq!(ply_sh_degree(&header(45)), Ok(3));
        assert!(ply_sh_degree(&header(7)).is_err());
        assert!(ply_sh_degree(b"ply\nformat ascii 1.0\n").is_err());
    }

    #[test]
    fn rotate_refuses_degree_three_and_says_why() {
        let path = std::path::Path::new("scan.ply");
        assert!(refuse_higher_bands(path, 0, "rotate").is_ok());
        let degree = ply_sh_degree(&header(45)).expect("degree 3");
        let err = refuse_higher_bands(path, degree, "rotate").expect_err("degree 3");
        let text = err.to_string();
        assert!(
            text.contains("scan.ply") && text.contains("degree 3") && text.contains("rotated"),
            "{text}"
        );
    }
}
