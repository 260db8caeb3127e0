//! One-pass intersection counts agree with naive counting.

use std::collections::BTreeMap;

use opengs_semantics::Overlap;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn counts_match_naive_counting() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for run_len in [1usize, 3, 17] {
        let n = 2000;
        let (mut input, mut rendered) = (Vec::with_capacity(n), Vec::with_capacity(n));
        while input.len() < n {
            let (s, r) = (rng.gen_range(0..6u32), rng.gen_range(0..5u32));
            for _ in 0..run_len.min(n - input.len()) {
                input.push(s);
                rendered.push(r);
            }
        }
        let overlap = Overlap::count(&input, &rendered);
        let mut pairs = BTreeMap::new();
        let (mut ins, mut ren) = (BTreeMap::new(), BTreeMap::new());
        for (&s, &r) in input.iter().zip(&rendered) {
            *pairs.entry((s, r)).or_insert(0u32) += 1;
            *ins.entry(s).or_insert(0u32) += 1;
            *ren.entry(r).or_insert(0u32) += 1;
        }
        assert_eq!(overlap.pairs, pairs);
        assert_eq!(overlap.input_area, ins);
        assert_eq!(overlap.rendered_area, ren);
    }
}

#[test]
fn ratios_are_exact_on_simple_counts() {
    // |ℓs| = 20, |ℓr| = 17 + 3, I = 17 → a = 17/20 = 0.85, b = 0.85.
    let input: Vec<u32> = [vec![1; 20], vec![0; 3]].concat();
    let rendered: Vec<u32> = [vec![0; 3], vec![2; 20]].concat();
    let overlap = Overlap::count(&input, &rendered);
    assert_eq!(overlap.ratios(1, 2), (0.85, 0.85));
    assert_eq!(overlap.ratios(1, 9), (0.0, 0.0));
}
