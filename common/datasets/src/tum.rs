//! TUM RGB-D reader: `rgb.txt`, `depth.txt`, `groundtruth.txt` associated by
//! timestamp, plus our synthetic extras `labels.txt`, `intrinsics.txt`,
//! `classes.json`.

use std::path::{Path, PathBuf};

use opengs_geometry::{Intrinsics, Pose};

use crate::classes::read_class_table;
use crate::image_io::{check_exists, check_image_size, read_rgb, read_u16};
use crate::text::{data_lines, nearest_within, parse_numbers};
use crate::trajectory::parse_tum_trajectory;
use crate::{DatasetError, InstanceClass, RgbdFrame, RgbdSource};

/// Depth units per metre in TUM depth PNGs.
pub const TUM_DEPTH_SCALE: f32 = 5000.0;

#[derive(Debug, Clone, PartialEq)]
pub struct TumOptions {
    /// Largest rgb↔depth (and rgb↔groundtruth/labels) time gap to associate.
    pub max_time_diff: f64,
    /// Overrides `intrinsics.txt` and the per-sequence defaults.
    pub intrinsics: Option<Intrinsics>,
    pub depth_scale: f32,
    /// Nominal frame rate reported to consumers.
    pub frame_rate: f64,
}

impl Default for TumOptions {
    fn default() -> Self {
        Self {
            max_time_diff: 0.08,
            intrinsics: None,
            depth_scale: TUM_DEPTH_SCALE,
            frame_rate: 30.0,
        }
    }
}

/// Calibration of the TUM sensor that recorded a sequence, by directory name.
pub fn tum_intrinsics_for(dir: &Path) -> Intrinsics {
    let name = dir
        .canonicalize()
        .unwrap_or_else(|_| dir.to_path_buf())
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let has = |a: &str, b: &str| name.contains(a) || name.contains(b);
    let (fx, fy, cx, cy) = if has("freiburg1", "fr1") {
        (517.3, 516.5, 318.6, 255.3)
    } else if has("freiburg2", "fr2") {
        (520.9, 521.0, 325.1, 249.7)
    } else if has("freiburg3", "fr3") {
        (535.4, 539.2, 320.1, 247.6)
    } else {
        (525.0, 525.0, 319.5, 239.5)
    };
    Intrinsics::new(fx, fy, cx, cy, 640, 480)
}

/// One associated frame: files and optional ground truth.
#[derive(Debug, Clone)]
struct TumEntry {
    timestamp: f64,
    rgb: PathBuf,
    depth: PathBuf,
    labels: Option<PathBuf>,
    gt_pose: Option<Pose>,
}

pub struct TumSource {
    dir: PathBuf,
    intrinsics: Intrinsics,
    options: TumOptions,
    entries: Vec<TumEntry>,
    classes: Vec<InstanceClass>,
}

/// Parses the text of a `timestamp filename` list read from `path`, file names joined to
/// `dir`, sorted by time.
pub fn parse_file_list(
    text: &str,
    dir: &Path,
    path: &Path,
) -> Result<Vec<(f64, PathBuf)>, DatasetError> {
    let mut list = Vec::new();
    for (line_no, line) in data_lines(text) {
        let mut fields = line.split_whitespace();
        let (Some(t), Some(file)) = (fields.next(), fields.next()) else {
            return Err(DatasetError::parse(
                path,
                line_no,
                "expected 'timestamp filename'",
            ));
        };
        let t = parse_numbers(path, line_no, t)?[0];
        list.push((t, dir.join(file)));
    }
    list.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(list)
}

/// Reads `intrinsics.txt`: `fx fy cx cy width height`.
fn read_intrinsics_file(path: &Path) -> Result<Intrinsics, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
    parse_intrinsics(&text, path)
}

/// Parses the text of an `intrinsics.txt` read from `path`.
pub fn parse_intrinsics(text: &str, path: &Path) -> Result<Intrinsics, DatasetError> {
    let lines = data_lines(text);
    let Some((line_no, line)) = lines.first() else {
        return Err(DatasetError::invalid(
            path,
            "empty, expected 'fx fy cx cy width height'",
        ));
    };
    let v = parse_numbers(path, *line_no, line)?;
    if v.len() != 6 || v[4] < 1.0 || v[5] < 1.0 || v[4].fract() != 0.0 || v[5].fract() != 0.0 {
        return Err(DatasetError::parse(
            path,
            *line_no,
            "expected 'fx fy cx cy width height' with integer width and height",
        ));
    }
    let k = Intrinsics::new(v[0], v[1], v[2], v[3], v[4] as u32, v[5] as u32);
    k.validate()
        .map_err(|e| DatasetError::parse(path, *line_no, e))?;
    Ok(k)
}

/// What a TUM folder's lists say, as read at one moment.
struct TumLists {
    rgb: Vec<(f64, PathBuf)>,
    depth: Vec<(f64, PathBuf)>,
    labels: Vec<(f64, PathBuf)>,
    gt: Vec<(f64, Pose)>,
}

impl TumLists {
    /// Reads the lists; `growing` ignores a last line without its newline (a recorder is
    /// still writing it).
    fn read(dir: &Path, growing: bool) -> Result<Self, DatasetError> {
        // rgb.txt and depth.txt must be there; labels and ground truth are optional.
        let text = |name: &str| -> Result<Option<String>, DatasetError> {
            let path = dir.join(name);
            let required = matches!(name, "rgb.txt" | "depth.txt");
            match std::fs::read_to_string(&path) {
                Ok(t) if growing => Ok(Some(complete_lines(&t).to_string())),
                Ok(t) => Ok(Some(t)),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound && !required => Ok(None),
                Err(e) => Err(DatasetError::io(&path, e)),
            }
        };
        let list = |name: &str| -> Result<Vec<(f64, PathBuf)>, DatasetError> {
            match text(name)? {
                Some(t) => parse_file_list(&t, dir, &dir.join(name)),
                None => Ok(Vec::new()),
            }
        };
        let gt_file = dir.join("groundtruth.txt");
        Ok(Self {
            rgb: list("rgb.txt")?,
            depth: list("depth.txt")?,
            labels: list("labels.txt")?,
            gt: match text("groundtruth.txt")? {
                Some(t) => parse_tum_trajectory(&t, &gt_file)?,
                None => Vec::new(),
            },
        })
    }

    /// Colour frames after `after` (seconds) with a depth frame within `max_dt`, each with
    /// its labels and ground truth when there are some.
    fn associate(&self, max_dt: f64, after: f64) -> Vec<TumEntry> {
        let depth_times: Vec<f64> = self.depth.iter().map(|(t, _)| *t).collect();
        let label_times: Vec<f64> = self.labels.iter().map(|(t, _)| *t).collect();
        let gt_times: Vec<f64> = self.gt.iter().map(|(t, _)| *t).collect();
        self.rgb
            .iter()
            .filter(|(t, _)| *t > after)
            .filter_map(|(t, rgb)| {
                let d = nearest_within(&depth_times, *t, max_dt)?;
                Some(TumEntry {
                    timestamp: *t,
                    rgb: rgb.clone(),
                    depth: self.depth[d].1.clone(),
                    labels: nearest_within(&label_times, *t, max_dt)
                        .map(|i| self.labels[i].1.clone()),
                    gt_pose: nearest_within(&gt_times, *t, max_dt).map(|i| self.gt[i].1),
                })
            })
            .collect()
    }
}

/// `text` up to and including its last newline.
fn complete_lines(text: &str) -> &str {
    text.rfind('\n').map_or("", |i| &text[..=i])
}

impl TumSource {
    pub fn open(dir: &Path, options: TumOptions) -> Result<Self, DatasetError> {
        if !dir.is_dir() {
            return Err(DatasetError::Missing {
                path: dir.to_path_buf(),
            });
        }
        let intrinsics_file = dir.join("intrinsics.txt");
        let intrinsics = match options.intrinsics {
            Some(k) => k,
            None if intrinsics_file.exists() => read_intrinsics_file(&intrinsics_file)?,
            None => tum_intrinsics_for(dir),
        };
        let lists = TumLists::read(dir, false)?;
        for (name, list) in [("rgb.txt", &lists.rgb), ("depth.txt", &lists.depth)] {
            if list.is_empty() {
                return Err(DatasetError::invalid(
                    &dir.join(name),
                    "lists no images (expected 'timestamp filename' lines)",
                ));
            }
        }
        let classes_file = dir.join("classes.json");
        let classes = match classes_file.exists() {
            true => read_class_table(&classes_file)?,
            false => Vec::new(),
        };

        let max_dt = options.max_time_diff;
        let entries = lists.associate(max_dt, f64::NEG_INFINITY);
        if entries.is_empty() {
            return Err(DatasetError::invalid(
                &dir.join("rgb.txt"),
                format!("no colour frame has a depth frame within {max_dt} s (see depth.txt)"),
            ));
        }
        // A missing image found now fails before any stage starts, not mid-run.
        for e in &entries {
            check_entry_files(e)?;
        }
        let camera = match (options.intrinsics.is_some(), intrinsics_file.exists()) {
            (true, _) => "the camera given",
            (false, true) => "intrinsics.txt",
            (false, false) => "the TUM default camera (no intrinsics.txt)",
        };
        check_image_size(&entries[0].rgb, &intrinsics, camera)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            intrinsics,
            options,
            entries,
            classes,
        })
    }
}

/// Every file an entry names exists.
fn check_entry_files(e: &TumEntry) -> Result<(), DatasetError> {
    check_exists(&e.rgb, "rgb.txt")?;
    check_exists(&e.depth, "depth.txt")?;
    if let Some(l) = &e.labels {
        check_exists(l, "labels.txt")?;
    }
    Ok(())
}

impl RgbdSource for TumSource {
    fn name(&self) -> String {
        format!("tum:{}", self.dir.display())
    }

    fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    fn len(&self) -> usize {
        self.entries.len()
    }

    fn frame_rate(&self) -> f64 {
        self.options.frame_rate
    }

    fn frame(&mut self, index: usize) -> Result<RgbdFrame, DatasetError> {
        let e = self.entries.get(index).ok_or(DatasetError::OutOfRange {
            index,
            len: self.entries.len(),
        })?;
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        let labels = match &e.labels {
            Some(p) => Some(read_u16(p, w, h)?),
            None => None,
        };
        Ok(RgbdFrame {
            index,
            timestamp: e.timestamp,
            width: w,
            height: h,
            rgb: read_rgb(&e.rgb, w, h)?,
            depth: read_u16(&e.depth, w, h)?,
            depth_scale: self.options.depth_scale,
            gt_pose: e.gt_pose,
            labels,
        })
    }

    fn class_table(&self) -> Vec<InstanceClass> {
        self.classes.clone()
    }

    /// A recorder appends a frame by writing its images first, then a line to rgb.txt and
    /// depth.txt. A colour frame is taken once a depth frame at or after its time is
    /// listed (so its nearest depth frame is known) and its files exist; frames are
    /// taken in time order, so one not yet complete holds back the ones after it.
    fn refresh(&mut self) -> Result<usize, DatasetError> {
        let last = self
            .entries
            .last()
            .map_or(f64::NEG_INFINITY, |e| e.timestamp);
        let lists = TumLists::read(&self.dir, true)?;
        let newest_depth = lists.depth.last().map_or(f64::NEG_INFINITY, |(t, _)| *t);
        let before = self.entries.len();
        for e in lists.associate(self.options.max_time_diff, last) {
            if e.timestamp > newest_depth || check_entry_files(&e).is_err() {
                break;
            }
            self.entries.push(e);
        }
        Ok(self.entries.len() - before)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intrinsics_by_sequence_name() {
        let k = tum_intrinsics_for(Path::new("/nonexistent/rgbd_dataset_freiburg1_desk"));
        assert_eq!((k.fx, k.cy), (517.3, 255.3));
        let k = tum_intrinsics_for(Path::new("/nonexistent/rgbd_dataset_freiburg2_xyz"));
        assert_eq!((k.fx, k.cx), (520.9, 325.1));
        let k = tum_intrinsics_for(Path::new("fr3_office"));
        assert_eq!((k.fy, k.cx), (539.2, 320.1));
        let k = tum_intrinsics_for(Path::new("/nonexistent/my_scan"));
        assert_eq!((k.fx, k.cx, k.cy), (525.0, 319.5, 239.5));
    }
}
