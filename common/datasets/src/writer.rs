//! Writes any source to disk in TUM or Replica layout, or as a ROS 2 bag (what `opengs
//! synth` uses), so the readers of this crate load it back unchanged.

use std::path::Path;
use std::str::FromStr;

use rayon::prelude::*;

use crate::classes::write_class_table;
use crate::image_io::{write_rgb_jpeg, write_rgb_png, write_u16_png};
use crate::replica::{
    depth_path, frame_path, label_path, CamParams, CameraParams, REPLICA_DEPTH_SCALE,
};
use crate::rosbag2_writer::{write_rosbag2, ChunkCompression};
use crate::trajectory::format_tum_line;
use crate::tum::TUM_DEPTH_SCALE;
use crate::{DatasetError, RgbdFrame, RgbdSource};

/// JPEG quality of Replica colour frames.
const JPEG_QUALITY: u8 = 95;
/// Frames fetched before encoding them in parallel.
const BATCH: usize = 8;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DatasetFormat {
    Tum,
    Replica,
    /// A ROS 2 bag directory (metadata.yaml + one MCAP file).
    Rosbag2,
}

impl FromStr for DatasetFormat {
    type Err = DatasetError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "tum" => Ok(Self::Tum),
            "replica" => Ok(Self::Replica),
            "rosbag2" => Ok(Self::Rosbag2),
            _ => Err(DatasetError::Spec(format!(
                "unknown dataset format '{s}': expected 'tum', 'replica' or 'rosbag2'"
            ))),
        }
    }
}

impl std::fmt::Display for DatasetFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Tum => "tum",
            Self::Replica => "replica",
            Self::Rosbag2 => "rosbag2",
        })
    }
}

/// Converts depth units; values that no longer fit become missing (0).
pub(crate) fn rescale_depth(depth: &[u16], from: f32, to: f32) -> Vec<u16> {
    if from == to {
        return depth.to_vec();
    }
    let k = to as f64 / from as f64;
    depth
        .iter()
        .map(|&d| {
            let v = (d as f64 * k).round();
            if v <= u16::MAX as f64 {
                v as u16
            } else {
                0
            }
        })
        .collect()
}

fn create_dir(path: &Path) -> Result<(), DatasetError> {
    std::fs::create_dir_all(path).map_err(|e| DatasetError::io(path, e))
}

fn write_text(path: &Path, text: &str) -> Result<(), DatasetError> {
    std::fs::write(path, text).map_err(|e| DatasetError::io(path, e))
}

/// Writes all frames of `source` under `out`; `progress(done, total)` is
/// called after each batch.
pub fn write_dataset(
    source: &mut dyn RgbdSource,
    out: &Path,
    format: DatasetFormat,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), DatasetError> {
    let total = source.len();
    let k = source.intrinsics();
    match format {
        DatasetFormat::Rosbag2 => {
            return write_rosbag2(source, out, ChunkCompression::Zstd, progress)
        }
        DatasetFormat::Tum => {
            for sub in ["rgb", "depth", "labels"] {
                create_dir(&out.join(sub))?;
            }
            write_text(
                &out.join("intrinsics.txt"),
                &format!(
                    "# fx fy cx cy width height\n{} {} {} {} {} {}\n",
                    k.fx, k.fy, k.cx, k.cy, k.width, k.height
                ),
            )?;
        }
        DatasetFormat::Replica => {
            create_dir(&out.join("results"))?;
            let params = CamParams {
                camera: CameraParams {
                    w: k.width,
                    h: k.height,
                    fx: k.fx,
                    fy: k.fy,
                    cx: k.cx,
                    cy: k.cy,
                    scale: REPLICA_DEPTH_SCALE,
                },
            };
            let path = out.join("cam_params.json");
            let text = serde_json::to_string_pretty(&params)
                .map_err(|e| DatasetError::invalid(&path, e.to_string()))?;
            write_text(&path, &text)?;
        }
    }
    write_class_table(&out.join("classes.json"), &source.class_table())?;

    let mut index_lines = IndexLines::default();
    let mut done = 0;
    while done < total {
        let batch: Vec<RgbdFrame> = (done..(done + BATCH).min(total))
            .map(|i| source.frame(i))
            .collect::<Result<_, _>>()?;
        batch
            .par_iter()
            .map(|f| match format {
                DatasetFormat::Tum => write_tum_frame(out, f),
                DatasetFormat::Replica => write_replica_frame(out, f),
                DatasetFormat::Rosbag2 => Ok(()),
            })
            .collect::<Result<Vec<()>, _>>()?;
        for f in &batch {
            index_lines.add(format, f, out)?;
        }
        done += batch.len();
        progress(done, total);
    }
    index_lines.write(format, out)
}

fn tum_name(dir: &str, index: usize) -> String {
    format!("{dir}/{index:06}.png")
}

fn write_tum_frame(out: &Path, f: &RgbdFrame) -> Result<(), DatasetError> {
    write_rgb_png(
        &out.join(tum_name("rgb", f.index)),
        f.width,
        f.height,
        &f.rgb,
    )?;
    let depth = rescale_depth(&f.depth, f.depth_scale, TUM_DEPTH_SCALE);
    write_u16_png(
        &out.join(tum_name("depth", f.index)),
        f.width,
        f.height,
        &depth,
    )?;
    if let Some(labels) = &f.labels {
        write_u16_png(
            &out.join(tum_name("labels", f.index)),
            f.width,
            f.height,
            labels,
        )?;
    }
    Ok(())
}

fn write_replica_frame(out: &Path, f: &RgbdFrame) -> Result<(), DatasetError> {
    write_rgb_jpeg(
        &frame_path(out, f.index),
        f.width,
        f.height,
        &f.rgb,
        JPEG_QUALITY,
    )?;
    let depth = rescale_depth(&f.depth, f.depth_scale, REPLICA_DEPTH_SCALE);
    write_u16_png(&depth_path(out, f.index), f.width, f.height, &depth)?;
    if let Some(labels) = &f.labels {
        write_u16_png(&label_path(out, f.index), f.width, f.height, labels)?;
    }
    Ok(())
}

/// The per-frame text files, accumulated in frame order.
#[derive(Default)]
struct IndexLines {
    rgb: String,
    depth: String,
    labels: String,
    groundtruth: String,
    traj: String,
}

impl IndexLines {
    fn add(
        &mut self,
        format: DatasetFormat,
        f: &RgbdFrame,
        out: &Path,
    ) -> Result<(), DatasetError> {
        let t = f.timestamp;
        match format {
            DatasetFormat::Tum => {
                self.rgb
                    .push_str(&format!("{t:.6} {}\n", tum_name("rgb", f.index)));
                self.depth
                    .push_str(&format!("{t:.6} {}\n", tum_name("depth", f.index)));
                if f.labels.is_some() {
                    self.labels
                        .push_str(&format!("{t:.6} {}\n", tum_name("labels", f.index)));
                }
                if let Some(p) = &f.gt_pose {
                    self.groundtruth.push_str(&format_tum_line(t, p));
                    self.groundtruth.push('\n');
                }
            }
            DatasetFormat::Replica => {
                let Some(p) = &f.gt_pose else {
                    return Err(DatasetError::invalid(
                        &out.join("traj.txt"),
                        format!(
                            "frame {} has no pose; the Replica layout needs one per frame",
                            f.index
                        ),
                    ));
                };
                let m = p.to_homogeneous();
                // Row-major, shortest round-trip formatting (exact).
                let row: Vec<String> = (0..16)
                    .map(|i| format!("{:e}", m[(i / 4, i % 4)]))
                    .collect();
                self.traj.push_str(&row.join(" "));
                self.traj.push('\n');
            }
            // Written by `write_rosbag2`, not through index files.
            DatasetFormat::Rosbag2 => {}
        }
        Ok(())
    }

    fn write(self, format: DatasetFormat, out: &Path) -> Result<(), DatasetError> {
        match format {
            DatasetFormat::Tum => {
                write_text(
                    &out.join("rgb.txt"),
                    &format!("# timestamp filename\n{}", self.rgb),
                )?;
                write_text(
                    &out.join("depth.txt"),
                    &format!("# timestamp filename\n{}", self.depth),
                )?;
                if !self.labels.is_empty() {
                    write_text(
                        &out.join("labels.txt"),
                        &format!("# timestamp filename\n{}", self.labels),
                    )?;
                }
                write_text(
                    &out.join("groundtruth.txt"),
                    &format!("# timestamp tx ty tz qx qy qz qw\n{}", self.groundtruth),
                )
            }
            DatasetFormat::Replica => write_text(&out.join("traj.txt"), &self.traj),
            DatasetFormat::Rosbag2 => Ok(()),
        }
    }
}
