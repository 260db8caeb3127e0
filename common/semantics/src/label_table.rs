//! Global Label-Class table (paper: M_LC^G): starts empty and grows during the run.
//!
//! Cap behaviour: `allocate` refuses with `SemanticsError::LabelTableFull` once the table
//! holds `cap` labels; the consensus then sends a New segment to background 0 and keeps a
//! winning Partial part on its map label, and counts the refusal in its output.
//! Labels found in the map but unknown here (e.g. after a consensus restart) are *adopted*
//! with confidence 0 and class `None`; adoption ignores the cap but counts towards it.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Result, SemanticsError};

/// One global label: best-scored class seen so far, map confidence C_r and counters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GlobalLabel {
    /// Class name of the best detection seen for this label (`None` = no detection matched).
    pub class: Option<String>,
    /// Best detection score seen; it chose `class`.
    pub score: f32,
    /// Map confidence C_r used by the consensus (never below 0).
    pub confidence: f32,
    /// Keyframes in which an input segment was mapped to this label.
    pub observations: u32,
    /// Times this label was identified as a part and decayed (§5.1).
    pub part_decays: u32,
    /// Keyframes in a row in which this label was a fragment inside a segment matched to
    /// another label (§5.5); a Full or Majority match of its own resets it.
    #[serde(default)]
    pub fragment_streak: u32,
    /// Keyframes in which this label had a Full or Majority match of its own: absorbing it as
    /// a fragment takes at least as many fragment views in a row (§5.5).
    #[serde(default)]
    pub own_matches: u32,
}

/// One row of `labels.json`; the Gaussian count comes from the map owner.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LabelRecord {
    pub id: u32,
    pub class: Option<String>,
    pub score: f32,
    pub confidence: f32,
    pub gaussians: u64,
}

/// Global label id → class, score, confidence; ids start at 1 (0 is background) and only grow.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GlobalLabelTable {
    cap: usize,
    next_id: u32,
    labels: BTreeMap<u32, GlobalLabel>,
    /// Labels absorbed whole (§5.5), kept so that one the map still carries (the mapper found
    /// it standing off its host's surface) comes back as it was.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    retired: BTreeMap<u32, GlobalLabel>,
}

impl GlobalLabelTable {
    /// The table saved at `path` (`label_table.json` of a run); `Ok(None)` when there is none.
    pub fn load(path: &Path) -> Result<Option<Self>> {
        let file_error = |message: String| SemanticsError::TableFile {
            path: path.display().to_string(),
            message,
        };
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(file_error(e.to_string())),
        };
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| file_error(e.to_string()))
    }

    /// Saves the table to `path` atomically (a reader never sees half a table).
    pub fn save(&self, path: &Path) -> Result<()> {
        let file_error = |message: String| SemanticsError::TableFile {
            path: path.display().to_string(),
            message,
        };
        let text = serde_json::to_vec_pretty(self).map_err(|e| file_error(e.to_string()))?;
        let tmp = path.with_extension("json.tmp");
        std::fs::write(&tmp, text)
            .and_then(|()| std::fs::rename(&tmp, path))
            .map_err(|e| file_error(e.to_string()))
    }

    /// Empty table that allocates at most `cap` labels.
    pub fn new(cap: usize) -> Self {
        Self {
            cap,
            next_id: 1,
            labels: BTreeMap::new(),
            retired: BTreeMap::new(),
        }
    }

    pub fn cap(&self) -> usize {
        self.cap
    }

    pub fn len(&self) -> usize {
        self.labels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    /// True when `allocate` would refuse.
    pub fn is_full(&self) -> bool {
        self.labels.len() >= self.cap || self.next_id == u32::MAX
    }

    pub fn get(&self, id: u32) -> Option<&GlobalLabel> {
        self.labels.get(&id)
    }

    /// Map confidence C_r of `id`; 0 for background or unknown labels.
    pub fn confidence(&self, id: u32) -> f32 {
        self.labels.get(&id).map_or(0.0, |l| l.confidence)
    }

    /// Labels in increasing id order.
    pub fn iter(&self) -> impl Iterator<Item = (u32, &GlobalLabel)> {
        self.labels.iter().map(|(id, l)| (*id, l))
    }

    /// New label with the next id (always larger than every id seen), or `LabelTableFull`.
    pub fn allocate(&mut self, class: Option<&str>, score: f32, confidence: f32) -> Result<u32> {
        if self.is_full() {
            return Err(SemanticsError::LabelTableFull { cap: self.cap });
        }
        let id = self.next_id;
        self.next_id += 1;
        self.labels.insert(
            id,
            GlobalLabel {
                class: class.map(str::to_owned),
                score,
                confidence: confidence.max(0.0),
                observations: 0,
                part_decays: 0,
                fragment_streak: 0,
                own_matches: 0,
            },
        );
        Ok(id)
    }

    /// Registers a map label this table does not hold: a retired one comes back as it was, its
    /// fragment streak started again; any other with confidence 0 and class `None`.
    /// Returns true if it was new. Background 0 is never adopted.
    pub fn adopt(&mut self, id: u32) -> bool {
        if id == 0 || self.labels.contains_key(&id) {
            return false;
        }
        if let Some(label) = self.retired.remove(&id) {
            self.labels.insert(
                id,
                GlobalLabel {
                    fragment_streak: 0,
                    ..label
                },
            );
            return true;
        }
        self.labels.insert(
            id,
            GlobalLabel {
                class: None,
                score: 0.0,
                confidence: 0.0,
                observations: 0,
                part_decays: 0,
                fragment_streak: 0,
                own_matches: 0,
            },
        );
        self.next_id = self.next_id.max(id.saturating_add(1));
        true
    }

    /// Removes `id` once no Gaussian should carry it (absorbed whole); its id is never reused.
    /// Should the map still render it, [`Self::adopt`] brings it back as it was.
    pub fn retire(&mut self, id: u32) {
        if let Some(label) = self.labels.remove(&id) {
            self.retired.insert(id, label);
        }
    }

    /// Records an observation of `id` with a detection; the class follows the best score
    /// (ties keep the older class, except that a named class replaces `None`).
    pub fn observe(&mut self, id: u32, class: Option<&str>, score: f32) {
        let Some(label) = self.labels.get_mut(&id) else {
            return;
        };
        label.observations = label.observations.saturating_add(1);
        let better = score > label.score;
        let names_unnamed = label.class.is_none() && class.is_some() && score >= label.score;
        if better || names_unnamed {
            label.class = class.map(str::to_owned);
            label.score = score;
        }
    }

    /// Sets C_r of `id` (floored at 0); unknown ids are ignored.
    pub fn set_confidence(&mut self, id: u32, confidence: f32) {
        if let Some(label) = self.labels.get_mut(&id) {
            label.confidence = confidence.max(0.0);
        }
    }

    /// Fragment streak of `id` (0 for unknown labels).
    pub fn fragment_streak(&self, id: u32) -> u32 {
        self.labels.get(&id).map_or(0, |l| l.fragment_streak)
    }

    /// One more keyframe in a row as a fragment (§5.5).
    pub fn note_fragment(&mut self, id: u32) {
        if let Some(label) = self.labels.get_mut(&id) {
            label.fragment_streak = label.fragment_streak.saturating_add(1);
        }
    }

    /// Keyframes in which `id` was matched on its own (0 for unknown labels).
    pub fn own_matches(&self, id: u32) -> u32 {
        self.labels.get(&id).map_or(0, |l| l.own_matches)
    }

    /// Matched as an object of its own: counted, and the fragment streak starts again.
    pub fn note_own_match(&mut self, id: u32) {
        if let Some(label) = self.labels.get_mut(&id) {
            label.fragment_streak = 0;
            label.own_matches = label.own_matches.saturating_add(1);
        }
    }

    /// Part label decay: C_r ← max(0, C_r − δ).
    pub fn decay(&mut self, id: u32, delta: f32) {
        if let Some(label) = self.labels.get_mut(&id) {
            label.confidence = (label.confidence - delta).max(0.0);
            label.part_decays = label.part_decays.saturating_add(1);
        }
    }

    /// Rows for `labels.json`, in id order; `gaussians(id)` gives each label's Gaussian count.
    pub fn records(&self, gaussians: impl Fn(u32) -> u64) -> Vec<LabelRecord> {
        self.iter()
            .map(|(id, l)| LabelRecord {
                id,
                class: l.class.clone(),
                score: l.score,
                confidence: l.confidence,
                gaussians: gaussians(id),
            })
            .collect()
    }
}
