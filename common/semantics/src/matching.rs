//! Resolves each input label to exactly one relation (Full > Partial > Whole > New > other).

use std::collections::{BTreeMap, BTreeSet};

use crate::config::ConsensusConfig;
use crate::intersection::Overlap;
use crate::relation::{pair_relation, PairRelation};

/// Relation of every non-zero input label; all maps are sorted, so iteration is deterministic.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Matching {
    /// ℓs → ℓr of Full matches (one-to-one).
    pub full: BTreeMap<u32, u32>,
    /// ℓr → its Partial parts ℓs (sorted).
    pub partial: BTreeMap<u32, Vec<u32>>,
    /// ℓs → its rendered Whole parts ℓr (sorted).
    pub whole: BTreeMap<u32, Vec<u32>>,
    /// Input labels over unmapped space.
    pub new: Vec<u32>,
    /// Input labels sent to background.
    pub other: Vec<u32>,
}

impl Matching {
    /// Classifies every non-zero input label of `overlap`.
    pub fn resolve(overlap: &Overlap, config: &ConsensusConfig) -> Self {
        let mut m = Matching::default();
        let inputs: Vec<u32> = overlap
            .input_area
            .keys()
            .copied()
            .filter(|&s| s != 0)
            .collect();
        // Non-zero rendered partners of ℓs with (ℓr, I, relation), ℓr increasing.
        let partners = |s: u32| {
            overlap
                .pairs
                .range((s, 1)..=(s, u32::MAX))
                .map(move |(&(_, r), &i)| {
                    let (a, b) = overlap.ratios(s, r);
                    (r, i, a, pair_relation(a, b, config))
                })
        };
        // Largest I wins, then smallest ℓr: only matters when thresholds ≤ 0.5 allow ties.
        let best =
            |cands: Vec<(u32, u32)>| cands.into_iter().max_by_key(|&(r, i)| (i, u32::MAX - r));

        let mut full_r = BTreeSet::new();
        for &s in &inputs {
            let cands = partners(s)
                .filter(|&(r, _, _, rel)| rel == Some(PairRelation::Full) && !full_r.contains(&r))
                .map(|(r, i, _, _)| (r, i))
                .collect();
            if let Some((r, _)) = best(cands) {
                m.full.insert(s, r);
                full_r.insert(r);
            }
        }
        let mut in_partial = BTreeSet::new();
        for &s in inputs.iter().filter(|s| !m.full.contains_key(s)) {
            let cands = partners(s)
                .filter(|&(_, _, _, rel)| rel == Some(PairRelation::Partial))
                .map(|(r, i, _, _)| (r, i))
                .collect();
            if let Some((r, _)) = best(cands) {
                m.partial.entry(r).or_default().push(s);
                in_partial.insert(s);
            }
        }
        // A rendered label already used as Full or Partial target is not also a Whole part
        // (possible only at exact threshold boundaries); each part belongs to one input label.
        let mut claimed: BTreeSet<u32> = full_r.iter().chain(m.partial.keys()).copied().collect();
        for &s in &inputs {
            if m.full.contains_key(&s) || in_partial.contains(&s) {
                continue;
            }
            let parts: Vec<u32> = partners(s)
                .filter(|&(r, _, _, rel)| rel == Some(PairRelation::Whole) && !claimed.contains(&r))
                .map(|(r, _, _, _)| r)
                .collect();
            if !parts.is_empty() {
                claimed.extend(parts.iter().copied());
                m.whole.insert(s, parts);
            } else if partners(s).all(|(_, _, a, _)| a < config.tau_min) {
                m.new.push(s);
            } else {
                m.other.push(s);
            }
        }
        m
    }
}
