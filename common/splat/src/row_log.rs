//! Contribution log of one tile: every row visit (a Gaussian compositing onto some pixels of
//! a 16-pixel tile row) as one vector of 16 weights (0 where a pixel took nothing) and the
//! Gaussian's id, in front-to-back order. The lane loop logs with one vector store per visit;
//! once the tile is done each row is packed into the top-K store (per visit: its id, its lane
//! mask and its non-zero weights as f16, one compress, conversion and vector store), the
//! per-pixel counts taken on the way. Pixels with more than K contributions have their column
//! gathered for the choice of their K heaviest. Per-pixel lists instead (a 16×16 transpose and
//! two vector stores per 16 visits and pixel) cost about 5 ms per frame at 100k Gaussians,
//! 640×480, on one thread; the pack about 3 ms (with f32 weights; f16 took about 1.5 ms off).

use crate::cpu::SimdLevel;
use crate::tiles::TILE_SIZE;
use crate::top_k::{store_weight, KEPT_SHIFT, WEIGHT_SCALE};
use half::f16;

const T: usize = TILE_SIZE as usize;

pub(crate) struct RowLog {
    /// `[row][visit]`: the visit's weight per pixel of the row.
    w: [Vec<[f32; T]>; T],
    /// `[row][visit]`: the visit's Gaussian id.
    g: [Vec<u32>; T],
}

/// Where one row's packed visits go: per visit its id and lanes (reached pixels in bits
/// 0..16, the same as kept in bits 16..32), and the reached pixels' weights back to back
/// ([stored](store_weight) as f16). `weights` must hold 16 per visit (a visit's store
/// writes 16 lanes, however few it keeps).
pub(crate) struct PackDst<'a> {
    pub ids: &'a mut [u32],
    pub lanes: &'a mut [u32],
    pub weights: &'a mut [f16],
}

/// Where [`RowLog::gather`] puts pixel x's contributions: visit indices in
/// `visits[x·stride..]`, weights in `ws[x·stride..]`. `stride` must be at least the row's
/// visits rounded up to 16, plus 16; the lanes past a pixel's list hold anything.
pub(crate) struct Columns<'a> {
    pub stride: usize,
    pub visits: &'a mut [u32],
    pub ws: &'a mut [f32],
}

/// What [`RowLog::pack`] did: each pixel's contributions, and the weights written.
pub(crate) struct Packed {
    pub counts: [u32; T],
    pub weights: usize,
}

impl RowLog {
    pub fn new() -> Self {
        Self {
            w: std::array::from_fn(|_| Vec::new()),
            g: std::array::from_fn(|_| Vec::new()),
        }
    }

    /// Empties the log for the next tile (keeping its memory).
    pub fn clear(&mut self) {
        for (w, g) in self.w.iter_mut().zip(&mut self.g) {
            w.clear();
            g.clear();
        }
    }

    /// Logs a visit of Gaussian `gid` to row `y` with per-pixel weights `w`.
    #[inline(always)]
    pub fn push(&mut self, y: usize, gid: u32, w: &[f32; T]) {
        self.w[y].push(*w);
        self.g[y].push(gid);
    }

    /// Visits logged on row `y`.
    #[inline(always)]
    pub fn len(&self, y: usize) -> usize {
        self.g[y].len()
    }

    /// Pixel `x`'s contributions on row `y` (Gaussian id, weight), front to back.
    pub fn column(&self, y: usize, x: usize) -> impl Iterator<Item = (u32, f32)> + Clone + '_ {
        self.g[y]
            .iter()
            .zip(&self.w[y])
            .map(move |(&g, w)| (g, w[x]))
            .filter(|e| e.1 > 0.0)
    }

    /// Gathers the contributions of the pixels in bit mask `xs` on row `y` into `dst`;
    /// returns how many each pixel has (0 for pixels not gathered).
    #[inline(always)]
    pub fn gather(&self, y: usize, xs: u32, simd: SimdLevel, dst: Columns) -> [usize; T] {
        let Columns { stride, visits, ws } = dst;
        let mut len = [0usize; T];
        let n = self.len(y);
        assert!(
            stride >= n.div_ceil(T) * T + T && visits.len() >= T * stride && ws.len() >= T * stride,
            "gather: room for {n} visits per pixel"
        );
        #[cfg(target_arch = "x86_64")]
        if simd == SimdLevel::Avx512 {
            // SAFETY: the caller passes Avx512 only after detecting AVX-512 F and POPCNT.
            unsafe { self.gather_avx512(y, xs, stride, visits, ws, &mut len) };
            return len;
        }
        let _ = simd;
        let w = &self.w[y];
        for x in (0..T).filter(|&x| (xs >> x) & 1 != 0) {
            let (visits, ws) = (&mut visits[x * stride..][..n], &mut ws[x * stride..][..n]);
            // Branch-free: every visit is written, only contributions advance.
            let mut l = 0;
            for (v, wv) in w.iter().enumerate() {
                visits[l] = v as u32;
                ws[l] = wv[x];
                l += (wv[x] > 0.0) as usize;
            }
            len[x] = l;
        }
        len
    }

    /// [`RowLog::gather`] 16 visits at a time: each block is transposed in registers into
    /// 16 pixel columns, and each gathered pixel's column compressed to its contributions.
    /// (Rows with a pixel past K have about ten such pixels: a walk per pixel measured 2.3 ms
    /// per frame, this 0.8 ms.)
    ///
    /// # Safety
    /// The caller must ensure the CPU supports AVX-512 F and POPCNT, and the room checked by
    /// [`RowLog::gather`].
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,popcnt")]
    unsafe fn gather_avx512(
        &self,
        y: usize,
        xs: u32,
        stride: usize,
        visits: &mut [u32],
        ws: &mut [f32],
        len: &mut [usize; T],
    ) {
        use std::arch::x86_64::*;
        let w = &self.w[y];
        let n = w.len();
        let zero = _mm512_setzero_ps();
        let iota = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
        let (out_v, out_w) = (visits.as_mut_ptr(), ws.as_mut_ptr());
        *len = [0; T];
        for b in (0..n).step_by(T) {
            // Visits past the last read as "no contribution". (Plain loops: closures would not
            // inherit the target feature.)
            let mut rows = [zero; T];
            for (v, row) in rows.iter_mut().enumerate().take(n - b) {
                // SAFETY: in bounds of the visit's 16 weights.
                *row = unsafe { _mm512_loadu_ps(w[b + v].as_ptr()) };
            }
            let columns = transpose16(rows);
            let ids = _mm512_add_epi32(iota, _mm512_set1_epi32(b as i32));
            let mut left = xs;
            while left != 0 {
                let x = left.trailing_zeros() as usize;
                left &= left - 1;
                let m = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(columns[x], zero);
                let at = x * stride + len[x];
                // SAFETY: len[x] ≤ b, so 16 lanes at `at` end within x·stride + b + 16 ≤
                // (x + 1)·stride (the room checked by `gather`).
                unsafe {
                    _mm512_storeu_ps(out_w.add(at), _mm512_maskz_compress_ps(m, columns[x]));
                    _mm512_storeu_si512(out_v.add(at).cast(), _mm512_maskz_compress_epi32(m, ids));
                }
                len[x] += m.count_ones() as usize;
            }
        }
    }

    /// Packs row `y` into `dst` (the row's visits in order) and counts each pixel's
    /// contributions.
    #[inline(always)]
    pub fn pack(&self, y: usize, simd: SimdLevel, dst: PackDst) -> Packed {
        let n = self.len(y);
        assert!(
            dst.ids.len() >= n && dst.lanes.len() >= n && dst.weights.len() >= T * n,
            "pack: room for {n} visits"
        );
        match simd {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the caller passes Avx512 only after detecting AVX-512 F and POPCNT.
            SimdLevel::Avx512 => unsafe { self.pack_avx512(y, dst) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the caller passes Avx2 only after detecting AVX2 and POPCNT.
            SimdLevel::Avx2 => unsafe { self.pack_avx2(y, dst) },
            SimdLevel::Portable => self.pack_portable(y, dst),
        }
    }

    fn pack_portable(&self, y: usize, dst: PackDst) -> Packed {
        let mut counts = [0u32; T];
        let mut at = 0;
        let ids = dst.ids.iter_mut().zip(&self.g[y]);
        for ((wv, lanes), (id, &g)) in self.w[y].iter().zip(dst.lanes.iter_mut()).zip(ids) {
            *id = g;
            let mut m = 0u32;
            // Branch-free: every lane is written, only contributions advance (at < 16·n).
            for (x, (&w, c)) in wv.iter().zip(&mut counts).enumerate() {
                let took = w > 0.0;
                dst.weights[at] = store_weight(w);
                at += took as usize;
                m |= (took as u32) << x;
                *c += took as u32;
            }
            *lanes = m | (m << KEPT_SHIFT);
        }
        Packed {
            counts,
            weights: at,
        }
    }

    /// [`RowLog::pack`] on AVX-512: per visit a compare, a masked add (the counts), a
    /// compress and a conversion to f16.
    ///
    /// # Safety
    /// The caller must ensure the CPU supports AVX-512 F and POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,popcnt")]
    unsafe fn pack_avx512(&self, y: usize, dst: PackDst) -> Packed {
        use std::arch::x86_64::*;
        let zero = _mm512_setzero_ps();
        let one = _mm512_set1_epi32(1);
        let scale = _mm512_set1_ps(WEIGHT_SCALE);
        let mut counts = _mm512_setzero_si512();
        let out = dst.weights.as_mut_ptr().cast::<u16>();
        let mut at = 0usize;
        // The ids are copied in the loop: a memcpy call per row cost more (rows are short).
        let ids = dst.ids.iter_mut().zip(&self.g[y]);
        for ((wv, lanes), (id, &g)) in self.w[y].iter().zip(dst.lanes.iter_mut()).zip(ids) {
            *id = g;
            // SAFETY: 16 weights of the visit.
            let w = unsafe { _mm512_loadu_ps(wv.as_ptr()) };
            let m = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(w, zero);
            counts = _mm512_mask_add_epi32(counts, m, counts, one);
            let h = _mm512_cvtps_ph::<ROUND_NEAREST>(_mm512_maskz_compress_ps(
                m,
                _mm512_mul_ps(w, scale),
            ));
            // SAFETY: at ≤ 16·v before visit v, and `weights` holds 16·n (checked by `pack`).
            unsafe { _mm256_storeu_si256(out.add(at).cast(), h) };
            at += m.count_ones() as usize;
            *lanes = m as u32 | ((m as u32) << KEPT_SHIFT);
        }
        let mut c = [0u32; T];
        // SAFETY: 16 u32 lanes into 16 u32.
        unsafe { _mm512_storeu_si512(c.as_mut_ptr().cast(), counts) };
        Packed {
            counts: c,
            weights: at,
        }
    }

    /// [`RowLog::pack`] on AVX2: per half visit a compare, a subtract (the counts: a true
    /// compare is −1), a permutation from a table that packs the taken lanes to the front
    /// (AVX2 has no compress) and a conversion to f16.
    ///
    /// # Safety
    /// The caller must ensure the CPU supports AVX2, F16C and POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,f16c,popcnt")]
    unsafe fn pack_avx2(&self, y: usize, dst: PackDst) -> Packed {
        use std::arch::x86_64::*;
        let zero = _mm256_setzero_ps();
        let scale = _mm256_set1_ps(WEIGHT_SCALE);
        let mut counts = [_mm256_setzero_si256(); 2];
        let out = dst.weights.as_mut_ptr().cast::<u16>();
        let mut at = 0usize;
        let ids = dst.ids.iter_mut().zip(&self.g[y]);
        for ((wv, lanes), (id, &g)) in self.w[y].iter().zip(dst.lanes.iter_mut()).zip(ids) {
            *id = g;
            let mut m = 0u32;
            for (h, counts) in counts.iter_mut().enumerate() {
                // SAFETY: 8 of the visit's 16 weights, from 8·h.
                let w = unsafe { _mm256_loadu_ps(wv[8 * h..].as_ptr()) };
                let took = _mm256_cmp_ps::<_CMP_GT_OQ>(w, zero);
                *counts = _mm256_sub_epi32(*counts, _mm256_castps_si256(took));
                let mh = _mm256_movemask_ps(took) as usize;
                let perm = _mm256_loadu_si256(PACK8[mh].as_ptr().cast());
                let packed = _mm256_permutevar8x32_ps(_mm256_mul_ps(w, scale), perm);
                let halves = _mm256_cvtps_ph::<ROUND_NEAREST>(packed);
                // SAFETY: at ≤ 16·v + 8·h before this half, and `weights` holds 16·n.
                unsafe { _mm_storeu_si128(out.add(at).cast(), halves) };
                at += mh.count_ones() as usize;
                m |= (mh as u32) << (8 * h);
            }
            *lanes = m | (m << KEPT_SHIFT);
        }
        let mut c = [0u32; T];
        // SAFETY: 8 u32 lanes into each half of 16 u32.
        unsafe {
            _mm256_storeu_si256(c.as_mut_ptr().cast(), counts[0]);
            _mm256_storeu_si256(c[8..].as_mut_ptr().cast(), counts[1]);
        }
        Packed {
            counts: c,
            weights: at,
        }
    }
}

/// f32 → f16 rounding of the packs: to nearest, ties to even, as `half::f16::from_f32`.
#[cfg(target_arch = "x86_64")]
const ROUND_NEAREST: i32 = std::arch::x86_64::_MM_FROUND_TO_NEAREST_INT;

/// Transposes a 16×16 block of f32 (row v, lane x → row x, lane v): 32-bit then 64-bit
/// interleaves within 128-bit lanes, then two rounds of 128-bit lane shuffles.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
fn transpose16(r: [std::arch::x86_64::__m512; T]) -> [std::arch::x86_64::__m512; T] {
    use std::arch::x86_64::*;
    let mut out = [_mm512_setzero_ps(); T];
    // t[2i], t[2i+1]: rows 2i, 2i+1 interleaved (columns 4k, 4k+1 / 4k+2, 4k+3 of lane k).
    let mut t = out;
    for i in (0..T).step_by(2) {
        t[i] = _mm512_unpacklo_ps(r[i], r[i + 1]);
        t[i + 1] = _mm512_unpackhi_ps(r[i], r[i + 1]);
    }
    // u[4g + j], lane k: rows 4g..4g+3 at column 4k + j.
    let mut u = out;
    for g in 0..4 {
        for j in 0..4 {
            let a = _mm512_castps_pd(t[4 * g + j / 2]);
            let b = _mm512_castps_pd(t[4 * g + 2 + j / 2]);
            u[4 * g + j] = _mm512_castpd_ps(if j % 2 == 0 {
                _mm512_unpacklo_pd(a, b)
            } else {
                _mm512_unpackhi_pd(a, b)
            });
        }
    }
    for j in 0..4 {
        let v0 = _mm512_shuffle_f32x4::<0x88>(u[j], u[4 + j]);
        let v1 = _mm512_shuffle_f32x4::<0xDD>(u[j], u[4 + j]);
        let v2 = _mm512_shuffle_f32x4::<0x88>(u[8 + j], u[12 + j]);
        let v3 = _mm512_shuffle_f32x4::<0xDD>(u[8 + j], u[12 + j]);
        out[j] = _mm512_shuffle_f32x4::<0x88>(v0, v2);
        out[8 + j] = _mm512_shuffle_f32x4::<0xDD>(v0, v2);
        out[4 + j] = _mm512_shuffle_f32x4::<0x88>(v1, v3);
        out[12 + j] = _mm512_shuffle_f32x4::<0xDD>(v1, v3);
    }
    out
}

/// For each 8-bit mask, the lanes of its set bits in order (the rest 0): a permutation that
/// packs those lanes to the front.
#[cfg(target_arch = "x86_64")]
static PACK8: [[u32; 8]; 256] = {
    let mut t = [[0u32; 8]; 256];
    let mut m = 0;
    while m < 256 {
        let (mut i, mut j) = (0, 0);
        while i < 8 {
            if (m >> i) & 1 == 1 {
                t[m][j] = i as u32;
                j += 1;
            }
            i += 1;
        }
        m += 1;
    }
    t
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::top_k::{load_weight, REACHED};

    /// Row 5 of a log with `visits` visits of weights `weight(v, x)` (ids 1000 + v), packed
    /// (the weights read back as f32).
    fn packed(
        visits: usize,
        weight: impl Fn(usize, usize) -> f32,
        simd: SimdLevel,
    ) -> (Vec<u32>, Vec<u32>, Vec<f32>, [u32; T]) {
        let mut log = RowLog::new();
        for v in 0..visits {
            log.push(5, 1000 + v as u32, &std::array::from_fn(|x| weight(v, x)));
        }
        let (mut ids, mut lanes) = (vec![0; visits], vec![0; visits]);
        let mut weights = vec![f16::NEG_ONE; T * visits];
        let p = log.pack(
            5,
            simd,
            PackDst {
                ids: &mut ids,
                lanes: &mut lanes,
                weights: &mut weights,
            },
        );
        let weights = weights[..p.weights]
            .iter()
            .map(|&h| load_weight(h))
            .collect();
        (ids, lanes, weights, p.counts)
    }

    #[test]
    fn packed_rows_hold_each_visits_weights_in_lane_order() {
        // Visit v reaches pixel x when (v + x) % 3 != 0, with weight (16·v + x + 1) / 1024
        // (f16 holds it exactly).
        let weight = |v: usize, x: usize| {
            if !(v + x).is_multiple_of(3) {
                (v * T + x + 1) as f32 / 1024.0
            } else {
                0.0
            }
        };
        for simd in SimdLevel::available() {
            let (ids, lanes, weights, counts) = packed(37, weight, simd);
            assert_eq!(ids, (1000..1037).collect::<Vec<u32>>());
            let mut at = 0;
            for (v, &l) in lanes.iter().enumerate() {
                let reached: Vec<usize> = (0..T).filter(|&x| weight(v, x) > 0.0).collect();
                let m: u32 = reached.iter().map(|&x| 1 << x).sum();
                assert_eq!(l, m | (m << 16), "{simd:?} visit {v}");
                for &x in &reached {
                    assert_eq!(weights[at], weight(v, x), "{simd:?} visit {v} pixel {x}");
                    at += 1;
                }
            }
            assert_eq!(at, weights.len());
            for (x, &c) in counts.iter().enumerate() {
                assert_eq!(c as usize, (0..37).filter(|v| (v + x) % 3 != 0).count());
            }
        }
    }

    #[test]
    fn simd_packs_match_portable() {
        // Weights that round when stored, over the renderer's range (1 down to 1e-7).
        let weight = |v: usize, x: usize| {
            if (v * 7 + x * 3) % 5 < 2 {
                ((v * T + x + 1) as f32 * 0.618034).fract() * 10f32.powi(-((v % 8) as i32))
            } else {
                0.0
            }
        };
        for simd in SimdLevel::available() {
            for visits in [1, 8, 16, 37, 200, 1500] {
                assert_eq!(
                    packed(visits, weight, simd),
                    packed(visits, weight, SimdLevel::Portable),
                    "{simd:?}, {visits} visits"
                );
            }
        }
    }

    #[test]
    fn a_visit_reaching_every_pixel_fills_its_16_weights() {
        for simd in SimdLevel::available() {
            let weight = |v, x| (v * 100 + x + 1) as f32 / 1024.0;
            let (_, lanes, weights, counts) = packed(3, weight, simd);
            assert!(lanes.iter().all(|&l| l & REACHED == REACHED));
            assert_eq!(weights.len(), 48);
            assert_eq!(weights[47], 216.0 / 1024.0);
            assert_eq!(counts, [3; T]);
        }
    }

    #[test]
    fn columns_and_gathers_are_a_pixels_contributions() {
        let mut log = RowLog::new();
        for v in 0..40u32 {
            let w = std::array::from_fn(|x| {
                if (v as usize + x).is_multiple_of(4) {
                    v as f32 + 0.5
                } else {
                    0.0
                }
            });
            log.push(2, 7 * v, &w);
        }
        let want: Vec<(u32, f32)> = (0..40u32)
            .filter(|v| (v + 3) % 4 == 0)
            .map(|v| (7 * v, v as f32 + 0.5))
            .collect();
        assert_eq!(log.column(2, 3).collect::<Vec<_>>(), want);
        let stride = 48 + 16;
        for simd in SimdLevel::available() {
            let (mut visits, mut ws) = (vec![0; T * stride], vec![0.0; T * stride]);
            let len = log.gather(
                2,
                0b1000_1000,
                simd,
                Columns {
                    stride,
                    visits: &mut visits,
                    ws: &mut ws,
                },
            );
            assert_eq!(len[3], want.len(), "{simd:?}");
            for (i, want) in want.iter().enumerate() {
                assert_eq!((7 * visits[3 * stride + i], ws[3 * stride + i]), *want);
            }
            // Pixel 7 took the visits with v % 4 == 1.
            assert_eq!(len[7], 10, "{simd:?}");
            assert_eq!(&visits[7 * stride..][..3], &[1, 5, 9]);
        }
        assert_eq!(log.len(2), 40);
        log.clear();
        assert_eq!(log.len(2), 0);
        assert_eq!(log.column(2, 3).count(), 0);
    }
}
