//! Before/after picture of an edit seen from one camera:
//!
//! ```text
//! ┌──────────────┬──────────────┐   magenta: outline of the object's voted pixels before the edit
//! │ colour before│ colour after │            (drawn on all four panels: where it was)
//! ├──────────────┼──────────────┤   yellow:  outline of its voted pixels after the edit (where it is)
//! │ labels before│ labels after │
//! └──────────────┴──────────────┘
//! ```
//!
//! With the picture come the counts that say what the edit did to the view: the object's
//! pixels before and after, and what its former pixels show now (another label, unlabelled
//! Gaussians, or nothing: accumulated α below ½).

use std::collections::BTreeMap;

use image::{Rgb, RgbImage};
use opengs_splat::{label_color, render, Camera, GaussianMap, RenderOutput, RenderRequest};
use serde::Serialize;

use crate::selection::Selection;

const WAS: [u8; 3] = [255, 0, 255];
const IS: [u8; 3] = [255, 230, 0];
const GAP: u32 = 4;
const GAP_COLOUR: [u8; 3] = [40, 40, 40];
/// A pixel whose accumulated α is below this shows (mostly) nothing.
const EMPTY_ALPHA: f32 = 0.5;

/// What the edit changed in the view, in pixels.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct EditEffect {
    /// Pixels voted to the selected labels before the edit.
    pub before: u64,
    /// ... and after it.
    pub after: u64,
    /// Of the `before` pixels: now voted to another label.
    pub former_now_other_label: u64,
    /// ... which labels, with their pixels, most first.
    pub former_now_labels: Vec<(u32, u64)>,
    /// Of the `before` pixels: now covered by unlabelled Gaussians only.
    pub former_now_unlabelled: u64,
    /// Of the `before` pixels: now nearly empty (α < ½).
    pub former_now_empty: u64,
}

/// The picture and the counts.
#[derive(Debug, Clone)]
pub struct EditComparison {
    pub image: RgbImage,
    pub effect: EditEffect,
    pub before: RenderOutput,
    pub after: RenderOutput,
}

/// Renders `before` and `after` from `camera` and composes the picture (module doc).
pub fn compare_edit(
    before: &GaussianMap,
    after: &GaussianMap,
    camera: &Camera,
    selection: &Selection,
) -> EditComparison {
    let request = RenderRequest {
        labels: true,
        ..RenderRequest::color_depth()
    };
    let before = render(before, camera, &request).output;
    let after = render(after, camera, &request).output;
    let was = object_mask(&before, selection);
    let is = object_mask(&after, selection);
    let effect = effect_of(&after, &was, &is);
    let (w, h) = (before.width, before.height);
    let mut image = RgbImage::from_pixel(2 * w + GAP, 2 * h + GAP, Rgb(GAP_COLOUR));
    for (column, out) in [&before, &after].into_iter().enumerate() {
        let x0 = column as u32 * (w + GAP);
        paint(&mut image, x0, 0, out, |i| colour_of(out, i));
        paint(&mut image, x0, h + GAP, out, |i| {
            label_color(out.labels.as_ref().map_or(0, |l| l[i]))
        });
        for y0 in [0, h + GAP] {
            draw_outline(&mut image, x0, y0, w, h, &was, WAS);
            if column == 1 {
                draw_outline(&mut image, x0, y0, w, h, &is, IS);
            }
        }
    }
    EditComparison {
        image,
        effect,
        before,
        after,
    }
}

/// Per pixel: is it voted to one of the selected labels.
fn object_mask(out: &RenderOutput, selection: &Selection) -> Vec<bool> {
    match &out.labels {
        Some(labels) => labels.iter().map(|&l| selection.contains(l)).collect(),
        None => vec![false; (out.width * out.height) as usize],
    }
}

fn effect_of(after: &RenderOutput, was: &[bool], is: &[bool]) -> EditEffect {
    let count = |m: &[bool]| m.iter().filter(|&&b| b).count() as u64;
    let mut effect = EditEffect {
        before: count(was),
        after: count(is),
        former_now_other_label: 0,
        former_now_labels: Vec::new(),
        former_now_unlabelled: 0,
        former_now_empty: 0,
    };
    let labels = after.labels.as_deref().unwrap_or(&[]);
    let mut now: BTreeMap<u32, u64> = BTreeMap::new();
    for (i, _) in was.iter().enumerate().filter(|(_, &w)| w) {
        let label = labels.get(i).copied().unwrap_or(0);
        if is[i] {
            continue;
        } else if after.silhouette[i] < EMPTY_ALPHA {
            effect.former_now_empty += 1;
        } else if label == 0 {
            effect.former_now_unlabelled += 1;
        } else {
            effect.former_now_other_label += 1;
            *now.entry(label).or_default() += 1;
        }
    }
    effect.former_now_labels = now.into_iter().collect();
    effect
        .former_now_labels
        .sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    effect
}

fn colour_of(out: &RenderOutput, i: usize) -> [u8; 3] {
    out.color[i].map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8)
}

fn paint(
    image: &mut RgbImage,
    x0: u32,
    y0: u32,
    out: &RenderOutput,
    pixel: impl Fn(usize) -> [u8; 3],
) {
    for y in 0..out.height {
        for x in 0..out.width {
            image.put_pixel(x0 + x, y0 + y, Rgb(pixel(out.index(x, y))));
        }
    }
}

/// Marks the mask's boundary pixels (a 4-neighbour outside it), two pixels wide so it shows.
fn draw_outline(
    image: &mut RgbImage,
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
    mask: &[bool],
    colour: [u8; 3],
) {
    let inside = |x: i64, y: i64| {
        x >= 0
            && y >= 0
            && x < i64::from(w)
            && y < i64::from(h)
            && mask[(y * i64::from(w) + x) as usize]
    };
    for y in 0..i64::from(h) {
        for x in 0..i64::from(w) {
            let edge = inside(x, y)
                && !(inside(x - 1, y) && inside(x + 1, y) && inside(x, y - 1) && inside(x, y + 1));
            if !edge {
                continue;
            }
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (px, py) = (x + dx, y + dy);
                if px < i64::from(w) && py < i64::from(h) {
                    image.put_pixel(x0 + px as u32, y0 + py as u32, Rgb(colour));
                }
            }
        }
    }
}
