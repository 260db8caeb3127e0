//! Turning components into per-frame label ids and full-resolution maps.

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::union_find::UnionFind;

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
