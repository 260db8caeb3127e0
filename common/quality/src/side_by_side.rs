//! `render_XXXXXX.png`: input | render | rendered depth | |error| heat-map, side by side.

use std::path::Path;

use image::{ImageBuffer, Rgb};
use opengs_datasets::RgbdFrame;
use opengs_splat::RenderOutput;

use crate::colormap::{depth_color, error_color};
use crate::QualityError;

/// Mean |error| over the channels that saturates the heat-map.
const ERROR_FULL_SCALE: f32 = 0.25;
/// Rendered depth is shown only where the render is this opaque.
const MIN_SILHOUETTE: f32 = 0.5;
/// Pixels with nothing to show (no depth, masked).
const EMPTY: [u8; 3] = [32, 32, 32];

/// Writes the four panels of one frame into `path` (4·W × H). Depth shares one scale with
/// the input's valid depth range; the error panel is dark where `valid` is false.
pub fn write_side_by_side_png(
    path: &Path,
    frame: &RgbdFrame,
    render: &RenderOutput,
    valid: &[bool],
) -> Result<(), QualityError> {
    let (w, h) = (frame.width, frame.height);
    let at = |x: u32, y: u32| (y * w + x) as usize;
    let (near, far) = depth_range(frame);
    let image = ImageBuffer::<Rgb<u8>, Vec<u8>>::from_fn(4 * w, h, |x, y| {
        let i = at(x % w, y);
        let input = [0, 1, 2].map(|c| frame.rgb[3 * i + c]);
        Rgb(match x / w {
            0 => input,
            1 => render.color[i].map(to_u8),
            2 => {
                let s = render.silhouette[i];
                if s < MIN_SILHOUETTE {
                    EMPTY
                } else {
                    depth_color((render.depth[i] / s - near) / (far - near))
                }
            }
            _ if !valid[i] => EMPTY,
            _ => {
                let err: f32 = (0..3)
                    .map(|c| (render.color[i][c].clamp(0.0, 1.0) - input[c] as f32 / 255.0).abs())
                    .sum::<f32>()
                    / 3.0;
                error_color(err / ERROR_FULL_SCALE)
            }
        })
    });
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|error| QualityError::Io {
            path: dir.to_path_buf(),
            error,
        })?;
    }
    image.save(path).map_err(|error| QualityError::Image {
        path: path.to_path_buf(),
        error,
    })
}

/// Min and max valid input depth in metres (a 1 m span when there is none).
fn depth_range(frame: &RgbdFrame) -> (f32, f32) {
    let (lo, hi) = frame
        .depth
        .iter()
        .filter(|&&d| d != 0)
        .fold((u16::MAX, 0u16), |(lo, hi), &d| (lo.min(d), hi.max(d)));
    if hi == 0 || hi <= lo {
        return (0.0, 1.0_f32.max(hi as f32 / frame.depth_scale));
    }
    (lo as f32 / frame.depth_scale, hi as f32 / frame.depth_scale)
}

fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}
