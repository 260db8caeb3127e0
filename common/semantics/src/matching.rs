//! Resolves each input label to exactly one relation (Full > Inside > Partial > Whole > New >
//! Majority > other).

use std::collections::{BTreeMap, BTreeSet};

use crate::config::ConsensusConfig;
use crate::intersection::Overlap;
use crate::relation::{pair_relation, PairRelation};

/// Relation of every non-zero input label; all maps are sorted, so iteration is deterministic.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Matching {
    /// ℓs → ℓr of Full matches (one-to-one).
    pub full: BTreeMap<u32, u32>,
    /// ℓs → ℓr: ℓs lies (a ≥ τ2) inside rendered labels that other input labels hold (Full,
    /// or Majority at b < τ3), or lies mostly over unlabelled Gaussians with the rest in held
    /// labels of which it is a sliver (b < τ3); ℓr is the one it shares most with.
    pub inside: BTreeMap<u32, u32>,
    /// ℓs → the other held labels it lies over (ascending), relabelled with ℓr.
    pub inside_also: BTreeMap<u32, Vec<u32>>,
    /// The Inside input labels that lie mostly over unlabelled Gaussians (the unlabelled-object
    /// split): their fresh label rejoins ℓr where it lies on ℓr's surface.
    pub split_off: BTreeSet<u32>,
    /// ℓr → its Partial parts ℓs (sorted).
    pub partial: BTreeMap<u32, Vec<u32>>,
    /// ℓs → its rendered Whole parts ℓr (sorted).
    pub whole: BTreeMap<u32, Vec<u32>>,
    /// Input labels over unmapped space.
    pub new: Vec<u32>,
    /// ℓs → ℓr: no relation of the table, but they share over half of each (a over mapped
    /// pixels, and b), or ℓs is a part of ℓr over its mapped pixels (a ≥ τ2, b ≥ τ3);
    /// departure, docs/METHOD.md §5.5.
    pub majority: BTreeMap<u32, u32>,
    /// Input labels sent to background.
    pub other: Vec<u32>,
    /// Fragments ℓr → (ℓs, ℓt): a map label lying wholly inside (b ≥ τ2) an input segment ℓs
    /// whose Full or Majority partner is another label ℓt, too small a share of ℓs for a Whole
    /// part; departure, docs/METHOD.md §5.5.
    pub fragments: BTreeMap<u32, (u32, u32)>,
}

impl Matching {
    /// Classifies every non-zero input label of `overlap`; `completeness` is each rendered
    /// label's share of its Gaussians in view (§5.2), `touching` the input label pairs that
    /// meet in the image ([`crate::intersection::touching_labels`]).
    pub fn resolve(
        overlap: &Overlap,
        completeness: &BTreeMap<u32, f32>,
        touching: &BTreeSet<(u32, u32)>,
        config: &ConsensusConfig,
    ) -> Self {
        let mut m = Matching::default();
        let mut inputs: Vec<u32> = overlap
            .input_area
            .keys()
            .copied()
            .filter(|&s| s != 0)
            .collect();
        let area = |s: u32| overlap.input_area.get(&s).copied().unwrap_or(0);
        // The pixels of ℓs where the map renders a label (all of them unless unmapped pixels
        // abstain).
        let mapped_area = |s: u32| {
            if config.unmapped_pixels_abstain {
                area(s) - overlap.pairs.get(&(s, 0)).copied().unwrap_or(0)
            } else {
                area(s)
            }
        };
        // Non-zero rendered partners of ℓs: (ℓr, I, a, a over mapped pixels, the §5 relation
        // of (a, b)), ℓr increasing.
        let partners = |s: u32| {
            let n = f64::from(mapped_area(s));
            overlap
                .pairs
                .range((s, 1)..=(s, u32::MAX))
                .map(move |(&(_, r), &i)| {
                    let (a, b) = overlap.ratios(s, r);
                    let a_mapped = if n > 0.0 { f64::from(i) / n } else { 0.0 };
                    let full = pair_relation(a_mapped, b, config) == Some(PairRelation::Full);
                    (r, i, a, a_mapped, full, pair_relation(a, b, config))
                })
        };
        // Mostly over unmapped space: New, whatever the few mapped pixels render.
        let unmapped = |s: u32| {
            config.unmapped_pixels_abstain
                && f64::from(mapped_area(s)) < config.tau_min * f64::from(area(s))
        };
        // Largest I wins, then smallest ℓr: only matters when thresholds ≤ 0.5 allow ties.
        let best =
            |cands: Vec<(u32, u32)>| cands.into_iter().max_by_key(|&(r, i)| (i, u32::MAX - r));

        let mut full_r = BTreeSet::new();
        for &s in inputs.iter().filter(|&&s| unmapped(s)) {
            m.new.push(s);
        }
        inputs.retain(|&s| !unmapped(s));
        for &s in &inputs {
            // Full over the mapped pixels: the unmapped rest of ℓs extends the same object.
            let cands = partners(s)
                .filter(|&(r, _, _, _, full, _)| full && !full_r.contains(&r))
                .map(|(r, i, ..)| (r, i))
                .collect();
            if let Some((r, _)) = best(cands) {
                m.full.insert(s, r);
                full_r.insert(r);
            }
        }
        if config.enable_inside_split {
            // Who holds each rendered label: its Full partner, else the input label sharing
            // over half of each with it without a relation of the table, where the label is
            // mostly in view (a floor larger than the view is seen in pieces, each a part).
            let mut holder: BTreeMap<u32, (u32, bool)> =
                m.full.iter().map(|(&s, &r)| (r, (s, true))).collect();
            for &s in inputs.iter().filter(|s| !m.full.contains_key(s)) {
                let Some(r) = majority_partner(overlap, s, mapped_area(s), &full_r) else {
                    continue;
                };
                let (a, b) = overlap.ratios(s, r);
                let in_view = completeness.get(&r).copied().unwrap_or(0.0);
                if pair_relation(a, b, config).is_none()
                    && in_view >= config.absorb_min_completeness
                {
                    holder.entry(r).or_insert((s, false));
                }
            }
            let unmatched: Vec<u32> = inputs
                .iter()
                .copied()
                .filter(|s| !m.full.contains_key(s))
                .collect();
            for s in unmatched {
                // Inside one label another input label Full-matches.
                let cands = partners(s)
                    .filter(|&(r, _, _, a, _, _)| a >= config.tau_part && full_r.contains(&r))
                    .map(|(r, i, ..)| (r, i))
                    .collect();
                if let Some((r, _)) = best(cands) {
                    m.inside.insert(s, r);
                    continue;
                }
                // Or mostly over unlabelled Gaussians, the labelled rest all in held labels of
                // which ℓs is a sliver: an object beside them that the map left unlabelled.
                let held_by_other = |r: u32| holder.get(&r).is_some_and(|&(h, _)| h != s);
                let mapped = mapped_area(s);
                if config.split_unlabelled_objects
                    && mapped > 0
                    && 2 * u64::from(mapped) < u64::from(area(s))
                    && partners(s)
                        .all(|(r, ..)| held_by_other(r) && overlap.ratios(s, r).1 < config.tau_min)
                {
                    let held: Vec<(u32, u32)> = partners(s).map(|(r, i, ..)| (r, i)).collect();
                    if m.insert_inside(s, &held) {
                        m.split_off.insert(s);
                        continue;
                    }
                }
                // Or, together, inside labels held by input labels that do not touch ℓs: the
                // map gave an object the label of something apart from it. A Majority-held
                // label only where ℓs is no Partial candidate of it (b < τ3). Pieces of one
                // surface touch each other, so they stay parts.
                let apart = |h: u32| h != s && !touching.contains(&(s.min(h), s.max(h)));
                let held: Vec<(u32, u32)> = partners(s)
                    .filter(|&(r, ..)| match holder.get(&r) {
                        Some(&(h, true)) => apart(h),
                        Some(&(h, false)) => apart(h) && overlap.ratios(s, r).1 < config.tau_min,
                        None => false,
                    })
                    .map(|(r, i, ..)| (r, i))
                    .collect();
                let inside: u64 = held.iter().map(|&(_, i)| u64::from(i)).sum();
                if inside as f64 >= config.tau_part * f64::from(mapped_area(s)) {
                    m.insert_inside(s, &held);
                }
            }
        }
        let mut in_partial = BTreeSet::new();
        for &s in inputs
            .iter()
            .filter(|s| !m.full.contains_key(s) && !m.inside.contains_key(s))
        {
            // Partial and Whole keep the paper's a: over a big surface's unmapped pixels a
            // Partial would hand its confident pieces fresh labels and split the surface.
            let cands = partners(s)
                .filter(|&(.., rel)| rel == Some(PairRelation::Partial))
                .map(|(r, i, ..)| (r, i))
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
            if m.full.contains_key(&s) || m.inside.contains_key(&s) || in_partial.contains(&s) {
                continue;
            }
            let parts: Vec<u32> = partners(s)
                .filter(|&(r, .., rel)| rel == Some(PairRelation::Whole) && !claimed.contains(&r))
                .map(|(r, ..)| r)
                .collect();
            if !parts.is_empty() {
                claimed.extend(parts.iter().copied());
                m.whole.insert(s, parts);
            } else if partners(s).all(|(_, _, a, ..)| a < config.tau_min) {
                m.new.push(s);
            } else if let Some(r) = config
                .majority_match
                .then(|| {
                    majority_partner(overlap, s, mapped_area(s), &claimed)
                        .or_else(|| mapped_part_of(overlap, s, mapped_area(s), &claimed, config))
                })
                .flatten()
            {
                m.majority.insert(s, r);
            } else {
                m.other.push(s);
            }
        }
        if config.absorb_fragments {
            claimed.extend(m.majority.values().copied());
            claimed.extend(m.inside.values().copied());
            claimed.extend(m.inside_also.values().flatten().copied());
            m.fragments = fragments(overlap, &m, &claimed, config);
        }
        m
    }
}

impl Matching {
    /// ℓs Inside the held label (ℓr, I) it shares most with (ties: smallest ℓr); the other
    /// held labels under it go with it. False when nothing is held.
    fn insert_inside(&mut self, s: u32, held: &[(u32, u32)]) -> bool {
        let Some(&(r, _)) = held.iter().max_by_key(|&&(r, i)| (i, u32::MAX - r)) else {
            return false;
        };
        self.inside.insert(s, r);
        let also: Vec<u32> = held.iter().map(|&(h, _)| h).filter(|&h| h != r).collect();
        if !also.is_empty() {
            self.inside_also.insert(s, also);
        }
        true
    }
}

/// Unclaimed map labels with b ≥ τ2 inside an input label that Full- or Majority-matches
/// another map label: the fragments a Whole match would merge if they were not under τ3 of ℓs.
fn fragments(
    overlap: &Overlap,
    m: &Matching,
    claimed: &BTreeSet<u32>,
    config: &ConsensusConfig,
) -> BTreeMap<u32, (u32, u32)> {
    let mut found = BTreeMap::new();
    for (&s, &t) in m.full.iter().chain(&m.majority) {
        for (&(_, r), _) in overlap.pairs.range((s, 1)..=(s, u32::MAX)) {
            if r == t || claimed.contains(&r) {
                continue;
            }
            if overlap.ratios(s, r).1 >= config.tau_part {
                // b ≥ τ2 > 1/2: at most one input label can hold ℓr this way.
                found.insert(r, (s, t));
            }
        }
    }
    found
}

/// The unclaimed rendered label ℓr that holds τ2 of input label `s`'s `mapped` pixels and of
/// which `s` covers at least τ3: a Partial part but for its unmapped pixels (Gaussians left
/// unlabelled while it was "other"). It takes ℓr; no fresh label, so a surface never splits.
fn mapped_part_of(
    overlap: &Overlap,
    s: u32,
    mapped: u32,
    claimed: &BTreeSet<u32>,
    config: &ConsensusConfig,
) -> Option<u32> {
    first_partner(overlap, s, claimed, |i, b| {
        f64::from(i) >= config.tau_part * f64::from(mapped) && b >= config.tau_min
    })
}

/// The unclaimed rendered label ℓr that shares over half of input label `s`'s `mapped` pixels
/// and over half of its own rendered pixels. Then each is the other's largest partner, so at
/// most one ℓr qualifies for `s`, and no other input label can claim the same ℓr.
fn majority_partner(
    overlap: &Overlap,
    s: u32,
    mapped: u32,
    claimed: &BTreeSet<u32>,
) -> Option<u32> {
    first_partner(overlap, s, claimed, |i, b| {
        2 * u64::from(i) > u64::from(mapped) && b > 0.5
    })
}

/// The first unclaimed non-zero rendered partner ℓr of `s` (ℓr increasing) whose shared pixels
/// I and b = I/|ℓr| pass `test`.
fn first_partner(
    overlap: &Overlap,
    s: u32,
    claimed: &BTreeSet<u32>,
    test: impl Fn(u32, f64) -> bool,
) -> Option<u32> {
    overlap
        .pairs
        .range((s, 1)..=(s, u32::MAX))
        .find(|(&(_, r), &i)| !claimed.contains(&r) && test(i, overlap.ratios(s, r).1))
        .map(|(&(_, r), _)| r)
}
