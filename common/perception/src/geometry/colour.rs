//! Colour of a segment as one material: its pixel-weighted mean, and whether two means are one
//! material under different light. Used where geometry alone would join two segments
//! (the coplanar floor pieces, the crease join).

use super::patches::PatchStats;
use crate::classic::normals::{dot, sub};

/// Whether two mean colours (RGB, 0..1) are one material under different light: their
/// chromaticities (each channel over the sum) within `MAX_CHROMA_GAP`, their brightness
/// within a factor `MAX_SHADING`; colours too dark for a chromaticity only by distance.
pub fn same_colour(a: [f32; 3], b: [f32; 3]) -> bool {
    same_colour_within(a, b, MAX_CHROMA_GAP, MAX_SHADING)
}

/// [`same_colour`] with its chromaticity gap and brightness factor given.
pub fn same_colour_within(a: [f32; 3], b: [f32; 3], chroma_gap: f32, shading: f32) -> bool {
    let (sa, sb) = (a[0] + a[1] + a[2], b[0] + b[1] + b[2]);
    if sa < DARK_SUM || sb < DARK_SUM {
        let d = sub(a, b);
        return dot(d, d).sqrt() <= DARK_GAP;
    }
    let chroma = |c: [f32; 3], sum: f32| c.map(|x| x / sum);
    let gap = sub(chroma(a, sa), chroma(b, sb));
    dot(gap, gap).sqrt() <= chroma_gap && sa.max(sb) <= shading * sa.min(sb)
}

const MAX_CHROMA_GAP: f32 = 0.05;
const MAX_SHADING: f32 = 2.0;
/// Below this channel sum (RGB 0..1) chromaticity is noise: compare the colours directly,
/// within `DARK_GAP`.
const DARK_SUM: f32 = 0.15;
const DARK_GAP: f32 = 0.1;

/// Pixel-weighted mean colour of each segment's patches.
pub fn mean_colours(stats: &[PatchStats], segment_of_patch: &[u32], count: usize) -> Vec<[f32; 3]> {
    let mut sums = vec![([0.0f64; 3], 0.0f64); count];
    for (st, &s) in stats.iter().zip(segment_of_patch) {
        let (c, w) = &mut sums[s as usize];
        let pw = f64::from(st.pixels);
        for (sum, &x) in c.iter_mut().zip(&st.colour) {
            *sum += pw * f64::from(x);
        }
        *w += pw;
    }
    sums.iter()
        .map(|(c, w)| c.map(|x| (x / w.max(1.0)) as f32))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_colour_allows_shading_but_not_another_hue() {
        let grey = [0.588, 0.607, 0.590];
        assert!(same_colour(grey, grey.map(|c| 0.55 * c)));
        assert!(
            !same_colour(grey, grey.map(|c| 0.45 * c)),
            "more than 2× darker"
        );
        assert!(
            !same_colour(grey, [0.375, 0.230, 0.147]),
            "brown is not grey"
        );
        // Floor pieces of scene 6 (blue, one in a table's shade) are one material.
        assert!(same_colour([0.317, 0.447, 0.637], [0.257, 0.363, 0.512]));
        // Near black, hue is noise: colours compare directly.
        assert!(same_colour([0.02, 0.05, 0.03], [0.06, 0.02, 0.02]));
        assert!(!same_colour([0.02, 0.05, 0.03], [0.2, 0.02, 0.02]));
    }
}
