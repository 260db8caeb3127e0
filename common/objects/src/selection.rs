//! Which Gaussians an edit touches: the labels of one or more objects, checked against the map
//! (and the catalog for class names) before anything is changed.

use std::collections::BTreeSet;

use opengs_splat::GaussianMap;

use crate::catalog::Catalog;
use crate::error::{ObjectError, Result};

/// A non-empty set of object labels, each carried by at least one Gaussian of the map.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Selection {
    labels: BTreeSet<u32>,
}

/// Fails with [`ObjectError::NoLabels`] when every Gaussian carries label 0.
pub fn require_labels(map: &GaussianMap) -> Result<()> {
    if map.labels.iter().all(|&l| l == 0) {
        return Err(ObjectError::NoLabels);
    }
    Ok(())
}

impl Selection {
    /// The objects `ids`; each must be a label of the map.
    pub fn of_labels(map: &GaussianMap, catalog: Option<&Catalog>, ids: &[u32]) -> Result<Self> {
        require_labels(map)?;
        if ids.is_empty() {
            return Err(ObjectError::EmptySelection("no label given".into()));
        }
        let present = map.count_per_label();
        for &id in ids {
            if id == 0 {
                return Err(ObjectError::Background);
            }
            if !present.contains_key(&id) {
                let reason = match catalog.and_then(|c| c.record(id)) {
                    Some(r) => match &r.class {
                        Some(class) => format!(
                            "({class}) is in labels.json but no Gaussian of the map carries it"
                        ),
                        None => "is in labels.json but no Gaussian of the map carries it".into(),
                    },
                    None => "is not a label of the map".into(),
                };
                return Err(ObjectError::UnknownLabel {
                    label: id,
                    reason,
                    known: known_labels(map),
                });
            }
        }
        Ok(Self {
            labels: ids.iter().copied().collect(),
        })
    }

    /// Every object whose class (from the catalog) is `name`.
    pub fn of_class(map: &GaussianMap, catalog: Option<&Catalog>, name: &str) -> Result<Self> {
        require_labels(map)?;
        let catalog = catalog.ok_or(ObjectError::NoClassNames)?;
        let labels = catalog.labels_of_class(name);
        if labels.is_empty() {
            return Err(ObjectError::UnknownClass {
                class: name.to_string(),
                catalog: catalog.source.display().to_string(),
                known: catalog.class_names().join(", "),
            });
        }
        let present = map.count_per_label();
        let in_map: BTreeSet<u32> = labels
            .iter()
            .copied()
            .filter(|l| present.contains_key(l))
            .collect();
        if in_map.is_empty() {
            return Err(ObjectError::EmptySelection(format!(
                "class '{name}' (labels {}) has no Gaussian in the map",
                join(&labels)
            )));
        }
        Ok(Self { labels: in_map })
    }

    pub fn labels(&self) -> &BTreeSet<u32> {
        &self.labels
    }

    pub fn contains(&self, label: u32) -> bool {
        self.labels.contains(&label)
    }

    /// Per Gaussian: does it belong to the selection.
    pub fn mask(&self, map: &GaussianMap) -> Vec<bool> {
        map.labels.iter().map(|l| self.labels.contains(l)).collect()
    }

    /// "7 (box), 9 (ball)" for messages.
    pub fn describe(&self, catalog: Option<&Catalog>) -> String {
        self.labels
            .iter()
            .map(|&l| match catalog.and_then(|c| c.class(l)) {
                Some(class) => format!("{l} ({class})"),
                None => l.to_string(),
            })
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The map split into the selected Gaussians and the rest, each in map order.
pub fn split(map: &GaussianMap, selection: &Selection) -> (GaussianMap, GaussianMap) {
    let mut selected = GaussianMap::new();
    let mut rest = GaussianMap::with_capacity(map.len());
    for i in 0..map.len() {
        let g = map.get(i);
        if selection.contains(g.label) {
            selected.push(g);
        } else {
            rest.push(g);
        }
    }
    (selected, rest)
}

/// The map's non-zero labels, for error messages (at most 40 shown).
fn known_labels(map: &GaussianMap) -> String {
    let labels: Vec<u32> = map
        .count_per_label()
        .into_keys()
        .filter(|&l| l != 0)
        .collect();
    const SHOWN: usize = 40;
    let mut text = join(&labels[..labels.len().min(SHOWN)]);
    if labels.len() > SHOWN {
        text += &format!(" … ({} in all)", labels.len());
    }
    text
}

fn join(ids: &[u32]) -> String {
    ids.iter()
        .map(u32::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}
