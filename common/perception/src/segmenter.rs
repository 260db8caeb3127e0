//! The segmenter interface shared by the geometry, classic, prior and model-based back-ends.

use opengs_datasets::{InstanceClass, RgbdFrame};
use opengs_geometry::Intrinsics;

use crate::{PerceptionError, Segmentation};

/// One RGB-D frame as seen by a segmenter; borrows the caller's buffers.
#[derive(Clone, Copy)]
pub struct SegmenterInput<'a> {
    pub width: u32,
    pub height: u32,
    /// Row-major RGB8, `width * height * 3` bytes.
    pub rgb: &'a [u8],
    /// Row-major depth, 0 = missing; metres = value / `depth_scale`.
    pub depth: &'a [u16],
    /// Depth units per metre.
    pub depth_scale: f32,
    /// Camera of this frame; its size must equal `width` × `height`.
    pub intrinsics: Intrinsics,
    /// Ground-truth instance id per pixel (0 = none), when the dataset has it.
    pub gt_labels: Option<&'a [u16]>,
    /// Ground-truth instance id → class name.
    pub classes: &'a [InstanceClass],
}

impl<'a> SegmenterInput<'a> {
    /// Borrows a dataset frame together with its camera and class table.
    pub fn from_frame(
        frame: &'a RgbdFrame,
        intrinsics: Intrinsics,
        classes: &'a [InstanceClass],
    ) -> Self {
        Self {
            width: frame.width,
            height: frame.height,
            rgb: &frame.rgb,
            depth: &frame.depth,
            depth_scale: frame.depth_scale,
            intrinsics,
            gt_labels: frame.labels.as_deref(),
            classes,
        }
    }

    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Checks that every buffer matches the frame size and the camera is usable.
    pub fn validate(&self) -> Result<(), PerceptionError> {
        let n = self.pixel_count();
        if n == 0 {
            return Err(PerceptionError::InvalidInput("empty frame".into()));
        }
        let check = |what, expected: usize, got: usize| {
            if expected == got {
                Ok(())
            } else {
                Err(PerceptionError::InputSize {
                    what,
                    expected,
                    got,
                })
            }
        };
        check("rgb", n * 3, self.rgb.len())?;
        check("depth", n, self.depth.len())?;
        if let Some(labels) = self.gt_labels {
            check("gt_labels", n, labels.len())?;
        }
        let k = &self.intrinsics;
        if (k.width, k.height) != (self.width, self.height) {
            return Err(PerceptionError::InvalidInput(format!(
                "intrinsics are for {}x{}, frame is {}x{}",
                k.width, k.height, self.width, self.height
            )));
        }
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if !positive(k.fx) || !positive(k.fy) || !k.cx.is_finite() || !k.cy.is_finite() {
            return Err(PerceptionError::InvalidInput(
                "focal lengths must be positive and finite".into(),
            ));
        }
        if !(self.depth_scale.is_finite() && self.depth_scale > 0.0) {
            return Err(PerceptionError::InvalidInput(format!(
                "depth scale must be positive, got {}",
                self.depth_scale
            )));
        }
        Ok(())
    }
}

impl std::fmt::Debug for SegmenterInput<'_> {
    // Buffer lengths only: a 640×480 frame would print a million numbers.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SegmenterInput")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("rgb_len", &self.rgb.len())
            .field("depth_len", &self.depth.len())
            .field("depth_scale", &self.depth_scale)
            .field("intrinsics", &self.intrinsics)
            .field("gt_labels_len", &self.gt_labels.map(<[u16]>::len))
            .field("classes", &self.classes.len())
            .finish()
    }
}

/// A per-frame instance segmenter (class-agnostic or with classes).
pub trait Segmenter: Send {
    fn name(&self) -> &str;
    fn segment(&mut self, input: &SegmenterInput) -> Result<Segmentation, PerceptionError>;
}
