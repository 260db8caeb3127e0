//! GS Voting (docs/METHOD.md §3): the label with the largest summed weight at a pixel.

/// Votes over one pixel's contributions `(label, weight)` in front-to-back order.
/// Label 0 never wins over a real label; no real-labelled contributor → 0. Ties go to the
/// smaller label. `sums` is scratch (a pixel sees only a few labels, so a short list).
#[inline]
pub fn vote(contributions: impl Iterator<Item = (u32, f32)>, sums: &mut Vec<(u32, f32)>) -> u32 {
    sums.clear();
    for (label, w) in contributions {
        if label == 0 {
            continue;
        }
        match sums.iter_mut().find(|(l, _)| *l == label) {
            Some(e) => e.1 += w,
            None => sums.push((label, w)),
        }
    }
    let mut best = (0u32, 0.0f32);
    for &(l, s) in sums.iter() {
        if best.0 == 0 || s > best.1 || (s == best.1 && l < best.0) {
            best = (l, s);
        }
    }
    best.0
}
