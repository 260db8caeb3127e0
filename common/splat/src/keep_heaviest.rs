//! The K heaviest of a pixel's contributions when it has more than K (docs/METHOD.md §3's G_topK),
//! kept in front-to-back order: a quickselect whose candidates are lane bit masks.

use crate::cpu::SimdLevel;

/// Longest list [`keep_heaviest`] takes (its lane masks are four 64-bit words).
pub const KEEP_MAX: usize = 256;

/// The lanes (bit i of word i / 64: entry i) of the `m` heaviest of the `n` contributions
/// `ws` (front to back, ties to the front one), 1 ≤ m < n. `ws` holds positive weights and is
/// padded with zeros to a multiple of 64 (at most [`KEEP_MAX`]). A mask rather than the
/// entries: the renderer unmarks the few dropped ones where they are.
///
/// Quickselect on the weights with the candidates as lane bit masks: each step is two
/// branch-free compares over the list (vector compares on SIMD builds) and a few popcounts,
/// and a step leaves about half the candidates; much cheaper for the few dozen entries of a
/// pixel than sorting keys (`select_nth_unstable`'s data-dependent branches mispredict).
#[inline(always)]
pub fn keep_heaviest(ws: &[f32], n: usize, m: usize, simd: SimdLevel) -> [u64; 4] {
    #[cfg(target_arch = "x86_64")]
    let avx512 = simd == SimdLevel::Avx512;
    #[cfg(not(target_arch = "x86_64"))]
    let avx512 = {
        let _ = simd;
        false
    };
    #[cfg(target_arch = "x86_64")]
    if avx512 && n <= 128 {
        let lanes = n.div_ceil(64) * 64;
        assert!(ws.len() >= lanes, "keep_heaviest: list not padded");
        // SAFETY: the Avx512 level has AVX-512 F and BW (SimdLevel::detected); the list holds
        // the lanes.
        return unsafe {
            if n <= 64 {
                keep_heaviest_64_avx512(ws, n, m)
            } else {
                keep_heaviest_128_avx512(ws, n, m)
            }
        };
    }
    let nw = n.div_ceil(64);
    debug_assert!(m >= 1 && m < n && n <= KEEP_MAX && ws.len() >= 64 * nw);
    debug_assert!(ws[n..64 * nw].iter().all(|&w| w == 0.0));
    let (blocks, _) = ws.as_chunks::<64>();
    let mut cand = [0u64; 4];
    for (b, c) in cand.iter_mut().enumerate().take(nw) {
        let left = n - 64 * b;
        *c = if left >= 64 { !0 } else { (1u64 << left) - 1 };
    }
    // The m-th largest weight: `need` of the candidates are still to be kept.
    let mut need = m;
    let p = loop {
        let p = pivot(ws, &cand, nw, need);
        let (mut gt, mut eq) = ([0u64; 4], [0u64; 4]);
        let (mut n_gt, mut n_eq) = (0, 0);
        for b in 0..nw {
            let (above, equal) = lanes_above_equal(&blocks[b], p, avx512);
            gt[b] = cand[b] & above;
            eq[b] = cand[b] & equal;
            n_gt += gt[b].count_ones() as usize;
            n_eq += eq[b].count_ones() as usize;
        }
        if n_gt >= need {
            cand = gt;
        } else if n_gt + n_eq >= need {
            break p;
        } else {
            need -= n_gt + n_eq;
            for b in 0..nw {
                cand[b] &= !(gt[b] | eq[b]);
            }
        }
    };
    // Keep everything heavier than p, and the front ones of those equal to it.
    let mut keep = [0u64; 4];
    let mut ties = m;
    let mut equal = [0u64; 4];
    for b in 0..nw {
        (keep[b], equal[b]) = lanes_above_equal(&blocks[b], p, avx512);
        ties -= keep[b].count_ones() as usize;
    }
    for b in 0..nw {
        let mut eq = equal[b];
        while ties > 0 && eq != 0 {
            keep[b] |= eq & eq.wrapping_neg();
            eq &= eq - 1;
            ties -= 1;
        }
    }
    keep
}

/// Defines `$name`: [`keep_heaviest`] for lists of at most 16·$q lanes on AVX-512, with the
/// weights in $q registers, the candidates in one `$mask` ($q·16 bits), and a step of 2·$q
/// compares and two popcounts. (A macro, not generic code: the 64-lane version on u64 masks
/// costs a sixth less than on u128 ones.)
macro_rules! keep_heaviest_in_registers {
    ($name:ident, $mask:ty, $q:literal) => {
        /// # Safety
        /// The CPU must support AVX-512 F and BW, and POPCNT; `ws` must hold at least 16·Q
        /// lanes.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,avx512bw,popcnt")]
        #[inline]
        unsafe fn $name(ws: &[f32], n: usize, m: usize) -> [u64; 4] {
            use std::arch::x86_64::*;
            const LANES: usize = 16 * $q;
            assert!(ws.len() >= LANES && n <= LANES);
            let mut v = [_mm512_setzero_ps(); $q];
            for (q, vq) in v.iter_mut().enumerate() {
                // SAFETY: ws holds LANES lanes (checked).
                *vq = unsafe { _mm512_loadu_ps(ws.as_ptr().add(16 * q)) };
            }
            // The lanes above p, and equal to it. (These closures are inlined into this
            // function, features and all: measured as fast as the plain code they replaced.)
            let masks = |p: f32| -> ($mask, $mask) {
                let pv = _mm512_set1_ps(p);
                let (mut above, mut equal): ($mask, $mask) = (0, 0);
                // Four 16-lane masks joined in mask registers (kunpack), one move out per 64.
                for (q, v4) in v.chunks_exact(4).enumerate() {
                    let join = |c: [u16; 4]| {
                        _mm512_kunpackd(
                            _mm512_kunpackw(c[3] as u32, c[2] as u32) as u64,
                            _mm512_kunpackw(c[1] as u32, c[0] as u32) as u64,
                        )
                    };
                    let gt = join(std::array::from_fn(|i| {
                        _mm512_cmp_ps_mask::<_CMP_GT_OQ>(v4[i], pv)
                    }));
                    let eq = join(std::array::from_fn(|i| {
                        _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(v4[i], pv)
                    }));
                    above |= (gt as $mask) << (64 * q);
                    equal |= (eq as $mask) << (64 * q);
                }
                (above, equal)
            };
            let mut cand: $mask = if n == LANES { !0 } else { (1 << n) - 1 };
            let mut need = m;
            let p = loop {
                let first = cand.trailing_zeros() as usize;
                let last = LANES - 1 - cand.leading_zeros() as usize;
                let mid = (cand & (!0 << ((first + last) / 2))).trailing_zeros() as usize;
                let p = sample_pivot(
                    [ws[first], ws[mid], ws[last]],
                    need,
                    cand.count_ones() as usize,
                );
                let (gt, eq) = masks(p);
                let (gt, eq) = (gt & cand, eq & cand);
                let (n_gt, n_eq) = (gt.count_ones() as usize, eq.count_ones() as usize);
                if n_gt >= need {
                    cand = gt;
                } else if n_gt + n_eq >= need {
                    break p;
                } else {
                    need -= n_gt + n_eq;
                    cand &= !(gt | eq);
                }
            };
            // Everything heavier than p, and the front ones of those equal to it.
            let (mut keep, mut equal) = masks(p);
            let mut ties = m - keep.count_ones() as usize;
            while ties > 0 && equal != 0 {
                keep |= equal & equal.wrapping_neg();
                equal &= equal - 1;
                ties -= 1;
            }
            [keep as u64, ((keep as u128) >> 64) as u64, 0, 0]
        }
    };
}

keep_heaviest_in_registers!(keep_heaviest_64_avx512, u64, 4);
keep_heaviest_in_registers!(keep_heaviest_128_avx512, u128, 8);

/// Bit masks of the lanes of `block` above `p` and equal to it. `avx512`: the CPU has
/// AVX-512 F and BW (four compares into mask registers instead of building the bits).
#[inline(always)]
fn lanes_above_equal(block: &[f32; 64], p: f32, avx512: bool) -> (u64, u64) {
    #[cfg(target_arch = "x86_64")]
    if avx512 {
        // SAFETY: the caller says the CPU has AVX-512 F and BW.
        return unsafe { lanes_above_equal_avx512(block, p) };
    }
    let _ = avx512;
    let (mut above, mut equal) = (0u64, 0u64);
    for (i, &w) in block.iter().enumerate() {
        above |= ((w > p) as u64) << i;
        equal |= ((w == p) as u64) << i;
    }
    (above, equal)
}

/// [`lanes_above_equal`] on AVX-512.
///
/// # Safety
/// The caller must ensure the CPU supports AVX-512 F and BW.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw")]
#[inline]
unsafe fn lanes_above_equal_avx512(block: &[f32; 64], p: f32) -> (u64, u64) {
    use std::arch::x86_64::*;
    let pv = _mm512_set1_ps(p);
    let (mut above, mut equal) = (0u64, 0u64);
    for q in 0..4 {
        // SAFETY: lanes 16q..16q + 16 of a 64-lane block.
        let v = unsafe { _mm512_loadu_ps(block.as_ptr().add(16 * q)) };
        above |= (_mm512_cmp_ps_mask::<_CMP_GT_OQ>(v, pv) as u64) << (16 * q);
        equal |= (_mm512_cmp_ps_mask::<_CMP_EQ_OQ>(v, pv) as u64) << (16 * q);
    }
    (above, equal)
}

/// A pivot from the first, last and middle candidates: the one whose rank among the three
/// is nearest the target's (the `need`-th largest candidate), so the steps close in on it.
#[inline(always)]
fn pivot(ws: &[f32], cand: &[u64; 4], nw: usize, need: usize) -> f32 {
    let first = first_candidate_from(cand, nw, 0);
    let mut last = 0;
    for b in (0..nw).rev() {
        if cand[b] != 0 {
            last = 64 * b + 63 - cand[b].leading_zeros() as usize;
            break;
        }
    }
    let mid = first_candidate_from(cand, nw, (first + last) / 2);
    let count: usize = cand[..nw].iter().map(|c| c.count_ones() as usize).sum();
    sample_pivot([ws[first], ws[mid], ws[last]], need, count)
}

/// Of three sampled weights: the largest when the target is in the top third of the
/// `count` candidates, the smallest in the bottom third, else the median.
#[inline(always)]
fn sample_pivot([a, b, c]: [f32; 3], need: usize, count: usize) -> f32 {
    if 3 * need <= count {
        a.max(b).max(c)
    } else if 3 * need >= 2 * count {
        a.min(b).min(c)
    } else {
        a.max(b).min(a.min(b).max(c))
    }
}

/// Position of the first candidate at or after `from` (one exists: `last` is one).
#[inline(always)]
fn first_candidate_from(cand: &[u64; 4], nw: usize, from: usize) -> usize {
    let mut b = from / 64;
    let mut word = cand[b] & (!0u64 << (from % 64));
    while word == 0 && b + 1 < nw {
        b += 1;
        word = cand[b];
    }
    64 * b + word.trailing_zeros() as usize
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::top_k::heaviest_first;

    #[test]
    fn keep_heaviest_matches_selection() {
        let mut rng = ChaCha8Rng::seed_from_u64(12345);
        let mut rnd = move || rng.gen::<u32>();
        for case in 0..2000 {
            let n = 2 + (rnd() as usize % (KEEP_MAX - 1));
            let m = 1 + (rnd() as usize % (n - 1));
            // Few distinct values in some cases, so ties straddle the cut.
            let levels = if case % 3 == 0 {
                1 + rnd() % 5
            } else {
                1 << 20
            };
            let ws: Vec<f32> = (0..n)
                .map(|_| (1 + rnd() % levels) as f32 / (levels + 1) as f32)
                .collect();
            let entries: Vec<(u32, f32)> = (0..n as u32).zip(ws.iter().copied()).collect();
            // The m heaviest, in front-to-back order (entry i has id i).
            let mut want = heaviest_first(&entries, m);
            want.sort_by_key(|e| e.0);
            let mut pw = ws.clone();
            pw.resize(n.div_ceil(64) * 64, 0.0);
            let kept = |mask: [u64; 4]| -> Vec<(u32, f32)> {
                (0..KEEP_MAX)
                    .filter(|&i| (mask[i / 64] >> (i % 64)) & 1 != 0)
                    .map(|i| (i as u32, pw[i]))
                    .collect()
            };
            for simd in SimdLevel::available() {
                let got = kept(keep_heaviest(&pw, n, m, simd));
                assert_eq!(got, want, "{simd:?}: n {n} m {m} levels {levels}");
            }
        }
    }
}
