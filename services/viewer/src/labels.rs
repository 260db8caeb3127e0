//! Label colours and names: a stable colour per label id (the same global label has the same
//! colour in every view, every run), label maps as Rerun class ids, and the viewer's copy of
//! the global Label-Class table, rebuilt from the messages (the segmenter's classes, joined
//! through the consensus' input → global mapping), for the annotation context.

use std::collections::BTreeMap;

use opengs_ipc_schema::SegmentLabel;

use crate::record::ClassEntry;

/// Label 0: background / no label.
pub const UNLABELLED: u32 = 0;

/// The colour of Gaussians and pixels without a label.
pub const UNLABELLED_RGB: [u8; 3] = [128, 128, 128];

/// A fixed colour for `label`: hues a golden-ratio step apart (neighbouring ids far apart on
/// the colour wheel), with three saturation/value levels; grey for [`UNLABELLED`].
pub fn label_color(label: u32) -> [u8; 3] {
    if label == UNLABELLED {
        return UNLABELLED_RGB;
    }
    const GOLDEN: f64 = 0.618_033_988_749_895;
    let hue = (label as f64 * GOLDEN).fract();
    let (s, v) = match label % 3 {
        0 => (0.65, 0.95),
        1 => (0.90, 0.80),
        _ => (0.50, 1.00),
    };
    hsv_to_rgb(hue, s, v)
}

fn hsv_to_rgb(h: f64, s: f64, v: f64) -> [u8; 3] {
    let h6 = h * 6.0;
    let sector = h6.floor();
    let f = h6 - sector;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match sector as u32 % 6 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [r, g, b].map(|c| (c * 255.0).round().clamp(0.0, 255.0) as u8)
}

/// A label as a Rerun class id (16 bits): labels past 65535 have no class id, and show as
/// none; the second value counts them.
pub fn class_ids(labels: &[u32]) -> (Vec<u16>, usize) {
    let mut overflow = 0;
    let ids = labels
        .iter()
        .map(|&l| {
            u16::try_from(l).unwrap_or_else(|_| {
                overflow += 1;
                0
            })
        })
        .collect();
    (ids, overflow)
}

/// The annotation entry of label 0: transparent in segmentation images.
fn unlabelled_entry() -> ClassEntry {
    ClassEntry {
        id: 0,
        label: "unlabelled".to_string(),
        rgba: [0, 0, 0, 0],
    }
}

fn entry(id: u16, label: String) -> ClassEntry {
    let [r, g, b] = label_color(id as u32);
    ClassEntry {
        id,
        label,
        rgba: [r, g, b, 255],
    }
}

/// The annotation context of one segmentation: its own labels, named by their classes.
pub fn segment_classes(labels: &[SegmentLabel]) -> Vec<ClassEntry> {
    let mut entries = vec![unlabelled_entry()];
    let mut seen = std::collections::BTreeSet::new();
    for l in labels {
        let Ok(id) = u16::try_from(l.label) else {
            continue;
        };
        if id == 0 || !seen.insert(id) {
            continue;
        }
        let name = match l.class() {
            Some(c) => format!("{c} (segment {id})"),
            None => format!("segment {id}"),
        };
        entries.push(entry(id, name));
    }
    entries
}

/// One global label as the viewer knows it.
#[derive(Debug, Clone, PartialEq)]
struct GlobalClass {
    class: Option<String>,
    score: f32,
}

/// The global Label-Class table as seen through the messages: every global label the
/// consensus has produced, with the best-scored class of the input labels mapped to it (the
/// consensus' own rule: a better score wins, a named class replaces none).
#[derive(Debug, Default)]
pub struct ClassTable {
    labels: BTreeMap<u32, GlobalClass>,
    /// The input classes of recent segmentations, by keyframe seq, for the join.
    inputs: BTreeMap<u64, BTreeMap<u32, (Option<String>, f32)>>,
}

/// Segmentations kept for the join (the consensus answers the newest few).
const KEPT_SEGMENTATIONS: usize = 8;

impl ClassTable {
    /// Remembers the classes of keyframe `seq`'s segmentation.
    pub fn segments(&mut self, seq: u64, labels: &[SegmentLabel]) {
        let classes = labels
            .iter()
            .map(|l| (l.label, (l.class().map(str::to_string), l.score)))
            .collect();
        self.inputs.insert(seq, classes);
        while self.inputs.len() > KEPT_SEGMENTATIONS {
            self.inputs.pop_first();
        }
    }

    /// Applies keyframe `seq`'s consensus: its input → global mapping and the global labels
    /// of its consistent map. True when a label or class changed (the context is re-logged).
    pub fn consensus(&mut self, seq: u64, mapping: &[[u32; 2]], label_map: &[u32]) -> bool {
        let mut changed = false;
        let present: std::collections::BTreeSet<u32> = label_map
            .iter()
            .copied()
            .filter(|&l| l != UNLABELLED)
            .collect();
        for l in present {
            changed |= self.observe(l, None, 0.0);
        }
        let inputs = self.inputs.get(&seq).cloned().unwrap_or_default();
        for &[input, global] in mapping {
            if global == UNLABELLED {
                continue;
            }
            let (class, score) = inputs
                .get(&input)
                .map_or((None, 0.0), |(c, s)| (c.as_deref(), *s));
            changed |= self.observe(global, class, score);
        }
        changed
    }

    fn observe(&mut self, id: u32, class: Option<&str>, score: f32) -> bool {
        let score = if score.is_finite() { score } else { 0.0 };
        match self.labels.get_mut(&id) {
            None => {
                self.labels.insert(
                    id,
                    GlobalClass {
                        class: class.map(str::to_string),
                        score,
                    },
                );
                true
            }
            Some(known) => {
                let better = score > known.score && class.is_some();
                let names_unnamed =
                    known.class.is_none() && class.is_some() && score >= known.score;
                if (better || names_unnamed) && known.class.as_deref() != class {
                    known.class = class.map(str::to_string);
                    known.score = score;
                    true
                } else {
                    if better {
                        known.score = score;
                    }
                    false
                }
            }
        }
    }

    pub fn len(&self) -> usize {
        self.labels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    /// The class of global label `id`, if it has one.
    pub fn class(&self, id: u32) -> Option<&str> {
        self.labels.get(&id).and_then(|g| g.class.as_deref())
    }

    /// The annotation context of global labels (those that fit a class id).
    pub fn entries(&self) -> Vec<ClassEntry> {
        let mut entries = vec![unlabelled_entry()];
        for (&id, g) in &self.labels {
            let Ok(id16) = u16::try_from(id) else {
                continue;
            };
            let name = match &g.class {
                Some(c) => format!("{c} ({id})"),
                None => format!("label {id}"),
            };
            entries.push(entry(id16, name));
        }
        entries
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn distance(a: [u8; 3], b: [u8; 3]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(&x, y)| (x as f64 - y as f64).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    #[test]
    fn each_label_has_one_colour_and_neighbours_differ() {
        for l in [1, 2, 7, 23, 544, 65_535, u32::MAX] {
            assert_eq!(label_color(l), label_color(l), "{l}");
            assert_ne!(label_color(l), UNLABELLED_RGB, "{l}");
        }
        assert_eq!(label_color(0), UNLABELLED_RGB);
        // Ids next to each other (what the consensus allocates) are told apart at a glance.
        for l in 1..600 {
            let d = distance(label_color(l), label_color(l + 1));
            assert!(d > 60.0, "labels {l} and {}: distance {d:.1}", l + 1);
        }
        // And the first few dozen are all distinct.
        let first: std::collections::BTreeSet<[u8; 3]> = (1..=60).map(label_color).collect();
        assert_eq!(first.len(), 60);
    }

    #[test]
    fn labels_become_class_ids_and_overflow_is_counted() {
        let (ids, overflow) = class_ids(&[0, 1, 65_535, 65_536, u32::MAX, 9]);
        assert_eq!(ids, [0, 1, 65_535, 0, 0, 9]);
        assert_eq!(overflow, 2);
    }

    #[test]
    fn segment_classes_name_each_label_once() {
        let labels = [
            SegmentLabel::new(3, 0.9, Some("chair"), 0.8),
            SegmentLabel::new(5, 0.7, None, 0.0),
            SegmentLabel::new(3, 0.9, Some("chair"), 0.8),
            SegmentLabel::new(70_000, 0.5, Some("far"), 0.5),
        ];
        let e = segment_classes(&labels);
        let names: Vec<(u16, &str)> = e.iter().map(|c| (c.id, c.label.as_str())).collect();
        assert_eq!(
            names,
            [
                (0, "unlabelled"),
                (3, "chair (segment 3)"),
                (5, "segment 5")
            ]
        );
        assert_eq!(e[0].rgba[3], 0, "label 0 is transparent");
        let [r, g, b] = label_color(3);
        assert_eq!(e[1].rgba, [r, g, b, 255]);
    }

    #[test]
    fn the_table_takes_classes_through_the_mapping_with_the_best_score() {
        let mut t = ClassTable::default();
        t.segments(
            10,
            &[
                SegmentLabel::new(1, 0.9, Some("table"), 0.6),
                SegmentLabel::new(2, 0.9, None, 0.0),
            ],
        );
        // Input 1 → global 4, input 2 → global 5, input 3 (absent) → background.
        assert!(t.consensus(10, &[[1, 4], [2, 5], [3, 0]], &[0, 4, 4, 5, 7]));
        assert_eq!(t.class(4), Some("table"));
        assert_eq!(t.class(5), None);
        assert_eq!(t.len(), 3, "4, 5 and 7 (in the map without a mapping)");
        // The same again changes nothing: the context is not re-logged.
        assert!(!t.consensus(10, &[[1, 4], [2, 5]], &[4, 5, 7]));
        // A lower score does not rename; a higher one does; a named class replaces none.
        t.segments(
            20,
            &[
                SegmentLabel::new(1, 0.9, Some("desk"), 0.5),
                SegmentLabel::new(2, 0.9, Some("lamp"), 0.1),
            ],
        );
        assert!(t.consensus(20, &[[1, 4], [2, 5]], &[]));
        assert_eq!(t.class(4), Some("table"));
        assert_eq!(t.class(5), Some("lamp"));
        t.segments(30, &[SegmentLabel::new(9, 0.9, Some("desk"), 0.95)]);
        assert!(t.consensus(30, &[[9, 4]], &[]));
        assert_eq!(t.class(4), Some("desk"));
        // A consensus whose segmentation the viewer never saw still registers its labels.
        assert!(t.consensus(99, &[[1, 12]], &[]));
        assert_eq!(t.class(12), None);
        let entries = t.entries();
        let names: Vec<&str> = entries.iter().map(|e| e.label.as_str()).collect();
        assert_eq!(
            names,
            ["unlabelled", "desk (4)", "lamp (5)", "label 7", "label 12"]
        );
    }

    #[test]
    fn the_table_forgets_old_segmentations() {
        let mut t = ClassTable::default();
        for seq in 0..20 {
            t.segments(seq, &[SegmentLabel::new(1, 1.0, Some("cup"), 0.9)]);
        }
        assert!(t.inputs.len() <= KEPT_SEGMENTATIONS);
        assert!(t.consensus(0, &[[1, 2]], &[]));
        assert_eq!(t.class(2), None, "seq 0 was forgotten");
        assert!(t.consensus(19, &[[1, 2]], &[]));
        assert_eq!(t.class(2), Some("cup"));
    }
}
