//! Caps a source at N frames (`--frames`), whatever kind it is.

use opengs_geometry::Intrinsics;

use crate::{DatasetError, InstanceClass, RgbdFrame, RgbdSource};

pub struct FrameLimit {
    inner: Box<dyn RgbdSource>,
    limit: usize,
}

impl FrameLimit {
    pub fn new(inner: Box<dyn RgbdSource>, limit: usize) -> Self {
        Self { inner, limit }
    }
}

impl RgbdSource for FrameLimit {
    fn name(&self) -> String {
        self.inner.name()
    }
    fn intrinsics(&self) -> Intrinsics {
        self.inner.intrinsics()
    }
    fn len(&self) -> usize {
        self.inner.len().min(self.limit)
    }
    fn frame_rate(&self) -> f64 {
        self.inner.frame_rate()
    }
    fn frame(&mut self, index: usize) -> Result<RgbdFrame, DatasetError> {
        if index >= self.len() {
            return Err(DatasetError::OutOfRange {
                index,
                len: self.len(),
            });
        }
        self.inner.frame(index)
    }
    fn class_table(&self) -> Vec<InstanceClass> {
        self.inner.class_table()
    }
    fn refresh(&mut self) -> Result<usize, DatasetError> {
        let before = self.len();
        self.inner.refresh()?;
        Ok(self.len() - before)
    }
}
