//! The paper's point and box prompts, answered by GS Voting on a render of the view
//! (docs/METHOD.md §3):
//!
//! ```text
//! pixel (u, v):  W_ℓ = Σ α_i T_i over the Gaussians i of label ℓ that composite onto (u, v)
//!                answer = the renderer's voted label: argmax W_ℓ over ℓ ≠ 0 (ties: smaller ℓ)
//! box B:         n_ℓ = voted pixels of ℓ inside B,  N_ℓ = voted pixels of ℓ in the view
//!                ℓ dominates B when  n_ℓ / |B| ≥ 1/2              it fills the box
//!                                or  n_ℓ / N_ℓ ≥ 1/2 and n_ℓ / |B| ≥ 1/10
//!                                                                 the box holds most of it, and it is no sliver
//! ```
//!
//! The second rule is what a box drawn around an object means: the wall behind a cup fills
//! part of the box but lies mostly outside it, the cup mostly inside.

use std::collections::BTreeMap;

use opengs_splat::{GaussianMap, Rendered};
use serde::Serialize;

use crate::error::{ObjectError, Result};

/// A label dominating the box by filling at least this share of it.
const FILLS_BOX: f64 = 0.5;
/// ... or by lying mostly inside the box, and covering at least `MIN_SHARE` of it.
const MOSTLY_INSIDE: f64 = 0.5;
const MIN_SHARE: f64 = 0.1;

/// One label's summed voting weight at a pixel.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LabelWeight {
    pub label: u32,
    pub weight: f32,
}

/// The answer to a point prompt.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PixelPick {
    pub u: u32,
    pub v: u32,
    /// The GS Voting winner.
    pub label: u32,
    /// Its summed weight Σ α T.
    pub weight: f32,
    /// Accumulated opacity of the pixel (every label's weight, background included).
    pub alpha: f32,
    /// Every label seen at the pixel, heaviest first (label 0: unlabelled Gaussians).
    pub votes: Vec<LabelWeight>,
}

/// Answers a point prompt from a render of `map` made with labels on.
pub fn pick_pixel(map: &GaussianMap, rendered: &Rendered, u: u32, v: u32) -> Result<PixelPick> {
    let (width, height) = (rendered.output.width, rendered.output.height);
    if u >= width || v >= height {
        return Err(ObjectError::PixelOutside {
            u,
            v,
            width,
            height,
        });
    }
    let mut sums: BTreeMap<u32, f32> = BTreeMap::new();
    for (id, weight) in rendered.pixel_contributions(u, v) {
        *sums.entry(map.labels[id as usize]).or_default() += weight;
    }
    let mut votes: Vec<LabelWeight> = sums
        .into_iter()
        .map(|(label, weight)| LabelWeight { label, weight })
        .collect();
    votes.sort_by(|a, b| b.weight.total_cmp(&a.weight).then(a.label.cmp(&b.label)));
    let voted = match &rendered.output.labels {
        Some(labels) => labels[rendered.output.index(u, v)],
        None => votes.iter().find(|w| w.label != 0).map_or(0, |w| w.label),
    };
    if voted == 0 {
        return Err(ObjectError::EmptySelection(format!(
            "no labelled Gaussian at pixel ({u}, {v}) of the view"
        )));
    }
    Ok(PixelPick {
        u,
        v,
        label: voted,
        weight: votes
            .iter()
            .find(|w| w.label == voted)
            .map_or(0.0, |w| w.weight),
        alpha: votes.iter().map(|w| w.weight).sum(),
        votes,
    })
}

/// A box of pixels, corners included.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct PixelBox {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl PixelBox {
    fn bad(&self, reason: String) -> ObjectError {
        ObjectError::BadBox {
            x0: self.x0,
            y0: self.y0,
            x1: self.x1,
            y1: self.y1,
            reason,
        }
    }

    /// Fails unless the box is ordered and inside a `width × height` image.
    pub fn check(&self, width: u32, height: u32) -> Result<()> {
        if self.x0 > self.x1 || self.y0 > self.y1 {
            return Err(self.bad("needs x0 ≤ x1 and y0 ≤ y1".into()));
        }
        if self.x1 >= width || self.y1 >= height {
            return Err(self.bad(format!("reaches outside the {width}x{height} image")));
        }
        Ok(())
    }

    pub fn pixels(&self) -> u64 {
        u64::from(self.x1 - self.x0 + 1) * u64::from(self.y1 - self.y0 + 1)
    }

    pub fn contains(&self, x: u32, y: u32) -> bool {
        (self.x0..=self.x1).contains(&x) && (self.y0..=self.y1).contains(&y)
    }
}

/// One label's voted pixels in and around a box.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BoxVote {
    pub label: u32,
    pub pixels_in_box: u64,
    pub pixels_in_view: u64,
    /// `pixels_in_box / |B|`.
    pub share_of_box: f64,
    /// `pixels_in_box / pixels_in_view`.
    pub inside: f64,
    pub dominates: bool,
}

/// The answer to a box prompt: every label voted inside the box, most pixels first.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoxPick {
    pub rect: PixelBox,
    pub votes: Vec<BoxVote>,
}

impl BoxPick {
    /// The labels that dominate the box; an error when none does.
    pub fn selected(&self) -> Result<Vec<u32>> {
        let labels: Vec<u32> = self
            .votes
            .iter()
            .filter(|v| v.dominates)
            .map(|v| v.label)
            .collect();
        if labels.is_empty() {
            let r = self.rect;
            let best = self.votes.first().map_or("nothing is labelled there".to_string(), |v| {
                format!(
                    "most pixels: label {} with {:.0} % of the box and {:.0} % of its pixels inside",
                    v.label,
                    100.0 * v.share_of_box,
                    100.0 * v.inside
                )
            });
            return Err(ObjectError::EmptySelection(format!(
                "no label dominates box {},{},{},{} ({best})",
                r.x0, r.y0, r.x1, r.y1
            )));
        }
        Ok(labels)
    }
}

/// Answers a box prompt from a voted label image (`width × height`, row-major, 0 = none).
pub fn pick_box(labels: &[u32], width: u32, height: u32, rect: PixelBox) -> Result<BoxPick> {
    rect.check(width, height)?;
    let mut counts: BTreeMap<u32, (u64, u64)> = BTreeMap::new();
    for (i, &label) in labels.iter().enumerate() {
        if label == 0 {
            continue;
        }
        let (x, y) = (i as u32 % width, i as u32 / width);
        let entry = counts.entry(label).or_default();
        entry.1 += 1;
        if rect.contains(x, y) {
            entry.0 += 1;
        }
    }
    let area = rect.pixels() as f64;
    let mut votes: Vec<BoxVote> = counts
        .into_iter()
        .filter(|(_, (inside, _))| *inside > 0)
        .map(|(label, (in_box, in_view))| {
            let share_of_box = in_box as f64 / area;
            let inside = in_box as f64 / in_view as f64;
            BoxVote {
                label,
                pixels_in_box: in_box,
                pixels_in_view: in_view,
                share_of_box,
                inside,
                dominates: share_of_box >= FILLS_BOX
                    || (inside >= MOSTLY_INSIDE && share_of_box >= MIN_SHARE),
            }
        })
        .collect();
    votes.sort_by(|a, b| {
        b.pixels_in_box
            .cmp(&a.pixels_in_box)
            .then(a.label.cmp(&b.label))
    });
    Ok(BoxPick { rect, votes })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(x0: u32, y0: u32, x1: u32, y1: u32) -> PixelBox {
        PixelBox { x0, y0, x1, y1 }
    }

    #[test]
    fn box_around_an_object_picks_it_not_the_wall_behind() {
        // 10x10 view: wall (1) everywhere, object (2) at x, y in 3..=5, a sliver (3) at (0, 0).
        let (w, h) = (10u32, 10u32);
        let mut labels = vec![1u32; 100];
        for y in 3..=5 {
            for x in 3..=5 {
                labels[y * 10 + x] = 2;
            }
        }
        labels[0] = 3;
        let around = rect(3, 3, 6, 6);
        let pick = pick_box(&labels, w, h, around).expect("box inside");
        assert_eq!(pick.selected().expect("one dominates"), vec![2]);
        // The wall: 7 of the 16 box pixels, 7 of its 90 in the view.
        let wall = pick
            .votes
            .iter()
            .find(|v| v.label == 1)
            .expect("wall in box");
        assert_eq!((wall.pixels_in_box, wall.pixels_in_view), (7, 90));
        assert!((wall.share_of_box - 7.0 / 16.0).abs() < 1e-12);
        assert!(!wall.dominates);
        // The whole view: the wall fills it; the object (9 %) and the sliver (1 %) are too small;
        // the sliver's own pixel: it fills that.
        let chosen = |r| {
            pick_box(&labels, w, h, r)
                .expect("inside")
                .selected()
                .expect("a label")
        };
        assert_eq!(chosen(rect(0, 0, 9, 9)), vec![1]);
        assert_eq!(chosen(rect(0, 0, 0, 0)), vec![3]);
    }

    #[test]
    fn bad_boxes_are_named() {
        let labels = vec![1u32; 100];
        let err = pick_box(&labels, 10, 10, rect(5, 0, 2, 3)).expect_err("reversed");
        assert!(err.to_string().contains("5,0,2,3"), "{err}");
        let err = pick_box(&labels, 10, 10, rect(0, 0, 10, 3)).expect_err("outside");
        assert!(err.to_string().contains("10x10"), "{err}");
        let empty = pick_box(&[0u32; 100], 10, 10, rect(0, 0, 3, 3)).expect("ok");
        assert!(empty.selected().is_err());
    }
}
