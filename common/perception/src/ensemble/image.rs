//! Image preprocessing of the tagger (stretch to a square, ImageNet
//! normalisation) and of the YOLO-family models (letterbox), plus box NMS.

use ndarray::Array4;

/// ImageNet pixel mean/std on [0, 1] values (RAM/RAM++ transform).
pub const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
pub const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];
/// Grey of the letterbox border (ultralytics, YOLO-World).
const PAD_VALUE: f32 = 114.0 / 255.0;

/// Bilinear sample of channel `c` at source position (`sx`, `sy`), in [0, 1].
fn sample(rgb: &[u8], width: usize, height: usize, sx: f32, sy: f32, c: usize) -> f32 {
    let sx = sx.clamp(0.0, (width - 1) as f32);
    let sy = sy.clamp(0.0, (height - 1) as f32);
    let (x0, y0) = (sx.floor() as usize, sy.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(width - 1), (y0 + 1).min(height - 1));
    let (fx, fy) = (sx - x0 as f32, sy - y0 as f32);
    let at = |x: usize, y: usize| rgb[(y * width + x) * 3 + c] as f32;
    let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
    let bottom = at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx;
    (top * (1.0 - fy) + bottom * fy) / 255.0
}

/// Resizes into `out[0, :, top.., left..]` (`new_w` × `new_h`), mapping each
/// value through `f(channel, value in [0, 1])`.
#[allow(clippy::too_many_arguments)]
fn resize_into(
    rgb: &[u8],
    width: usize,
    height: usize,
    out: &mut Array4<f32>,
    (left, top): (usize, usize),
    (new_w, new_h): (usize, usize),
    f: impl Fn(usize, f32) -> f32,
) {
    let (kx, ky) = (width as f32 / new_w as f32, height as f32 / new_h as f32);
    for y in 0..new_h {
        let sy = (y as f32 + 0.5) * ky - 0.5;
        for x in 0..new_w {
            let sx = (x as f32 + 0.5) * kx - 0.5;
            for c in 0..3 {
                out[[0, c, top + y, left + x]] = f(c, sample(rgb, width, height, sx, sy, c));
            }
        }
    }
}

/// RAM/RAM++ input: stretched to `out_w` × `out_h`, ImageNet-normalised.
pub fn stretch_normalised(
    rgb: &[u8],
    width: usize,
    height: usize,
    out_w: usize,
    out_h: usize,
) -> Array4<f32> {
    let mut out = Array4::<f32>::zeros((1, 3, out_h, out_w));
    resize_into(
        rgb,
        width,
        height,
        &mut out,
        (0, 0),
        (out_w, out_h),
        |c, v| (v - IMAGENET_MEAN[c]) / IMAGENET_STD[c],
    );
    out
}

/// Where the image lies in a letterboxed model input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Letterbox {
    /// Model pixels per image pixel, per axis.
    pub scale: [f32; 2],
    /// Border left of and above the image, model pixels.
    pub offset: [f32; 2],
    pub width: u32,
    pub height: u32,
}

impl Letterbox {
    /// A model-frame box `x0, y0, x1, y1` in image pixels, clipped to the image.
    pub fn to_image(&self, b: [f32; 4]) -> [f32; 4] {
        let x = |v: f32| ((v - self.offset[0]) / self.scale[0]).clamp(0.0, self.width as f32);
        let y = |v: f32| ((v - self.offset[1]) / self.scale[1]).clamp(0.0, self.height as f32);
        [x(b[0]), y(b[1]), x(b[2]), y(b[3])]
    }
}

/// YOLO input: longest side scaled to `side`, centred on a grey square, [0, 1].
pub fn letterbox(rgb: &[u8], width: usize, height: usize, side: usize) -> (Array4<f32>, Letterbox) {
    let scale = side as f32 / width.max(height) as f32;
    let new_w = ((width as f32 * scale).round() as usize).clamp(1, side);
    let new_h = ((height as f32 * scale).round() as usize).clamp(1, side);
    let (left, top) = ((side - new_w) / 2, (side - new_h) / 2);
    let mut out = Array4::<f32>::from_elem((1, 3, side, side), PAD_VALUE);
    resize_into(
        rgb,
        width,
        height,
        &mut out,
        (left, top),
        (new_w, new_h),
        |_, v| v,
    );
    let geometry = Letterbox {
        scale: [new_w as f32 / width as f32, new_h as f32 / height as f32],
        offset: [left as f32, top as f32],
        width: width as u32,
        height: height as u32,
    };
    (out, geometry)
}

/// IoU of two `x0, y0, x1, y1` boxes.
pub fn box_iou(a: [f32; 4], b: [f32; 4]) -> f32 {
    let iw = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let ih = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = iw * ih;
    let area = |r: [f32; 4]| (r[2] - r[0]).max(0.0) * (r[3] - r[1]).max(0.0);
    let union = area(a) + area(b) - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// Greedy NMS: indices of the kept boxes, best score first.
pub fn nms(boxes: &[[f32; 4]], scores: &[f32], iou_thresh: f32, max_keep: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..boxes.len().min(scores.len())).collect();
    order.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]));
    let mut kept: Vec<usize> = Vec::new();
    for i in order {
        if kept.len() >= max_keep {
            break;
        }
        if kept
            .iter()
            .all(|&k| box_iou(boxes[k], boxes[i]) <= iou_thresh)
        {
            kept.push(i);
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn letterbox_centres_and_maps_boxes_back() {
        let (w, h) = (160, 120);
        let rgb = vec![255u8; w * h * 3];
        let (t, lb) = letterbox(&rgb, w, h, 640);
        assert_eq!(t.shape(), &[1, 3, 640, 640]);
        assert_eq!(lb.offset, [0.0, 80.0]);
        assert_eq!(lb.scale, [4.0, 4.0]);
        assert!((t[[0, 0, 79, 10]] - PAD_VALUE).abs() < 1e-6, "border");
        assert!((t[[0, 0, 80, 10]] - 1.0).abs() < 1e-6, "image");
        assert!(
            (t[[0, 2, 559, 639]] - 1.0).abs() < 1e-6
                && (t[[0, 2, 560, 0]] - PAD_VALUE).abs() < 1e-6
        );
        assert_eq!(
            lb.to_image([80.0, 200.0, 240.0, 360.0]),
            [20.0, 30.0, 60.0, 70.0]
        );
        assert_eq!(
            lb.to_image([-10.0, 0.0, 700.0, 640.0]),
            [0.0, 0.0, 160.0, 120.0]
        );
    }

    #[test]
    fn stretch_normalises_with_imagenet_statistics() {
        let t = stretch_normalised(&[255, 0, 128].repeat(6), 3, 2, 4, 4);
        assert_eq!(t.shape(), &[1, 3, 4, 4]);
        assert!((t[[0, 0, 3, 3]] - (1.0 - 0.485) / 0.229).abs() < 1e-5);
        assert!((t[[0, 1, 0, 0]] - (-0.456 / 0.224)).abs() < 1e-5);
    }

    #[test]
    fn nms_keeps_the_best_of_overlapping_boxes() {
        let boxes = [
            [0.0, 0.0, 10.0, 10.0],
            [0.0, 0.0, 10.0, 9.0],
            [20.0, 20.0, 30.0, 30.0],
        ];
        assert!((box_iou(boxes[0], boxes[1]) - 0.9).abs() < 1e-6);
        assert_eq!(nms(&boxes, &[0.5, 0.9, 0.7], 0.7, 10), vec![1, 2]);
        assert_eq!(nms(&boxes, &[0.5, 0.9, 0.7], 0.95, 10), vec![1, 2, 0]);
        assert_eq!(nms(&boxes, &[0.5, 0.9, 0.7], 0.95, 1), vec![1]);
    }
}
