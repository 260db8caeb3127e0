use opengs_geometry::{Intrinsics, Pose};

use crate::DatasetError;

/// One RGB-D frame as published by the sensor stage: plain owned buffers,
/// depth kept as u16 so a 640x480 frame stays ~1.5 MB.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbdFrame {
    pub index: usize,
    /// Capture time in seconds.
    pub timestamp: f64,
    pub width: u32,
    pub height: u32,
    /// Row-major RGB8, `width * height * 3` bytes.
    pub rgb: Vec<u8>,
    /// Row-major depth; 0 = missing; metres = value / depth_scale.
    pub depth: Vec<u16>,
    /// Depth units per metre (TUM 5000, Replica 6553.5).
    pub depth_scale: f32,
    /// Ground-truth camera-to-world pose when the dataset has one.
    pub gt_pose: Option<Pose>,
    /// Instance id per pixel (0 = none) when the dataset has labels.
    pub labels: Option<Vec<u16>>,
}

impl RgbdFrame {
    /// Metric depth of pixel (u, v); `None` where depth is missing.
    pub fn depth_m(&self, u: u32, v: u32) -> Option<f32> {
        let d = *self.depth.get((v * self.width + u) as usize)?;
        (d != 0).then(|| d as f32 / self.depth_scale)
    }

    /// Instance labels where the frame has depth, 0 (not scored) elsewhere: what the sensor
    /// never measured (Kinect-like depth ends at 4 m) no segmenter or map can know; render
    /// quality is scored on valid depth only too. A depth image of another size masks nothing.
    pub fn labels_where_measured(&self) -> Option<Vec<u16>> {
        let labels = self.labels.as_ref()?;
        if self.depth.len() != labels.len() {
            return Some(labels.clone());
        }
        Some(
            labels
                .iter()
                .zip(&self.depth)
                .map(|(&l, &d)| if d == 0 { 0 } else { l })
                .collect(),
        )
    }

    /// Depth in metres, 0 where missing.
    pub fn depth_metres(&self) -> Vec<f32> {
        let k = 1.0 / self.depth_scale;
        self.depth.iter().map(|&d| d as f32 * k).collect()
    }

    /// Checks that the buffers match the frame's size and the camera's (frames are external
    /// input); the error says what does not match.
    pub fn check_buffers(&self, intrinsics: &Intrinsics) -> Result<(), String> {
        let (w, h) = (self.width, self.height);
        if (w, h) != (intrinsics.width, intrinsics.height) {
            return Err(format!(
                "image is {w}x{h} but the camera is {}x{}",
                intrinsics.width, intrinsics.height
            ));
        }
        let n = w as usize * h as usize;
        if self.rgb.len() != 3 * n || self.depth.len() != n {
            return Err(format!(
                "{} RGB bytes and {} depth values for {w}x{h}",
                self.rgb.len(),
                self.depth.len()
            ));
        }
        if !(self.depth_scale.is_finite() && self.depth_scale > 0.0) {
            return Err(format!("depth scale {} ≤ 0", self.depth_scale));
        }
        Ok(())
    }
}

/// Instance id → class name entry of a dataset's ground-truth class table.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct InstanceClass {
    pub id: u16,
    pub class: String,
}

/// A random-access RGB-D dataset (file reader or generator).
pub trait RgbdSource: Send {
    fn name(&self) -> String;
    fn intrinsics(&self) -> Intrinsics;
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Nominal frames per second (for pacing a live-like replay).
    fn frame_rate(&self) -> f64;
    fn frame(&mut self, index: usize) -> Result<RgbdFrame, DatasetError>;
    /// Instance id → class name; empty when the dataset has no labels.
    fn class_table(&self) -> Vec<InstanceClass>;
    /// Looks for frames a recorder appended since the source was opened (`opengs run
    /// --live`); `len()` grows by the number returned. Sources that cannot grow find none.
    fn refresh(&mut self) -> Result<usize, DatasetError> {
        Ok(0)
    }
}
