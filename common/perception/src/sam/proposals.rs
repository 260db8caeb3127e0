//! MobileSAMv2's box proposals: its object-aware model is an ultralytics
//! YOLOv8 export, `images[1,3,S,S] → output0[1,4+nc,N]` (rows cx, cy, w, h
//! in the S frame, then nc class scores; MobileSAMv2 has nc = 1, S = 1024).

use std::path::{Path, PathBuf};

use ort::session::Session;

use super::{model_error, tensor, ModelClock};
use crate::ensemble::{letterbox, nms};
use crate::model_check::{load_checked, session_signature, ModelRole};
use crate::{PerceptionError, SegmenterInput};

/// Input side when the model leaves it dynamic (ultralytics' default).
const DEFAULT_SIDE: usize = 640;

pub struct BoxProposer {
    session: Session,
    path: PathBuf,
    side: usize,
    /// MobileSAMv2's defaults: confidence 0.4, NMS IoU 0.9, at most 320 boxes.
    pub conf: f32,
    pub nms_iou: f32,
    pub max_boxes: usize,
    /// Where the model run's time goes (the segmenter's clock once attached).
    pub(crate) clock: ModelClock,
}

impl BoxProposer {
    pub fn new(path: &Path, threads: usize) -> Result<Self, PerceptionError> {
        let session = load_checked(path, ModelRole::Proposals, threads)?;
        let shape = session_signature(&session).inputs[0].shape.clone();
        if shape[2] > 0 && shape[3] > 0 && shape[2] != shape[3] {
            return Err(model_error(
                path,
                format!("images input {shape:?} is not square"),
            ));
        }
        Ok(Self {
            session,
            path: path.to_path_buf(),
            side: if shape[2] > 0 {
                shape[2] as usize
            } else {
                DEFAULT_SIDE
            },
            conf: 0.4,
            nms_iou: 0.9,
            max_boxes: 320,
            clock: ModelClock::default(),
        })
    }

    /// Object boxes `x0, y0, x1, y1` in image pixels, best first.
    pub fn propose(&mut self, input: &SegmenterInput) -> Result<Vec<[f32; 4]>, PerceptionError> {
        let (w, h) = (input.width as usize, input.height as usize);
        let (image, geometry) = letterbox(input.rgb, w, h, self.side);
        let path = &self.path;
        let inputs = ort::inputs!["images" => tensor(&image, path)?];
        let session = &mut self.session;
        let outputs = self
            .clock
            .time(|| session.run(inputs))
            .map_err(|e| model_error(path, e))?;
        let out = outputs
            .get("output0")
            .ok_or_else(|| model_error(path, "no output named output0"))?
            .try_extract_array::<f32>()
            .map_err(|e| model_error(path, e))?;
        let shape = out.shape().to_vec();
        if shape.len() != 3 || shape[0] != 1 || shape[1] < 5 {
            return Err(model_error(
                path,
                format!("output0 has shape {shape:?}, expected [1, 4+nc, N]"),
            ));
        }
        let mut boxes = Vec::new();
        let mut scores = Vec::new();
        for n in 0..shape[2] {
            let score = (4..shape[1])
                .map(|c| out[[0, c, n]])
                .fold(f32::NEG_INFINITY, f32::max);
            if score.is_nan() || score < self.conf {
                continue;
            }
            let (cx, cy, bw, bh) = (
                out[[0, 0, n]],
                out[[0, 1, n]],
                out[[0, 2, n]],
                out[[0, 3, n]],
            );
            let b = [cx - bw / 2.0, cy - bh / 2.0, cx + bw / 2.0, cy + bh / 2.0];
            if b.iter().all(|v| v.is_finite()) && bw > 0.0 && bh > 0.0 {
                boxes.push(b);
                scores.push(score);
            }
        }
        Ok(nms(&boxes, &scores, self.nms_iou, self.max_boxes)
            .into_iter()
            .map(|i| geometry.to_image(boxes[i]))
            .collect())
    }
}
