//! Replica reader, NICE-SLAM layout: `results/frame%06d.jpg`,
//! `results/depth%06d.png`, `traj.txt` (row-major 4×4 camera-to-world per
//! line); optional `cam_params.json`, `results/label%06d.png`, `classes.json`.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion};
use opengs_geometry::{Intrinsics, Pose};

use crate::classes::read_class_table;
use crate::image_io::{check_exists, check_image_size, read_rgb, read_u16};
use crate::text::{data_lines, parse_numbers};
use crate::{DatasetError, InstanceClass, RgbdFrame, RgbdSource};

/// Depth units per metre in Replica depth PNGs.
pub const REPLICA_DEPTH_SCALE: f32 = 6553.5;

#[derive(Debug, Clone, PartialEq)]
pub struct ReplicaOptions {
    /// Overrides `cam_params.json` and the Replica default camera.
    pub intrinsics: Option<Intrinsics>,
    pub frame_rate: f64,
}

impl Default for ReplicaOptions {
    fn default() -> Self {
        Self {
            intrinsics: None,
            frame_rate: 30.0,
        }
    }
}

/// The camera of the NICE-SLAM Replica renders.
pub fn replica_default_intrinsics() -> Intrinsics {
    Intrinsics::new(600.0, 600.0, 599.5, 339.5, 1200, 680)
}

/// `cam_params.json` as shipped with Replica renders (and written by us).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(crate) struct CamParams {
    pub camera: CameraParams,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(crate) struct CameraParams {
    pub w: u32,
    pub h: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub scale: f32,
}

pub(crate) fn frame_path(dir: &Path, index: usize) -> PathBuf {
    dir.join("results").join(format!("frame{index:06}.jpg"))
}

pub(crate) fn depth_path(dir: &Path, index: usize) -> PathBuf {
    dir.join("results").join(format!("depth{index:06}.png"))
}

pub(crate) fn label_path(dir: &Path, index: usize) -> PathBuf {
    dir.join("results").join(format!("label{index:06}.png"))
}

/// Reads `traj.txt`: one row-major 4×4 camera-to-world matrix per line.
pub fn read_replica_trajectory(path: &Path) -> Result<Vec<Pose>, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
    parse_replica_trajectory(&text, path)
}

/// Parses the text of a `traj.txt` read from `path`.
pub fn parse_replica_trajectory(text: &str, path: &Path) -> Result<Vec<Pose>, DatasetError> {
    let mut poses = Vec::new();
    for (line_no, line) in data_lines(text) {
        let v = parse_numbers(path, line_no, &line)?;
        if v.len() != 16 {
            return Err(DatasetError::parse(
                path,
                line_no,
                format!("expected 16 numbers (row-major 4x4), found {}", v.len()),
            ));
        }
        let r = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
        // `!(x <= tol)` refuses NaN too (huge entries overflow), on which from_matrix never ends.
        if !((r.determinant() - 1.0).abs() <= 1e-3
            && (r.transpose() * r - Matrix3::identity()).norm() <= 1e-3)
        {
            return Err(DatasetError::parse(
                path,
                line_no,
                "rotation part is not orthonormal",
            ));
        }
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
        poses.push(Pose::from_parts(Translation3::new(v[3], v[7], v[11]), rot));
    }
    Ok(poses)
}

/// Parses and checks the text of a `cam_params.json` read from `path`: the camera and the
/// depth scale (units per metre).
pub fn parse_cam_params(text: &str, path: &Path) -> Result<(Intrinsics, f32), DatasetError> {
    let c = serde_json::from_str::<CamParams>(text)
        .map_err(|e| DatasetError::Parse {
            path: path.to_path_buf(),
            line: e.line(),
            message: e.to_string(),
        })?
        .camera;
    let k = Intrinsics::new(c.fx, c.fy, c.cx, c.cy, c.w, c.h);
    k.validate().map_err(|e| DatasetError::invalid(path, e))?;
    if !(c.scale.is_finite() && c.scale > 0.0) {
        return Err(DatasetError::invalid(
            path,
            format!("depth scale {} must be finite and > 0", c.scale),
        ));
    }
    Ok((k, c.scale))
}

pub struct ReplicaSource {
    dir: PathBuf,
    intrinsics: Intrinsics,
    depth_scale: f32,
    options: ReplicaOptions,
    poses: Vec<Pose>,
    has_labels: bool,
    classes: Vec<InstanceClass>,
}

impl ReplicaSource {
    pub fn open(dir: &Path, options: ReplicaOptions) -> Result<Self, DatasetError> {
        if !dir.is_dir() {
            return Err(DatasetError::Missing {
                path: dir.to_path_buf(),
            });
        }
        let results = dir.join("results");
        if !results.is_dir() {
            return Err(DatasetError::Missing { path: results });
        }
        let poses = read_replica_trajectory(&dir.join("traj.txt"))?;
        if poses.is_empty() {
            return Err(DatasetError::invalid(&dir.join("traj.txt"), "no poses"));
        }
        let params_file = dir.join("cam_params.json");
        let params = match params_file.exists() {
            true => {
                let text = std::fs::read_to_string(&params_file)
                    .map_err(|e| DatasetError::io(&params_file, e))?;
                Some(parse_cam_params(&text, &params_file)?)
            }
            false => None,
        };
        let intrinsics = options.intrinsics.unwrap_or_else(|| match &params {
            Some((k, _)) => *k,
            None => replica_default_intrinsics(),
        });
        let depth_scale = params.as_ref().map_or(REPLICA_DEPTH_SCALE, |(_, s)| *s);
        let first_frame = frame_path(dir, 0);
        if !first_frame.exists() {
            return Err(DatasetError::Missing { path: first_frame });
        }
        let has_labels = label_path(dir, 0).exists();
        // A missing image found now fails before any stage starts, not mid-run.
        for i in 0..poses.len() {
            check_exists(&frame_path(dir, i), "traj.txt's poses")?;
            check_exists(&depth_path(dir, i), "traj.txt's poses")?;
            if has_labels {
                check_exists(&label_path(dir, i), "traj.txt's poses")?;
            }
        }
        let camera = match (options.intrinsics.is_some(), params.is_some()) {
            (true, _) => "the camera given",
            (false, true) => "cam_params.json",
            (false, false) => "the Replica default camera (no cam_params.json)",
        };
        check_image_size(&first_frame, &intrinsics, camera)?;
        let classes_file = dir.join("classes.json");
        let classes = match classes_file.exists() {
            true => read_class_table(&classes_file)?,
            false => Vec::new(),
        };
        Ok(Self {
            dir: dir.to_path_buf(),
            intrinsics,
            depth_scale,
            options,
            poses,
            has_labels,
            classes,
        })
    }
}

impl RgbdSource for ReplicaSource {
    fn name(&self) -> String {
        format!("replica:{}", self.dir.display())
    }

    fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    fn len(&self) -> usize {
        self.poses.len()
    }

    fn frame_rate(&self) -> f64 {
        self.options.frame_rate
    }

    fn frame(&mut self, index: usize) -> Result<RgbdFrame, DatasetError> {
        let pose = *self.poses.get(index).ok_or(DatasetError::OutOfRange {
            index,
            len: self.poses.len(),
        })?;
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        let labels = match self.has_labels {
            true => Some(read_u16(&label_path(&self.dir, index), w, h)?),
            false => None,
        };
        Ok(RgbdFrame {
            index,
            timestamp: index as f64 / self.options.frame_rate,
            width: w,
            height: h,
            rgb: read_rgb(&frame_path(&self.dir, index), w, h)?,
            depth: read_u16(&depth_path(&self.dir, index), w, h)?,
            depth_scale: self.depth_scale,
            gt_pose: Some(pose),
            labels,
        })
    }

    fn class_table(&self) -> Vec<InstanceClass> {
        self.classes.clone()
    }
}
