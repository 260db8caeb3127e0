//! Ground-truth "prior" segmenter: the dataset's instance image as-is.

use std::collections::{BTreeSet, HashMap};

use crate::{PerceptionError, SegmentInfo, Segmentation, Segmenter, SegmenterInput};

/// Returns the dataset's instance labels with their class names (score 1).
#[derive(Debug, Default, Clone)]
pub struct PriorSegmenter;

impl PriorSegmenter {
    pub fn new() -> Self {
        Self
    }
}

impl Segmenter for PriorSegmenter {
    fn name(&self) -> &str {
        "prior"
    }

    fn segment(&mut self, input: &SegmenterInput) -> Result<Segmentation, PerceptionError> {
        input.validate()?;
        let gt = input.gt_labels.ok_or(PerceptionError::MissingLabels)?;
        let class_of: HashMap<u16, &str> = input
            .classes
            .iter()
            .map(|c| (c.id, c.class.as_str()))
            .collect();
        let present: BTreeSet<u16> = gt.iter().copied().filter(|&id| id != 0).collect();
        let labels = present
            .into_iter()
            .map(|id| {
                let class = class_of.get(&id).map(|c| c.to_string());
                // An id missing from the class table is an unclassified instance.
                let score = if class.is_some() { 1.0 } else { 0.0 };
                SegmentInfo {
                    label: id as u32,
                    confidence: 1.0,
                    class,
                    score,
                }
            })
            .collect();
        Ok(Segmentation {
            width: input.width,
            height: input.height,
            label_map: gt.iter().map(|&id| id as u32).collect(),
            labels,
        })
    }
}
