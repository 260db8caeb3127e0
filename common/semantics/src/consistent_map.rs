//! The pixel pass that writes the consistent input label map and fills relabel / prune regions.

// FxHash: the keys are labels from our own pipeline, so SipHash's flood resistance buys nothing.
use crate::output::{CounterPruneRegion, RelabelInstruction};
use rustc_hash::FxHashMap;

/// What a pixel with this input label does.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct InputPixelRule {
    /// Output label (with `take_parts`: the label of pixels where nothing is rendered).
    pub label: u32,
    /// Whole match lost by the input: take the rendered label if it is one of this label's
    /// parts, `label` (the largest part) where the map renders nothing, else 0.
    pub take_parts: bool,
    /// Relabel region collecting all pixels of this input label.
    pub relabel: Option<usize>,
    /// Full partner ℓr and its prune region: pixels of ℓs that do not render ℓr go there.
    pub full: Option<(u32, usize)>,
}

/// What a pixel with this rendered label does.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct RenderedPixelRule {
    /// Input label whose Whole match lists this rendered label as a part.
    pub part_of: Option<u32>,
    /// Relabel region collecting all pixels of this rendered label.
    pub relabel: Option<usize>,
    /// Full partner ℓs and the prune region: pixels rendering ℓr outside ℓs go there.
    pub full: Option<(u32, usize)>,
}

/// Per-label rules; pixels of labels without a rule get 0 and join no region.
#[derive(Debug, Default)]
pub(crate) struct PixelRules {
    pub input: FxHashMap<u32, InputPixelRule>,
    pub rendered: FxHashMap<u32, RenderedPixelRule>,
    /// Pixels the input leaves 0 join no prune region: they say nothing against ℓr.
    pub unsegmented_abstain: bool,
}

/// One pass over the pixels; label lookups happen only when a label changes along the row.
pub(crate) fn paint(
    input: &[u32],
    rendered: &[u32],
    rules: &PixelRules,
    relabels: &mut [RelabelInstruction],
    prune: &mut [CounterPruneRegion],
) -> Vec<u32> {
    let mut out = Vec::with_capacity(input.len());
    let (mut last_s, mut si) = (None, InputPixelRule::default());
    let (mut last_r, mut ri) = (None, RenderedPixelRule::default());
    for (p, (&s, &r)) in input.iter().zip(rendered).enumerate() {
        let p = p as u32; // fits: the caller checked W×H ≤ u32::MAX
        if last_s != Some(s) {
            last_s = Some(s);
            si = rules.input.get(&s).copied().unwrap_or_default();
        }
        if last_r != Some(r) {
            last_r = Some(r);
            ri = rules.rendered.get(&r).copied().unwrap_or_default();
        }
        // Whole lost by the input: parts keep their labels; unmapped pixels follow the input's
        // grouping (largest part); pixels of another rendered label are uncertain, so 0.
        out.push(if si.take_parts {
            if ri.part_of == Some(s) {
                r
            } else if r == 0 {
                si.label
            } else {
                0
            }
        } else {
            si.label
        });
        if let Some(i) = si.relabel {
            relabels[i].pixels.push(p);
        }
        if let Some(i) = ri.relabel {
            relabels[i].pixels.push(p);
        }
        if let Some((lr, i)) = si.full {
            if r != lr {
                prune[i].pixels.push(p);
            }
        }
        if let Some((ls, i)) = ri.full {
            if s != ls && !(s == 0 && rules.unsegmented_abstain) {
                prune[i].pixels.push(p);
            }
        }
    }
    out
}
