//! The mapper's side of the semantic loop ([`SemanticLoop`]): a GS Voting render at a keyframe
//! pose for the consensus, kept with its G_topK until the consensus result comes back, and
//! that result applied to the map (docs/METHOD.md §3–§5). It owns only the renders; the map and the
//! optimiser state it changes are passed in by the [`crate::Mapper`] that holds it.
//!
//! Decisions where docs/METHOD.md is open:
//! - Unlabelled (label 0) Gaussians whose centre projects onto a labelled pixel of the
//!   consistent input label map, and that are visible there (weight α·T ≥ 0.05 in the pixel's
//!   top-K, or within 5 cm + 5 % of the rendered surface depth), take that pixel's label. For
//!   the Gaussians added at this keyframe that is the pixel they were back-projected from;
//!   the rule also labels Gaussians of keyframes the (slow) segmenter skipped.
//! - Order: relabels via G_topK, then counter-pruning selection (so a Gaussian just moved to
//!   a fresh label is not pruned as a counter of its old one), then unlabelled Gaussians
//!   take labels, then split-off labels rejoin their holder where they lie on its surface
//!   (they need the Gaussians just labelled), then the counter Gaussians are removed.

use std::collections::{BTreeMap, VecDeque};

use opengs_semantics::{
    apply_relabels_centred, select_counter_gaussians, validate_regions, CounterPruneRegion,
    RelabelInstruction, RelabelScope,
};
use opengs_splat::{render_into, Adam, Camera, GaussianMap, RenderRequest, Rendered, TopK};

use crate::fragment::lies_on_host;

/// Renders kept at most while their consensus is outstanding (the segmenter works on the
/// newest keyframe only, so more would be stale).
pub const MAX_PENDING_RENDERS: usize = 3;

/// Below this accumulated α a pixel has no surface depth. Low on purpose: fresh Gaussians have
/// opacity 0.1, and D/S is a depth whatever S is.
const MIN_SILHOUETTE: f32 = 0.01;

/// A Gaussian with at least this weight at its centre pixel is seen there (fresh Gaussians
/// have opacity 0.1; one mostly hidden behind a surface stays below).
const MIN_LABEL_WEIGHT: f32 = 0.05;

/// Below this summed weight α·T of labelled Gaussians a pixel of the consensus's render is
/// 0, unmapped (docs/METHOD.md §5.5): a label voted from the faint edge of an object over
/// space the map lacks (beyond the depth range), or from behind unlabelled Gaussians, is not
/// the map's claim about that pixel. 0.5 is where `holes_pct` calls a pixel uncovered.
pub const MIN_LABELLED_COVER: f32 = 0.5;

/// Visible and total Gaussians of one label in a keyframe render (completeness, §5.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LabelVisibility {
    pub label: u32,
    pub visible: u32,
    pub total: u32,
}

/// A GS Voting render at a keyframe pose, kept until the consensus for it is applied.
#[derive(Debug, Clone)]
pub struct KeyframeRender {
    pub seq: u64,
    pub camera: Camera,
    /// Row-major voted labels (0 = nothing rendered).
    pub label_map: Vec<u32>,
    /// Rendered surface depth D/S (0 where nothing was rendered).
    pub surface_depth: Vec<f32>,
    pub top_k: TopK,
    /// Every non-zero label of the map, visible or not.
    pub visibility: Vec<LabelVisibility>,
}

/// Per-keyframe consensus result, as the mapper needs it.
#[derive(Debug, Clone, Copy)]
pub struct ConsensusUpdate<'a> {
    pub seq: u64,
    /// Row-major W×H consistent input label map (global labels).
    pub consistent_label_map: &'a [u32],
    pub relabels: &'a [RelabelInstruction],
    pub counter_regions: &'a [CounterPruneRegion],
    /// Counter Gaussians are pruned when their largest scale (m) exceeds this (θ).
    pub counter_prune_scale: f32,
}

/// What applying one consensus result did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ConsensusApplied {
    /// Label writes through G_topK.
    pub relabelled: usize,
    /// Unlabelled Gaussians that took a label from the consistent input label map.
    pub labelled: usize,
    /// Counter Gaussians removed.
    pub pruned: usize,
    /// Labels the consensus absorbed whole that stay: they stand off their host's surface.
    pub kept_off_host: Vec<u32>,
    /// Fresh labels split off a held label that went back to it: they lie on its surface.
    pub rejoined: Vec<u32>,
}

#[derive(Debug, thiserror::Error)]
pub enum ConsensusApplyError {
    #[error("no render of keyframe #{0} is pending (restarted mapper, or it was superseded)")]
    NoRender(u64),
    #[error("consistent label map of keyframe #{seq} has {got} pixels, the render {expected}")]
    SizeMismatch {
        seq: u64,
        expected: usize,
        got: usize,
    },
    #[error("consensus of keyframe #{seq}: {source}")]
    Invalid {
        seq: u64,
        source: opengs_semantics::SemanticsError,
    },
}

/// Renders outstanding, oldest first.
#[derive(Debug, Clone, Default)]
pub struct PendingRenders(VecDeque<KeyframeRender>);

impl PendingRenders {
    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    fn push(&mut self, r: KeyframeRender) -> &KeyframeRender {
        self.0.retain(|old| old.seq != r.seq);
        while self.0.len() >= MAX_PENDING_RENDERS {
            self.0.pop_front();
        }
        self.0.push_back(r);
        &self.0[self.0.len() - 1]
    }

    fn take(&mut self, seq: u64) -> Option<KeyframeRender> {
        let i = self.0.iter().position(|r| r.seq == seq)?;
        self.0.remove(i)
    }

    /// Keeps the kept top-K ids valid after the map was compacted.
    fn remap(&mut self, old_to_new: &[Option<u32>]) {
        for r in &mut self.0 {
            r.top_k.remap(old_to_new);
        }
    }
}

/// The renders sent to the consensus and not yet answered, and the buffers they reuse.
#[derive(Default)]
pub struct SemanticLoop {
    /// Renders waiting for their consensus (their top-K ids follow every prune).
    pending: PendingRenders,
    /// Buffers of the last semantic render, reused by the next (a fresh 640×480 render faults
    /// in ~50 MB: 46 ms against 33 ms reused); its top-K comes back from the consensus that
    /// used it.
    buffers: Rendered,
}

impl SemanticLoop {
    /// GS Voting render of `map` with top-K (K = `k`) and per-label visibility at `camera`
    /// (full resolution); kept for [`SemanticLoop::apply_consensus`] of keyframe `seq`.
    pub fn render_for_consensus(
        &mut self,
        map: &GaussianMap,
        seq: u64,
        camera: &Camera,
        k: usize,
    ) -> &KeyframeRender {
        let r = &mut self.buffers;
        render_into(map, camera, &RenderRequest::semantic(k), r);
        let out = &mut r.output;
        let mut label_map = out.labels.take().unwrap_or_default();
        let top_k = out.top_k.take().unwrap_or_default();
        abstain_where_labels_are_thin(&mut label_map, &top_k, &map.labels);
        let surface_depth = out
            .depth
            .iter()
            .zip(&out.silhouette)
            .map(|(&d, &s)| if s > MIN_SILHOUETTE { d / s } else { 0.0 })
            .collect();
        let visible = out.visible_per_label.take().unwrap_or_default();
        let visibility = label_visibility(&map.count_per_label(), &visible);
        self.pending.push(KeyframeRender {
            seq,
            camera: *camera,
            label_map,
            surface_depth,
            top_k,
            visibility,
        })
    }

    /// Renders waiting for their consensus.
    pub fn pending(&self) -> &PendingRenders {
        &self.pending
    }

    /// Keeps the pending renders' top-K ids valid after `map` was compacted.
    pub fn remap(&mut self, old_to_new: &[Option<u32>]) {
        self.pending.remap(old_to_new);
    }

    /// Applies one keyframe's consensus to `map` through the top-K kept from its render; the
    /// optimiser state `adam` loses the pruned Gaussians with it. On error nothing changed.
    pub fn apply_consensus(
        &mut self,
        map: &mut GaussianMap,
        adam: &mut Adam,
        update: &ConsensusUpdate,
    ) -> Result<ConsensusApplied, ConsensusApplyError> {
        let seq = update.seq;
        let render = self
            .pending
            .take(seq)
            .ok_or(ConsensusApplyError::NoRender(seq))?;
        let pixels = render.label_map.len();
        if update.consistent_label_map.len() != pixels {
            return Err(ConsensusApplyError::SizeMismatch {
                seq,
                expected: pixels,
                got: update.consistent_label_map.len(),
            });
        }
        let invalid = |source| ConsensusApplyError::Invalid { seq, source };
        // Check the counter regions before the relabels change anything.
        validate_regions(
            &render.top_k,
            map.len(),
            update.counter_regions.iter().map(|r| r.pixels.as_slice()),
        )
        .map_err(invalid)?;
        // A label absorbed whole must lie on its host's surface: the consensus cannot tell a
        // strip of floor from a cup on the desk that a segment merged with it.
        // Copies the instructions only when one is kept back.
        let kept_off_host: Vec<u32> = update
            .relabels
            .iter()
            .filter(|r| r.scope == RelabelScope::Label && !lies_on_host(map, r.from, r.to))
            .map(|r| r.from)
            .collect();
        let rest: Vec<RelabelInstruction>;
        let relabels = if kept_off_host.is_empty() {
            update.relabels
        } else {
            rest = update
                .relabels
                .iter()
                .filter(|r| !(r.scope == RelabelScope::Label && kept_off_host.contains(&r.from)))
                .cloned()
                .collect();
            &rest
        };
        let relabelled = {
            let (means, labels) = (&map.means, &mut map.labels);
            let centre = |id: u32| centre_pixel(&render.camera, means[id as usize]).map(|c| c.0);
            apply_relabels_centred(&render.top_k, labels, relabels, centre)
        }
        .map_err(invalid)?;
        let counters = {
            let map = &*map;
            select_counter_gaussians(
                &render.top_k,
                &map.labels,
                |i| {
                    let s = map.scale(i);
                    s[0].max(s[1]).max(s[2])
                },
                update.counter_prune_scale,
                update.counter_regions,
            )
            .map_err(invalid)?
        };
        let labelled = label_unlabelled(map, &render, update.consistent_label_map);
        let rejoined = rejoin_on_host(map, update.relabels);
        if !counters.is_empty() {
            let mut remove = vec![false; map.len()];
            for &i in &counters {
                remove[i as usize] = true;
            }
            let old_to_new = map.remove_where(&remove);
            adam.compact(&old_to_new);
            self.pending.remap(&old_to_new);
        }
        // Its top-K buffers serve the next semantic render.
        let spare = &mut self.buffers.output.top_k;
        if spare.is_none() {
            *spare = Some(render.top_k);
        }
        Ok(ConsensusApplied {
            relabelled,
            labelled,
            pruned: counters.len(),
            kept_off_host,
            rejoined,
        })
    }
}

/// [`RelabelScope::Rejoin`]: a fresh label, now on the Gaussians the consistent label map
/// labelled, goes back whole to the label it was split off where it lies on that label's
/// surface (a piece of floor the map left unlabelled, not a cup beside the floor's segment).
/// Returns the labels that went back.
fn rejoin_on_host(map: &mut GaussianMap, relabels: &[RelabelInstruction]) -> Vec<u32> {
    let mut rejoined = Vec::new();
    for r in relabels
        .iter()
        .filter(|r| r.scope == RelabelScope::Rejoin && r.from != r.to)
    {
        if !lies_on_host(map, r.from, r.to) {
            continue;
        }
        let mut moved = false;
        for label in map.labels.iter_mut().filter(|l| **l == r.from) {
            *label = r.to;
            moved = true;
        }
        if moved {
            rejoined.push(r.from);
        }
    }
    rejoined
}

/// Pixels whose labelled Gaussians weigh less than [`MIN_LABELLED_COVER`] render 0 (see the
/// constant); `labels` is the map's label per Gaussian.
fn abstain_where_labels_are_thin(label_map: &mut [u32], top_k: &TopK, labels: &[u32]) {
    let cover = top_k.weight_where(|id| labels.get(id as usize).is_some_and(|&l| l != 0));
    for (l, c) in label_map.iter_mut().zip(cover) {
        if c < MIN_LABELLED_COVER {
            *l = 0;
        }
    }
}

/// The row-major pixel a Gaussian centre `mean` projects to, and its depth, if in front and
/// in view.
fn centre_pixel(cam: &Camera, mean: [f32; 3]) -> Option<(usize, f32)> {
    let k = cam.intrinsics;
    let [x, y, z] = cam.to_camera(mean);
    if z <= cam.near {
        return None;
    }
    let u = (k.fx as f32 * x / z + k.cx as f32).round();
    let v = (k.fy as f32 * y / z + k.cy as f32).round();
    (u >= 0.0 && v >= 0.0 && u < k.width as f32 && v < k.height as f32)
        .then(|| (v as usize * k.width as usize + u as usize, z))
}

/// Label-0 Gaussians on the rendered surface of a labelled pixel take its label.
fn label_unlabelled(map: &mut GaussianMap, render: &KeyframeRender, labels: &[u32]) -> usize {
    let cam = &render.camera;
    let mut labelled = 0;
    for i in 0..map.len() {
        if map.labels[i] != 0 {
            continue;
        }
        let Some((p, z)) = centre_pixel(cam, map.means[i]) else {
            continue;
        };
        if labels[p] == 0 {
            continue;
        }
        // Visible at its centre: a real share of the pixel's weight, or on the rendered
        // surface (D/S blends depths, so it only catches what the top-K lacks).
        let surface = render.surface_depth[p];
        let on_surface = surface > 0.0 && (z - surface).abs() <= 0.05 + 0.05 * surface;
        let weight = render.top_k.weight_of(p, i as u32).unwrap_or(0.0);
        if on_surface || weight >= MIN_LABEL_WEIGHT {
            map.labels[i] = labels[p];
            labelled += 1;
        }
    }
    labelled
}

/// Visible and total counts of every non-zero label in the map.
fn label_visibility(
    total: &BTreeMap<u32, u32>,
    visible: &BTreeMap<u32, u32>,
) -> Vec<LabelVisibility> {
    total
        .iter()
        .filter(|(&l, _)| l != 0)
        .map(|(&label, &total)| LabelVisibility {
            label,
            visible: visible.get(&label).copied().unwrap_or(0).min(total),
            total,
        })
        .collect()
}
