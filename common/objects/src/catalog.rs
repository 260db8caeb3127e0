//! The run's `labels.json` (the global Label-Class table): label id → class and score.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use opengs_semantics::LabelRecord;

use crate::error::{ObjectError, Result};

/// Class names of the labels, as the run's consensus left them.
#[derive(Debug, Clone, Default)]
pub struct Catalog {
    /// Where the table came from (for messages).
    pub source: PathBuf,
    records: BTreeMap<u32, LabelRecord>,
}

impl Catalog {
    /// Parses the rows of a `labels.json`.
    pub fn from_json(text: &str, source: impl Into<PathBuf>) -> Result<Self> {
        let source = source.into();
        let rows: Vec<LabelRecord> = serde_json::from_str(text).map_err(|e| {
            ObjectError::file(
                &source,
                format!("not a labels.json (a list of {{id, class, score, confidence, gaussians}}): {e}"),
            )
        })?;
        Ok(Self::from_records(rows, source))
    }

    pub fn from_records(rows: Vec<LabelRecord>, source: impl Into<PathBuf>) -> Self {
        Self {
            source: source.into(),
            records: rows.into_iter().map(|r| (r.id, r)).collect(),
        }
    }

    /// Reads a `labels.json` file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| ObjectError::file(path, e))?;
        Self::from_json(&text, path)
    }

    pub fn record(&self, id: u32) -> Option<&LabelRecord> {
        self.records.get(&id)
    }

    /// Class of `id`; `None` when the label is not in the table or matched no detection.
    pub fn class(&self, id: u32) -> Option<&str> {
        self.records.get(&id).and_then(|r| r.class.as_deref())
    }

    /// The labels whose class is `name` (ASCII case ignored), in id order.
    pub fn labels_of_class(&self, name: &str) -> Vec<u32> {
        self.records
            .values()
            .filter(|r| {
                r.class
                    .as_deref()
                    .is_some_and(|c| c.eq_ignore_ascii_case(name))
            })
            .map(|r| r.id)
            .collect()
    }

    /// Every class name in the table, sorted, once each.
    pub fn class_names(&self) -> Vec<&str> {
        let mut names: Vec<&str> = self
            .records
            .values()
            .filter_map(|r| r.class.as_deref())
            .collect();
        names.sort_unstable();
        names.dedup();
        names
    }
}
