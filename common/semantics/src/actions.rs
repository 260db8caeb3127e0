//! Actions of each relation (docs/METHOD.md §5): who gets which label, which Gaussians move.

use std::collections::{BTreeMap, BTreeSet};

use crate::config::ConsensusConfig;
use crate::intersection::Overlap;
use crate::label_table::GlobalLabelTable;
use crate::matching::Matching;
use crate::output::{LabelTarget, RelabelInstruction, RelabelScope};
use crate::relation::Relation;

/// What the decisions of one keyframe read: relations, areas and both confidences.
pub(crate) struct Evidence<'a> {
    pub config: &'a ConsensusConfig,
    /// Completeness of each rendered label (§5.2); empty when nothing needs it.
    pub completeness: &'a BTreeMap<u32, f32>,
    pub matching: &'a Matching,
    pub overlap: &'a Overlap,
    /// C_s after the input confidence update.
    pub conf_s: &'a BTreeMap<u32, f32>,
    /// C_r as it was before this keyframe.
    pub conf_r: &'a BTreeMap<u32, f32>,
}

/// Decisions of one keyframe before they are painted into pixels.
#[derive(Default)]
pub(crate) struct Decisions {
    pub targets: BTreeMap<u32, (Relation, LabelTarget)>,
    pub relabels: Vec<RelabelInstruction>,
    /// Input label whose pixels form relabel region i.
    pub input_regions: BTreeMap<u32, usize>,
    /// (i, j): relabel j covers the pixels of relabel i (filled after painting).
    pub region_copies: Vec<(usize, usize)>,
    /// Rendered label whose pixels form relabel region i.
    pub rendered_regions: BTreeMap<u32, usize>,
    /// Map labels identified as parts this keyframe (decayed once each).
    pub parts: BTreeSet<u32>,
    /// Whole merges won by the input: merged label → input confidence.
    pub merged: Vec<(u32, f32)>,
    /// Map labels absorbed whole into another label: they leave the table.
    pub absorbed: Vec<u32>,
    /// Fragments seen this keyframe and kept: their streak grows.
    pub kept_fragments: Vec<u32>,
    pub refused: u32,
}

/// The winning Partial part of `r` that keeps `r`: one holding over half of its rendered
/// pixels, when every other segment holding τ3 of `r` splits off. A fresh label for it would
/// move only the Gaussians this view meets, and the object's hidden side would stay behind as
/// `r`. Where another piece of `r` that stays (a book the map merged with the one in view)
/// holds τ3 of it, the winner takes the fresh label as in the paper, so the two come apart.
fn partial_keeper(e: &Evidence, r: u32, parts: &[u32], wins: &impl Fn(u32) -> bool) -> Option<u32> {
    let keeper = parts
        .iter()
        .copied()
        .filter(|&s| wins(s))
        .map(|s| (e.overlap.ratios(s, r).1, s))
        .filter(|&(b, _)| b > 0.5)
        .max_by(|x, y| x.0.total_cmp(&y.0))
        .map(|(_, s)| s)?;
    let others_split = e
        .overlap
        .pairs
        .keys()
        .filter(|&&(s, rr)| rr == r && s != 0 && s != keeper)
        .filter(|&&(s, _)| e.overlap.ratios(s, r).1 >= e.config.tau_min)
        .all(|&(s, _)| parts.contains(&s) && wins(s));
    others_split.then_some(keeper)
}

impl Decisions {
    /// Every Gaussian of `from` takes `to` (`scope`: absorbed or merged), and `from` leaves
    /// the table.
    fn move_whole_label(&mut self, from: u32, to: u32, scope: RelabelScope) {
        self.relabels.push(RelabelInstruction {
            from,
            to,
            pixels: Vec::new(),
            scope,
        });
        self.absorbed.push(from);
    }
}

/// Σ c·n / Σ n (0 when the areas sum to 0).
fn area_weighted_mean(items: impl Iterator<Item = (f32, u32)>) -> f64 {
    let (num, den) = items.fold((0.0, 0.0), |(num, den), (c, n)| {
        (num + f64::from(c) * f64::from(n), den + f64::from(n))
    });
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

pub(crate) fn area(map: &BTreeMap<u32, u32>, label: u32) -> u32 {
    map.get(&label).copied().unwrap_or(0)
}

pub(crate) fn conf(map: &BTreeMap<u32, f32>, label: u32) -> f32 {
    map.get(&label).copied().unwrap_or(0.0)
}

impl Decisions {
    /// Decides every input label; fresh labels are allocated from `table` here.
    pub fn decide(e: &Evidence, table: &mut GlobalLabelTable) -> Self {
        let mut d = Decisions::default();
        for (&s, &r) in &e.matching.full {
            d.targets.insert(s, (Relation::Full, LabelTarget::Label(r)));
        }
        let split_from = Self::decide_partial(e, &mut d);
        Self::allocate_fresh(e, table, &split_from, &mut d);
        Self::decide_whole(e, &mut d);
        for (&s, &r) in &e.matching.majority {
            d.targets
                .insert(s, (Relation::Majority, LabelTarget::Label(r)));
        }
        for &s in &e.matching.other {
            d.targets
                .insert(s, (Relation::Other, LabelTarget::Background));
        }
        Self::decide_absorbed(e, table, &mut d);
        d
    }

    /// Fragments inside a matched segment and mostly in view: a part each time (decay);
    /// absorbed whole, hidden Gaussians included, once they were fragments in
    /// `absorb_after_views` keyframes in a row, and in no fewer than the keyframes they were
    /// matched on their own, and C_s > C_r: the decision is about the label,
    /// not these pixels. A large label barely in view is no fragment; an object that the
    /// segmenter merges with its support now and then is matched on its own in between.
    fn decide_absorbed(e: &Evidence, table: &GlobalLabelTable, d: &mut Decisions) {
        for (&r, &(s, t)) in &e.matching.fragments {
            if conf(e.completeness, r) < e.config.absorb_min_completeness {
                continue;
            }
            d.parts.insert(r);
            let streak = table.fragment_streak(r).saturating_add(1);
            // As many views in a row inside its support as it was seen on its own: a keyboard
            // matched alone in 17 keyframes is not given to its desk by the last 3, far off.
            let needed = e.config.absorb_after_views.max(table.own_matches(r));
            if streak < needed || conf(e.conf_s, s) <= conf(e.conf_r, r) {
                d.kept_fragments.push(r);
            } else {
                d.move_whole_label(r, t, RelabelScope::Label);
            }
        }
    }

    /// Partial groups: returns the winning parts ℓs → ℓr that need a fresh label.
    fn decide_partial(e: &Evidence, d: &mut Decisions) -> BTreeMap<u32, u32> {
        let mut split_from = BTreeMap::new();
        for (&r, parts) in &e.matching.partial {
            let cr = conf(e.conf_r, r);
            let mean = area_weighted_mean(
                parts
                    .iter()
                    .map(|&s| (conf(e.conf_s, s), area(&e.overlap.input_area, s))),
            );
            let wins = |s: u32| f64::from(cr) <= mean && conf(e.conf_s, s) > cr;
            let keeper = e
                .config
                .partial_majority_keeps
                .then(|| partial_keeper(e, r, parts, &wins))
                .flatten();
            for &s in parts {
                // Map wins when C_r > C̄s; otherwise only parts with C_s > C_r split off.
                if wins(s) && Some(s) != keeper {
                    split_from.insert(s, r);
                } else {
                    d.targets
                        .insert(s, (Relation::Partial, LabelTarget::Label(r)));
                }
            }
        }
        split_from
    }

    /// Fresh labels for winning Partial parts, Inside and New segments, in increasing ℓs order.
    fn allocate_fresh(
        e: &Evidence,
        table: &mut GlobalLabelTable,
        split_from: &BTreeMap<u32, u32>,
        d: &mut Decisions,
    ) {
        let mut order: Vec<u32> = split_from
            .keys()
            .chain(e.matching.inside.keys())
            .chain(&e.matching.new)
            .copied()
            .collect();
        order.sort_unstable();
        for s in order {
            let allocated = table.allocate(None, 0.0, conf(e.conf_s, s));
            if let Some(&r) = e.matching.inside.get(&s) {
                // ℓr keeps its confidence: its Full partner just confirmed it without ℓs.
                let target = match allocated {
                    Ok(t) => {
                        let region = d.relabels.len();
                        d.input_regions.insert(s, region);
                        d.relabels.push(RelabelInstruction {
                            from: r,
                            to: t,
                            pixels: Vec::new(),
                            scope: RelabelScope::Pixels,
                        });
                        // The other held labels under ℓs move to t over the same pixels.
                        for &also in e.matching.inside_also.get(&s).into_iter().flatten() {
                            d.region_copies.push((region, d.relabels.len()));
                            d.relabels.push(RelabelInstruction {
                                from: also,
                                to: t,
                                pixels: Vec::new(),
                                scope: RelabelScope::Pixels,
                            });
                        }
                        // A piece of ℓr's own surface the map left unlabelled goes back to
                        // it: only the map's 3D surfaces tell it from an object beside ℓr.
                        if e.matching.split_off.contains(&s) {
                            d.relabels.push(RelabelInstruction {
                                from: t,
                                to: r,
                                pixels: Vec::new(),
                                scope: RelabelScope::Rejoin,
                            });
                        }
                        t
                    }
                    Err(_) => {
                        d.refused += 1;
                        r
                    }
                };
                d.targets
                    .insert(s, (Relation::Inside, LabelTarget::Label(target)));
                continue;
            }
            match (split_from.get(&s), allocated) {
                (Some(&r), Ok(t)) => {
                    d.targets
                        .insert(s, (Relation::Partial, LabelTarget::Label(t)));
                    // Region = all pixels of the input part, not only those rendering ℓr.
                    d.input_regions.insert(s, d.relabels.len());
                    d.relabels.push(RelabelInstruction {
                        from: r,
                        to: t,
                        pixels: Vec::new(),
                        scope: RelabelScope::Pixels,
                    });
                    d.parts.insert(r);
                }
                (Some(&r), Err(_)) => {
                    d.refused += 1;
                    d.targets
                        .insert(s, (Relation::Partial, LabelTarget::Label(r)));
                }
                (None, Ok(t)) => {
                    d.targets.insert(s, (Relation::New, LabelTarget::Label(t)));
                }
                (None, Err(_)) => {
                    d.refused += 1;
                    d.targets
                        .insert(s, (Relation::New, LabelTarget::Background));
                }
            }
        }
    }

    /// Whole matches: merge the rendered parts into the largest one, or let the input take them.
    fn decide_whole(e: &Evidence, d: &mut Decisions) {
        for (&s, parts) in &e.matching.whole {
            let mean = area_weighted_mean(
                parts
                    .iter()
                    .map(|&r| (conf(e.conf_r, r), area(&e.overlap.rendered_area, r))),
            );
            d.parts.extend(parts.iter().copied());
            if f64::from(conf(e.conf_s, s)) > mean {
                // Keep the largest part's id (ties: smallest id) so most Gaussians keep their label.
                let Some(&merged) = parts
                    .iter()
                    .max_by_key(|&&r| (area(&e.overlap.rendered_area, r), u32::MAX - r))
                else {
                    continue;
                };
                d.targets
                    .insert(s, (Relation::Whole, LabelTarget::Label(merged)));
                d.merged.push((merged, conf(e.conf_s, s)));
                // Region = all rendered pixels of the part, so the part's label leaves the view;
                // a part mostly in view leaves the map, hidden Gaussians too.
                for &r in parts.iter().filter(|&&r| r != merged) {
                    if e.config.merge_whole_labels
                        && conf(e.completeness, r) >= e.config.absorb_min_completeness
                    {
                        d.move_whole_label(r, merged, RelabelScope::Merged);
                        continue;
                    }
                    d.rendered_regions.insert(r, d.relabels.len());
                    d.relabels.push(RelabelInstruction {
                        from: r,
                        to: merged,
                        pixels: Vec::new(),
                        scope: RelabelScope::Pixels,
                    });
                }
            } else {
                d.targets.insert(
                    s,
                    (Relation::Whole, LabelTarget::RenderedParts(parts.clone())),
                );
            }
        }
    }
}
