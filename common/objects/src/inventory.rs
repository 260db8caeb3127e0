//! The objects of a map: one row per label (label 0, the background, is not an object),
//! with its class from the catalog, its Gaussians and its [`Extent`]; largest first.

use std::collections::BTreeMap;

use opengs_splat::GaussianMap;
use rayon::prelude::*;
use serde::Serialize;

use crate::catalog::Catalog;
use crate::extent::{extent_of, Extent};

/// One object of the map.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObjectSummary {
    pub id: u32,
    /// Class from labels.json; `None` without one, or when no detection matched the label.
    pub class: Option<String>,
    /// Detection score that chose the class.
    pub score: Option<f32>,
    pub gaussians: usize,
    /// `None` when every Gaussian of the label is too transparent to show.
    pub extent: Option<Extent>,
}

impl ObjectSummary {
    /// Volume for ordering; objects without an extent come last.
    pub fn volume(&self) -> f64 {
        self.extent.as_ref().map_or(-1.0, |e| e.volume)
    }
}

/// Indices of the Gaussians of each label, in map order (one pass over the labels).
pub fn indices_per_label(map: &GaussianMap) -> BTreeMap<u32, Vec<u32>> {
    let mut groups: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for (i, &label) in map.labels.iter().enumerate() {
        groups.entry(label).or_default().push(i as u32);
    }
    groups
}

/// Every labelled object of `map`, largest volume first (then most Gaussians, then id).
pub fn list_objects(map: &GaussianMap, catalog: Option<&Catalog>) -> Vec<ObjectSummary> {
    let groups: Vec<(u32, Vec<u32>)> = indices_per_label(map)
        .into_iter()
        .filter(|(label, _)| *label != 0)
        .collect();
    let mut rows: Vec<ObjectSummary> = groups
        .par_iter()
        .map(|(id, indices)| {
            let record = catalog.and_then(|c| c.record(*id));
            ObjectSummary {
                id: *id,
                class: record.and_then(|r| r.class.clone()),
                score: record.map(|r| r.score),
                gaussians: indices.len(),
                extent: extent_of(map, indices),
            }
        })
        .collect();
    rows.sort_by(|a, b| {
        b.volume()
            .total_cmp(&a.volume())
            .then(b.gaussians.cmp(&a.gaussians))
            .then(a.id.cmp(&b.id))
    });
    rows
}
