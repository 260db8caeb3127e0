//! Per-frame quality of a segmentation against ground-truth instances
//! (issue 18): labels mean nothing across frames, so each frame is scored
//! on its own.
//!
//! - mIoU: one-to-one matching of objects and segments maximising the
//!   summed IoU (Hungarian), mean IoU over the frame's objects (an
//!   unmatched object scores 0).
//! - split share: objects of which two or more segments each cover at
//!   least `SIGNIFICANT` of the object's pixels.
//! - merge share: segments of which two or more objects each make up at
//!   least `SIGNIFICANT` of the segment's pixels.
//!
//! Pixels with ground-truth id 0 (no object) count for no object, and
//! label 0 for no segment; both still count in the other side's areas.

use std::collections::HashMap;

/// Share of an object (or segment) a part must reach to count.
pub const SIGNIFICANT: f64 = 0.1;

/// Scores of one frame, shares in [0, 1], `miou` in [0, 100].
#[derive(Debug, Clone, PartialEq)]
pub struct FrameQuality {
    pub miou: f64,
    pub split_share: f64,
    pub merge_share: f64,
    pub objects: usize,
    pub segments: usize,
    /// Every object of the frame (ground-truth id) with the IoU of its matched segment (0 when
    /// unmatched), by id: which objects a segmenter loses.
    pub object_iou: Vec<(u16, f64)>,
}

/// Scores `labels` (0 = none) against `truth` (0 = none); `None` when the
/// frame shows no object or the sizes differ.
pub fn frame_quality(labels: &[u32], truth: &[u16]) -> Option<FrameQuality> {
    if labels.len() != truth.len() {
        return None;
    }
    let mut object_area: HashMap<u16, u64> = HashMap::new();
    let mut segment_area: HashMap<u32, u64> = HashMap::new();
    let mut joint: HashMap<(u16, u32), u64> = HashMap::new();
    for (&l, &t) in labels.iter().zip(truth) {
        if t != 0 {
            *object_area.entry(t).or_default() += 1;
        }
        if l != 0 {
            *segment_area.entry(l).or_default() += 1;
        }
        if t != 0 && l != 0 {
            *joint.entry((t, l)).or_default() += 1;
        }
    }
    if object_area.is_empty() {
        return None;
    }
    let objects: Vec<u16> = sorted_keys(&object_area);
    let segments: Vec<u32> = sorted_keys(&segment_area);
    let seg_index: HashMap<u32, usize> =
        segments.iter().enumerate().map(|(i, &s)| (s, i)).collect();
    let obj_index: HashMap<u16, usize> = objects.iter().enumerate().map(|(i, &o)| (o, i)).collect();
    let mut iou = vec![vec![0.0f64; segments.len()]; objects.len()];
    let mut parts_of_object = vec![0usize; objects.len()];
    let mut parts_of_segment = vec![0usize; segments.len()];
    for (&(t, l), &n) in &joint {
        let (o, s) = (obj_index[&t], seg_index[&l]);
        let (a, b) = (object_area[&t], segment_area[&l]);
        iou[o][s] = n as f64 / (a + b - n) as f64;
        parts_of_object[o] += (n as f64 >= SIGNIFICANT * a as f64) as usize;
        parts_of_segment[s] += (n as f64 >= SIGNIFICANT * b as f64) as usize;
    }
    let matched = max_weight_matching(&iou);
    let object_iou: Vec<(u16, f64)> = matched
        .iter()
        .enumerate()
        .map(|(o, s)| (objects[o], s.map_or(0.0, |s| iou[o][s])))
        .collect();
    let total: f64 = object_iou.iter().map(|&(_, v)| v).sum();
    let share = |parts: &[usize]| {
        if parts.is_empty() {
            0.0
        } else {
            parts.iter().filter(|&&p| p >= 2).count() as f64 / parts.len() as f64
        }
    };
    Some(FrameQuality {
        miou: 100.0 * total / objects.len() as f64,
        split_share: share(&parts_of_object),
        merge_share: share(&parts_of_segment),
        objects: objects.len(),
        segments: segments.len(),
        object_iou,
    })
}

fn sorted_keys<K: Copy + Ord, V>(map: &HashMap<K, V>) -> Vec<K> {
    let mut keys: Vec<K> = map.keys().copied().collect();
    keys.sort_unstable();
    keys
}

/// Column matched to each row maximising the summed weight (weights ≥ 0;
/// a row matched at weight 0 is reported unmatched). Hungarian algorithm
/// with potentials on the matrix padded to square, O(n³).
pub fn max_weight_matching(weights: &[Vec<f64>]) -> Vec<Option<usize>> {
    let rows = weights.len();
    let cols = weights.first().map_or(0, Vec::len);
    let n = rows.max(cols);
    // Minimise cost = max − weight; padding costs max (weight 0).
    let max = weights.iter().flatten().copied().fold(0.0f64, f64::max);
    let cost = |i: usize, j: usize| {
        max - weights
            .get(i)
            .and_then(|r| r.get(j))
            .copied()
            .unwrap_or(0.0)
    };
    // 1-based potentials u (rows), v (columns); way/col_row as in the
    // textbook shortest-augmenting-path form.
    let (mut u, mut v) = (vec![0.0f64; n + 1], vec![0.0f64; n + 1]);
    let mut col_row = vec![0usize; n + 1];
    let mut way = vec![0usize; n + 1];
    for i in 1..=n {
        col_row[0] = i;
        let mut j0 = 0;
        let mut min_to = vec![f64::INFINITY; n + 1];
        let mut used = vec![false; n + 1];
        loop {
            used[j0] = true;
            let i0 = col_row[j0];
            let (mut delta, mut j1) = (f64::INFINITY, 0);
            for j in 1..=n {
                if used[j] {
                    continue;
                }
                let reduced = cost(i0 - 1, j - 1) - u[i0] - v[j];
                if reduced < min_to[j] {
                    min_to[j] = reduced;
                    way[j] = j0;
                }
                if min_to[j] < delta {
                    delta = min_to[j];
                    j1 = j;
                }
            }
            for j in 0..=n {
                if used[j] {
                    u[col_row[j]] += delta;
                    v[j] -= delta;
                } else {
                    min_to[j] -= delta;
                }
            }
            j0 = j1;
            if col_row[j0] == 0 {
                break;
            }
        }
        loop {
            let j1 = way[j0];
            col_row[j0] = col_row[j1];
            j0 = j1;
            if j0 == 0 {
                break;
            }
        }
    }
    let mut out = vec![None; rows];
    for j in 1..=n {
        let i = col_row[j];
        if i >= 1 && i <= rows && j <= cols && weights[i - 1][j - 1] > 0.0 {
            out[i - 1] = Some(j - 1);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matching_is_optimal_not_greedy() {
        // Greedy takes 0.9 (row 0 → col 0) and leaves 0.1; optimal is 0.8 + 0.8.
        let w = vec![vec![0.9, 0.8], vec![0.8, 0.1]];
        assert_eq!(max_weight_matching(&w), vec![Some(1), Some(0)]);
        // More rows than columns; zero weights stay unmatched.
        let w = vec![vec![0.5], vec![0.7], vec![0.0]];
        assert_eq!(max_weight_matching(&w), vec![None, Some(0), None]);
        assert!(max_weight_matching(&[]).is_empty());
    }

    #[test]
    fn pixels_without_depth_are_not_scored() {
        // A wall (1) whose right half lies beyond the sensor's range: no depth, no segment.
        let truth = [1, 1, 1, 1];
        let depth = [900, 900, 0, 0];
        let labels = [5, 5, 0, 0];
        let all = frame_quality(&labels, &truth).expect("objects");
        assert!((all.miou - 50.0).abs() < 1e-9, "{all:?}");
        assert_eq!(all.object_iou, vec![(1, 0.5)]);
        let frame = opengs_datasets::RgbdFrame {
            index: 0,
            timestamp: 0.0,
            width: 4,
            height: 1,
            rgb: vec![0; 12],
            depth: depth.to_vec(),
            depth_scale: 1000.0,
            gt_pose: None,
            labels: Some(truth.to_vec()),
        };
        let measured = frame.labels_where_measured().expect("labels");
        assert_eq!(measured, vec![1, 1, 0, 0]);
        let q = frame_quality(&labels, &measured).expect("objects");
        assert!((q.miou - 100.0).abs() < 1e-9, "{q:?}");
        let odd = opengs_datasets::RgbdFrame {
            depth: depth[..3].to_vec(),
            ..frame
        };
        assert_eq!(odd.labels_where_measured(), Some(truth.to_vec()));
    }

    #[test]
    fn perfect_split_and_merged_frames() {
        // Objects 1 (4 px) and 2 (4 px), 0 = background (2 px).
        let truth = [1, 1, 1, 1, 2, 2, 2, 2, 0, 0];
        let same = [7, 7, 7, 7, 3, 3, 3, 3, 0, 0];
        let q = frame_quality(&same, &truth).expect("objects");
        assert_eq!((q.miou, q.split_share, q.merge_share), (100.0, 0.0, 0.0));
        // Object 1 cut in halves: IoU 0.5 for it, split share 1/2.
        let split = [7, 7, 8, 8, 3, 3, 3, 3, 0, 0];
        let q = frame_quality(&split, &truth).expect("objects");
        assert!(
            (q.miou - 75.0).abs() < 1e-9 && q.split_share == 0.5,
            "{q:?}"
        );
        // Both objects in one segment: IoU 0.5 for one, 0 for the other.
        let merged = [7, 7, 7, 7, 7, 7, 7, 7, 0, 0];
        let q = frame_quality(&merged, &truth).expect("objects");
        assert!(
            (q.miou - 25.0).abs() < 1e-9 && q.merge_share == 1.0,
            "{q:?}"
        );
        assert!(frame_quality(&same, &[0; 10]).is_none());
        assert!(frame_quality(&same[..3], &truth).is_none());
    }
}
