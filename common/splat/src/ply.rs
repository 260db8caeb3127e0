//! Standard 3DGS PLY (x y z nx ny nz f_dc_* f_rest_* opacity scale_* rot_*) plus `label`,
//! read through the workspace's one PLY reader ([`opengs_geometry::read_vertex_table`]).

use std::io::Write;
use std::path::Path;

pub use opengs_geometry::PlyError;
use opengs_geometry::{read_vertex_table, VertexTable};

use crate::map::{Gaussian, GaussianMap};

/// Column index of each Gaussian field in the vertex property list.
struct Columns {
    mean: [usize; 3],
    dc: [usize; 3],
    opacity: usize,
    scale: [usize; 3],
    rot: [usize; 4],
    label: Option<usize>,
}

impl Columns {
    const REQUIRED: [&'static str; 14] = [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ];

    fn find(table: &VertexTable) -> Result<Self, PlyError> {
        let idx = |name: &str| table.require(name);
        Ok(Self {
            mean: [idx("x")?, idx("y")?, idx("z")?],
            dc: [idx("f_dc_0")?, idx("f_dc_1")?, idx("f_dc_2")?],
            opacity: idx("opacity")?,
            scale: [idx("scale_0")?, idx("scale_1")?, idx("scale_2")?],
            rot: [idx("rot_0")?, idx("rot_1")?, idx("rot_2")?, idx("rot_3")?],
            label: idx("label").ok(),
        })
    }

    /// Every value the map keeps is finite as f32 (the label is checked on its own).
    fn finite(&self, v: &[f64]) -> bool {
        self.mean
            .iter()
            .chain(&self.dc)
            .chain(&self.scale)
            .chain(&self.rot)
            .chain(std::iter::once(&self.opacity))
            .all(|&i| (v[i] as f32).is_finite())
    }

    fn gaussian(&self, v: &[f64], vertex: usize) -> Result<Gaussian, PlyError> {
        let f = |i: usize| v[i] as f32;
        let label = match self.label {
            None => 0,
            Some(i) if v[i] >= 0.0 && v[i] <= u32::MAX as f64 && v[i].fract() == 0.0 => v[i] as u32,
            Some(i) => {
                return Err(PlyError::Invalid {
                    vertex,
                    msg: format!("label {} is not a u32", v[i]),
                })
            }
        };
        let mut rot = self.rot.map(f);
        // In f64: f32 squares of tiny components lose their bits (and of huge ones overflow).
        let q = rot.map(f64::from);
        let n2: f64 = q.iter().map(|q| q * q).sum();
        if !(n2.is_finite() && n2 > 0.0) {
            return Err(PlyError::Invalid {
                vertex,
                msg: "rotation has zero or non-finite norm".into(),
            });
        }
        // Already-unit quaternions are kept bit-exact (round trips), others normalised.
        if (n2 - 1.0).abs() > 1e-6 {
            let n = n2.sqrt();
            rot = q.map(|q| (q / n) as f32);
        }
        Ok(Gaussian {
            mean: self.mean.map(f),
            rotation: rot,
            log_scale: self.scale.map(f),
            opacity_logit: f(self.opacity),
            sh_dc: self.dc.map(f),
            label,
        })
    }
}

/// A map read from a PLY, with the Gaussians the reader left out of it.
#[derive(Debug, Clone)]
pub struct PlyMap {
    pub map: GaussianMap,
    /// Vertices left out because a value is NaN or infinite (as f32): no render, loss or
    /// optimiser step can use them.
    pub non_finite: usize,
    /// The first of them (vertex index in the file).
    pub first_non_finite: Option<usize>,
}

impl PlyMap {
    /// What was left out, in words; `None` when nothing was.
    pub fn dropped_message(&self) -> Option<String> {
        let first = self.first_non_finite?;
        Some(format!(
            "{} of {} Gaussians have NaN or infinite values (the first is vertex {first})",
            self.non_finite,
            self.non_finite + self.map.len()
        ))
    }

    /// The map; with `strict`, an error when any Gaussian was left out.
    pub fn into_map(self, strict: bool) -> Result<GaussianMap, PlyError> {
        match self.dropped_message() {
            Some(msg) if strict => Err(PlyError::Invalid {
                vertex: self.first_non_finite.unwrap_or(0),
                msg: format!("{msg}; refused (--strict)"),
            }),
            _ => Ok(self.map),
        }
    }
}

/// Parses a PLY file's bytes into a map (SH beyond degree 0 ignored; no `label` → 0), counting
/// and leaving out Gaussians with NaN or infinite values.
pub fn read_ply_counted(data: &[u8]) -> Result<PlyMap, PlyError> {
    let table = read_vertex_table(data, &Columns::REQUIRED)?;
    let cols = Columns::find(&table)?;
    let mut map = GaussianMap::with_capacity(table.count);
    let (mut non_finite, mut first_non_finite) = (0, None);
    for (v, row) in table.rows().enumerate() {
        if !cols.finite(row) {
            non_finite += 1;
            first_non_finite.get_or_insert(v);
            continue;
        }
        map.push(cols.gaussian(row, v)?);
    }
    Ok(PlyMap {
        map,
        non_finite,
        first_non_finite,
    })
}

/// [`read_ply_counted`]'s map: Gaussians with NaN or infinite values left out.
pub fn read_ply(data: &[u8]) -> Result<GaussianMap, PlyError> {
    Ok(read_ply_counted(data)?.map)
}

/// Reads a PLY file from disk ([`read_ply_counted`]).
pub fn read_ply_file_counted(path: impl AsRef<Path>) -> Result<PlyMap, PlyError> {
    let path = path.as_ref();
    let data = std::fs::read(path).map_err(|source| PlyError::Io {
        path: path.display().to_string(),
        source,
    })?;
    read_ply_counted(&data)
}

/// Reads a PLY file from disk ([`read_ply`]).
pub fn read_ply_file(path: impl AsRef<Path>) -> Result<GaussianMap, PlyError> {
    Ok(read_ply_file_counted(path)?.map)
}

/// Writes the map as binary little-endian 3DGS PLY, SH degree 0, with a `label` property.
pub fn write_ply(map: &GaussianMap, mut out: impl Write) -> std::io::Result<()> {
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment opengs\nelement vertex {}\n",
        map.len()
    );
    for name in [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0",
        "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        header.push_str(&format!("property float {name}\n"));
    }
    header.push_str("property uint label\nend_header\n");
    out.write_all(header.as_bytes())?;
    let mut buf = Vec::with_capacity(map.len() * 72);
    for i in 0..map.len() {
        let floats = map.means[i]
            .iter()
            .chain(&[0.0f32; 3])
            .chain(&map.sh_dc[i])
            .chain(std::iter::once(&map.opacity_logits[i]))
            .chain(&map.log_scales[i])
            .chain(&map.rotations[i]);
        for v in floats {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        buf.extend_from_slice(&map.labels[i].to_le_bytes());
    }
    out.write_all(&buf)
}

/// Writes the map to a file (see [`write_ply`]).
pub fn write_ply_file(map: &GaussianMap, path: impl AsRef<Path>) -> Result<(), PlyError> {
    let path = path.as_ref();
    let io = |source| PlyError::Io {
        path: path.display().to_string(),
        source,
    };
    let file = std::fs::File::create(path).map_err(io)?;
    let mut w = std::io::BufWriter::new(file);
    write_ply(map, &mut w).map_err(io)?;
    w.flush().map_err(io)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::indoor_scene;

    fn bits(m: &GaussianMap) -> Vec<u32> {
        let mut v = Vec::new();
        for i in 0..m.len() {
            let g = m.get(i);
            v.extend(
                g.mean
                    .iter()
                    .chain(&g.rotation)
                    .chain(&g.log_scale)
                    .map(|f| f.to_bits()),
            );
            v.push(g.opacity_logit.to_bits());
            v.extend(g.sh_dc.iter().map(|f| f.to_bits()));
            v.push(g.label);
        }
        v
    }

    #[test]
    fn round_trip_is_bit_identical() {
        let mut map = indoor_scene(500, 3);
        map.labels[7] = u32::MAX;
        map.sh_dc[3] = [-0.0, 1e-30, -7.25];
        let mut buf = Vec::new();
        write_ply(&map, &mut buf).expect("write to memory");
        let back = read_ply(&buf).expect("read back");
        assert_eq!(back.len(), 500);
        assert_eq!(bits(&back), bits(&map));
        // And the file written again is byte-identical.
        let mut buf2 = Vec::new();
        write_ply(&back, &mut buf2).expect("write to memory");
        assert_eq!(buf, buf2);
    }

    #[test]
    fn ascii_sh3_without_label_loads() {
        let mut text = String::from("ply\nformat ascii 1.0\nelement vertex 2\n");
        for p in [
            "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
        ] {
            text += &format!("property float {p}\n");
        }
        for i in 0..45 {
            text += &format!("property float f_rest_{i}\n");
        }
        for p in [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ] {
            text += &format!("property float {p}\n");
        }
        text += "end_header\n";
        let rest = vec!["0.5"; 45].join(" ");
        // Second rotation (2, 0, 0, 0) is not unit: normalised to (1, 0, 0, 0).
        text += &format!("1 2 3 0 0 1 0.1 0.2 0.3 {rest} -1.5 -4 -4.5 -5 1 0 0 0\n");
        text += &format!("-1 0.5 2 0 0 1 -0.1 0 0 {rest} 2 -3 -3 -3 2 0 0 0\n");
        let map = read_ply(text.as_bytes()).expect("valid ascii ply");
        assert_eq!(map.len(), 2);
        assert_eq!(map.means[0], [1.0, 2.0, 3.0]);
        assert_eq!(map.sh_dc[0], [0.1, 0.2, 0.3]);
        assert_eq!(map.opacity_logits[0], -1.5);
        assert_eq!(map.log_scales[0], [-4.0, -4.5, -5.0]);
        assert_eq!(map.rotations[1], [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(map.labels, vec![0, 0]);
    }

    #[test]
    fn non_finite_gaussians_are_counted_left_out_and_refused_when_strict() {
        let mut map = indoor_scene(4, 1);
        map.means[1][0] = f32::NAN;
        map.log_scales[3][2] = f32::INFINITY;
        let mut buf = Vec::new();
        write_ply(&map, &mut buf).expect("write to memory");
        let read = read_ply_counted(&buf).expect("readable");
        assert_eq!((read.map.len(), read.non_finite), (2, 2));
        let msg = read.dropped_message().expect("message");
        assert!(
            msg.starts_with("2 of 4 Gaussians") && msg.contains("vertex 1"),
            "{msg}"
        );
        let e = read.clone().into_map(true).expect_err("strict");
        assert!(e.to_string().contains("--strict"), "{e}");
        assert_eq!(read.into_map(false).expect("lenient").len(), 2);
    }

    #[test]
    fn truncated_binary_names_vertex_and_property() {
        let map = indoor_scene(10, 1);
        let mut buf = Vec::new();
        write_ply(&map, &mut buf).expect("write to memory");
        // Cut inside vertex 9: 72 bytes per vertex, keep 9 full ones + 18 bytes (x y z nx complete, into ny).
        let header_len = buf.len() - 10 * 72;
        let err = read_ply(&buf[..header_len + 9 * 72 + 18]).expect_err("truncated");
        match &err {
            PlyError::Truncated {
                vertex: 9,
                count: 10,
                property,
            } => assert_eq!(property, "ny"),
            other => panic!("unexpected error {other}"),
        }
        assert!(err.to_string().contains("vertex 9"));
    }

    #[test]
    fn malformed_files_name_the_problem() {
        let no_rot =
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                      property float z\nproperty float f_dc_0\nproperty float f_dc_1\n\
                      property float f_dc_2\nproperty float opacity\nproperty float scale_0\n\
                      property float scale_1\nproperty float scale_2\nend_header\n";
        let err = read_ply(no_rot.as_bytes()).expect_err("no rotation");
        assert!(err.to_string().contains("rot_0"), "{err}");

        let header = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                      property float z\nproperty float f_dc_0\nproperty float f_dc_1\n\
                      property float f_dc_2\nproperty float opacity\nproperty float scale_0\n\
                      property float scale_1\nproperty float scale_2\nproperty float rot_0\n\
                      property float rot_1\nproperty float rot_2\nproperty float rot_3\nend_header\n";
        let bad_number =
            format!("{header}0 0 0 0 0 0 0 0 0 0 1 0 0 0\n0 0 zz 0 0 0 0 0 0 0 1 0 0 0\n");
        let err = read_ply(bad_number.as_bytes()).expect_err("bad number");
        assert!(
            err.to_string().contains("line 20") && err.to_string().contains("'z'"),
            "{err}"
        );
        let short = format!("{header}0 0 0 0 0 0 0 0 0 0 1 0 0 0\n");
        let err = read_ply(short.as_bytes()).expect_err("missing vertex");
        assert!(err.to_string().contains("vertex 1 of 2"), "{err}");
        let err = read_ply(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n")
            .expect_err("no end");
        assert!(err.to_string().contains("end_header"), "{err}");
        assert!(read_ply(b"PLY\n").is_err());
    }
}
