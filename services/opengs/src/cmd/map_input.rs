//! A Gaussian map read for a command: Gaussians with NaN/Inf values are reported (left out),
//! or the map is refused with `--strict`.

use std::path::Path;

use anyhow::Context;
use opengs_splat::{read_ply_counted, read_ply_file_counted, GaussianMap, PlyMap};

/// Reads the map at `path` (see [`checked`]).
pub fn load_map(path: &Path, strict: bool) -> anyhow::Result<GaussianMap> {
    let read =
        read_ply_file_counted(path).with_context(|| format!("reading {}", path.display()))?;
    checked(read, path, strict)
}

/// Parses the bytes of the map at `path` (see [`checked`]).
pub fn parse_map(data: &[u8], path: &Path, strict: bool) -> anyhow::Result<GaussianMap> {
    let read = read_ply_counted(data).with_context(|| format!("reading {}", path.display()))?;
    checked(read, path, strict)
}

/// The map, after a warning on stderr naming what was left out; an error with `strict`.
pub fn checked(read: PlyMap, path: &Path, strict: bool) -> anyhow::Result<GaussianMap> {
    if let Some(msg) = read.dropped_message() {
        anyhow::ensure!(!strict, "{}: {msg}; refused (--strict)", path.display());
        eprintln!(
            "warning: {}: {msg}; they are left out (--strict refuses such a map)",
            path.display()
        );
    }
    Ok(read.map)
}
