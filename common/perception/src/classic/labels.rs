//! Turning components into per-frame label ids and full-resolution maps.

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::union_find::UnionFind;
use crate::{SegmentInfo, Segmentation};

/// Compact segment index (0..count) per vertex, numbered in scan order.
pub fn compact_components(sets: &mut UnionFind, vertices: usize) -> (Vec<u32>, usize) {
    let mut index_of_root = vec![u32::MAX; vertices];
    let mut count = 0u32;
    let segment_of = (0..vertices as u32)
        .map(|v| {
            let root = sets.find(v) as usize;
            if index_of_root[root] == u32::MAX {
                index_of_root[root] = count;
                count += 1;
            }
            index_of_root[root]
        })
        .collect();
    (segment_of, count as usize)
}

/// Label ids 1..=count in a seeded random order: ids carry no meaning
/// across frames, exactly like SAM's mask order.
pub fn shuffled_label_ids(count: usize, seed: u64) -> Vec<u32> {
    let mut ids: Vec<u32> = (1..=count as u32).collect();
    ids.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    ids
}

/// The frame's output: every full-resolution segment index through
/// `label_of_segment` (a label 0 marks "no segment" and is not listed), and
/// the table of the labels actually painted, with their confidences.
pub fn segmentation(
    width: u32,
    height: u32,
    full_segments: &[u32],
    label_of_segment: &[u32],
    confidence: &[f32],
) -> Segmentation {
    // Edge-aware upsampling can swallow a sliver segment: list painted ones only.
    let mut painted = vec![false; label_of_segment.len()];
    for &s in full_segments {
        painted[s as usize] = true;
    }
    let label_map = full_segments
        .iter()
        .map(|&s| label_of_segment[s as usize])
        .collect();
    let mut labels: Vec<SegmentInfo> = (0..label_of_segment.len())
        .filter(|&s| painted[s] && label_of_segment[s] != 0)
        .map(|s| SegmentInfo {
            label: label_of_segment[s],
            confidence: confidence[s],
            class: None,
            score: 0.0,
        })
        .collect();
    labels.sort_unstable_by_key(|s| s.label);
    Segmentation {
        width,
        height,
        label_map,
        labels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shuffle_is_a_permutation_and_seeded() {
        let a = shuffled_label_ids(50, 1);
        let mut sorted = a.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (1..=50).collect::<Vec<u32>>());
        assert_eq!(a, shuffled_label_ids(50, 1));
        assert_ne!(a, shuffled_label_ids(50, 2));
    }
}
