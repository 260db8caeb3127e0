//! Input confidence update (docs/METHOD.md §5.2): C_s ← mean over ℓs's pixels of Cov_r(p)·C_s.

use std::collections::BTreeMap;

use crate::intersection::Overlap;

/// Updated C_s of every non-zero input label. Cov_r is the completeness of the pixel's rendered
/// label (1 where it is 0), so the mean is C_s · Σ_r I(ℓs, ℓr)·cov(ℓr) / |ℓs| — no pixel pass.
pub fn update_input_confidence(
    overlap: &Overlap,
    confidence: &BTreeMap<u32, f32>,
    completeness: &BTreeMap<u32, f32>,
) -> BTreeMap<u32, f32> {
    let mut weighted: BTreeMap<u32, f64> = BTreeMap::new();
    for (&(s, r), &n) in &overlap.pairs {
        if s == 0 {
            continue;
        }
        let cov = if r == 0 {
            1.0
        } else {
            completeness.get(&r).copied().map_or(1.0, f64::from)
        };
        *weighted.entry(s).or_insert(0.0) += f64::from(n) * cov;
    }
    confidence
        .iter()
        .map(|(&s, &c)| {
            let area = overlap.input_area.get(&s).copied().map_or(0.0, f64::from);
            let mean_cov = match weighted.get(&s) {
                Some(w) if area > 0.0 => w / area,
                _ => 1.0,
            };
            (s, (f64::from(c) * mean_cov) as f32)
        })
        .collect()
}
