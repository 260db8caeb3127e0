//! Contribution log of one tile: every row visit (a Gaussian compositing onto some pixels of
//! a 16-pixel tile row) as one vector of 16 weights (0 where a pixel took nothing) and the
//! Gaussian's id, in front-to-back order. The lane loop logs with one vector store per visit;
//! the per-pixel counts and lists (the top-K's input) are read off the log once the tile is
//! done, with transposes in registers (16×16 on AVX-512, written back over the log, the
//! counts taken on the way; 8×8 on AVX2; a column walk in portable code).
//! Appending to 16 per-pixel lists during the lane loop instead (16 scattered stores per
//! visit) was the top-K's largest cost; a scatter per visit, or a walk over each visit's
//! lanes, measured 2.4× and 2× the transposes.

use crate::tiles::TILE_SIZE;

const T: usize = TILE_SIZE as usize;

/// Visits logged per tile row; a row meeting more is marked overflowed and its pixels are
/// replayed exactly (rare even in dense maps: 500k Gaussians average 120 visits per row).
pub(crate) const ROW_CAP: usize = 1024;

/// Longest per-pixel list kept in the scratch lists; longer ones are replayed exactly.
pub(crate) const LIST_CAP: usize = 256;

pub(crate) struct RowLog {
    /// `[row][visit]`: the visit's weight per pixel of the row.
    w: Box<[[[f32; T]; ROW_CAP]; T]>,
    /// `[row][visit]`: the visit's Gaussian id.
    g: Box<[[u32; ROW_CAP]; T]>,
    n: [usize; T],
    overflowed: [bool; T],
    /// Rows already transposed in place (AVX-512: by [`RowLog::counts`]).
    transposed: [bool; T],
}

/// A boxed `[a; T]` built on the heap (a tile's rows of log or lists are too big for the
/// stack).
pub(crate) fn boxed_rows<A: Copy>(a: A) -> Box<[A; T]> {
    match vec![a; T].into_boxed_slice().try_into() {
        Ok(b) => b,
        Err(_) => unreachable!("the vector has T elements"),
    }
}

/// Room per scratch pixel list: LIST_CAP plus 16 of padding (a last block of 16).
pub(crate) const STRIDE: usize = LIST_CAP + 16;

/// Per-pixel contribution lists of one tile row, `[pixel][entry]`.
pub(crate) type PixelLists<V> = [[V; STRIDE]; T];

/// Which instructions read the lists off the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ListSimd {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

/// Where the lists of one tile row go: pixel x's `n[x]` entries go nowhere if bit x of
/// `skip` is set (the caller replays it), to `scratch_*[x]` if bit x of `to_scratch` is set
/// (n ≤ LIST_CAP), else to `out_*[off[x]..off[x] + n[x]]`. The readers may write anything
/// into `out_*` past a list's end (up to 16 entries past the row's last list, which `out_*`
/// must hold): lists are written in order, so a later one, or the caller, overwrites it.
pub(crate) struct RowDst<'a> {
    pub out_ids: &'a mut [u32],
    pub out_ws: &'a mut [f32],
    pub off: [usize; T],
    pub n: [usize; T],
    pub scratch_ids: &'a mut PixelLists<u32>,
    pub scratch_ws: &'a mut PixelLists<f32>,
    pub to_scratch: u32,
    pub skip: u32,
}

impl RowLog {
    pub fn new() -> Self {
        Self {
            w: boxed_rows([[0.0; T]; ROW_CAP]),
            g: boxed_rows([0; ROW_CAP]),
            n: [0; T],
            overflowed: [false; T],
            transposed: [false; T],
        }
    }

    /// Empties the log for the next tile.
    pub fn clear(&mut self) {
        self.n = [0; T];
        self.overflowed = [false; T];
        self.transposed = [false; T];
    }

    /// Logs a visit of Gaussian `gid` to row `y` with per-pixel weights `w`.
    #[inline(always)]
    pub fn push(&mut self, y: usize, gid: u32, w: &[f32; T]) {
        let n = self.n[y];
        if n < ROW_CAP {
            self.w[y][n] = *w;
            self.g[y][n] = gid;
            self.n[y] = n + 1;
        } else {
            self.overflowed[y] = true;
        }
    }

    /// Whether row `y` met more than [`ROW_CAP`] visits (its pixels must be replayed).
    #[inline(always)]
    pub fn overflowed(&self, y: usize) -> bool {
        self.overflowed[y]
    }

    /// Contributions per pixel of row `y` (which must not have overflowed; once per row, before
    /// [`RowLog::write_lists`]): counted here
    /// rather than in the lane loop, where every added instruction stretches the loop the
    /// whole render waits on. On AVX-512 the row is transposed for [`RowLog::write_lists`]
    /// on the way, and counted before its transposes (16 masked adds per 16 visits).
    #[inline(always)]
    pub fn counts(&mut self, y: usize, simd: ListSimd) -> [u32; T] {
        debug_assert!(!self.overflowed[y]);
        #[cfg(target_arch = "x86_64")]
        if simd == ListSimd::Avx512 {
            // SAFETY: the caller passes Avx512 only after detecting AVX-512 F and POPCNT on
            // this CPU.
            return unsafe { self.transpose_avx512(y) };
        }
        let _ = simd;
        let mut c = [0u32; T];
        for wv in &self.w[y][..self.n[y]] {
            for (c, &w) in c.iter_mut().zip(wv) {
                *c += (w > 0.0) as u32;
            }
        }
        c
    }

    /// Writes each pixel's (id, weight) list of row `y`, front to back, where `dst` says.
    /// The row must not have overflowed; `dst.n` must be the pixels' contribution counts.
    /// Consumes the row: its log may be left transposed.
    #[inline(always)]
    pub fn write_lists(&mut self, y: usize, simd: ListSimd, dst: &mut RowDst) {
        debug_assert!(!self.overflowed[y]);
        #[cfg(target_arch = "x86_64")]
        if simd == ListSimd::Avx512 {
            // SAFETY: the caller passes Avx512 only after detecting AVX-512 F and POPCNT on
            // this CPU.
            unsafe { self.write_lists_avx512(y, dst) };
            return;
        }
        // Pixels whose list fits the scratch: walked there (then copied out if bound for the
        // output). Others go straight to the output, or nowhere if skipped.
        let mut fits = 0u32;
        for x in 0..T {
            fits |= ((dst.n[x] <= LIST_CAP && (dst.skip >> x) & 1 == 0) as u32) << x;
        }
        match simd {
            #[cfg(target_arch = "x86_64")]
            ListSimd::Avx2 => {
                // SAFETY: the caller passes Avx2 only after detecting AVX2 and POPCNT on this CPU.
                unsafe { self.walk_columns_avx2(y, fits, dst) };
                // Lists longer than the scratch (whole top-Ks, when K > LIST_CAP).
                self.walk_columns_one_by_one(y, !fits & ((1 << T) - 1), 0, dst);
            }
            _ => self.walk_columns(y, fits, dst),
        }
        for x in 0..T {
            if (fits >> x) & 1 != 0 && (dst.to_scratch >> x) & 1 == 0 {
                let (off, n) = (dst.off[x], dst.n[x]);
                dst.out_ids[off..off + n].copy_from_slice(&dst.scratch_ids[x][..n]);
                dst.out_ws[off..off + n].copy_from_slice(&dst.scratch_ws[x][..n]);
            }
        }
    }

    /// Walks row `y`'s pixel columns into the scratch lists (`fits`) or the output.
    fn walk_columns(&self, y: usize, fits: u32, dst: &mut RowDst) {
        let (w, g) = (&self.w[y][..self.n[y]], &self.g[y][..self.n[y]]);
        // Branch-free walks down the pixels' columns, four at a time (independent chains):
        // every visit is written, only contributions advance (len ≤ n ≤ LIST_CAP < STRIDE).
        const J: usize = 4;
        for x0 in (0..T).step_by(J) {
            let block = ((1u32 << J) - 1) << x0;
            if fits & block != block {
                self.walk_columns_one_by_one(y, block, fits, dst);
                continue;
            }
            let mut len = [0usize; J];
            for (wv, &gv) in w.iter().zip(g) {
                for (j, len) in len.iter_mut().enumerate() {
                    let x = x0 + j;
                    dst.scratch_ids[x][*len] = gv;
                    dst.scratch_ws[x][*len] = wv[x];
                    *len += (wv[x] > 0.0) as usize;
                }
            }
        }
    }

    /// The walk of [`RowLog::write_lists`] for the pixels in bit mask `xs`, one at a time:
    /// into the scratch if the list `fits`, else straight into the output unless skipped.
    #[inline(never)]
    fn walk_columns_one_by_one(&self, y: usize, xs: u32, fits: u32, dst: &mut RowDst) {
        let (w, g) = (&self.w[y][..self.n[y]], &self.g[y][..self.n[y]]);
        for x in (0..T).filter(|&x| (xs >> x) & 1 != 0) {
            let mut len = 0usize;
            if (fits >> x) & 1 != 0 {
                for (wv, &gv) in w.iter().zip(g) {
                    dst.scratch_ids[x][len] = gv;
                    dst.scratch_ws[x][len] = wv[x];
                    len += (wv[x] > 0.0) as usize;
                }
            } else if (dst.skip >> x) & 1 == 0 {
                let off = dst.off[x];
                for (wv, &gv) in w.iter().zip(g) {
                    if wv[x] > 0.0 {
                        dst.out_ids[off + len] = gv;
                        dst.out_ws[off + len] = wv[x];
                        len += 1;
                    }
                }
            }
        }
    }

    /// The column walk for the pixels that `fits`, on AVX2: blocks of 8 visits × 8 pixels
    /// are transposed in registers, and each pixel's contributions are packed to the front
    /// by a permutation from a table (AVX2 has no compress) and stored as a whole vector into
    /// its scratch list (the room past LIST_CAP takes the overhang).
    ///
    /// # Safety
    /// The caller must ensure the CPU supports AVX2 and POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt")]
    unsafe fn walk_columns_avx2(&self, y: usize, fits: u32, dst: &mut RowDst) {
        use std::arch::x86_64::*;
        let n = self.n[y];
        let zero = _mm256_setzero_ps();
        let scratch_ids = dst.scratch_ids.as_mut_ptr().cast::<u32>();
        let scratch_ws = dst.scratch_ws.as_mut_ptr().cast::<f32>();
        let mut len = [0usize; T];
        for b in (0..n).step_by(8) {
            // ROW_CAP is a multiple of 8: the block's 8 ids are in bounds.
            let ids = _mm256_loadu_si256(self.g[y][b..b + 8].as_ptr().cast());
            for h in 0..2 {
                if (fits >> (8 * h)) & 0xFF == 0 {
                    continue;
                }
                let mut rows = [zero; 8];
                for (v, row) in rows.iter_mut().enumerate().take(n - b) {
                    // SAFETY: 8 of the visit's 16 weights, from 8·h.
                    *row = unsafe { _mm256_loadu_ps(self.w[y][b + v][8 * h..].as_ptr()) };
                }
                let columns = transpose8(rows);
                for (j, col) in columns.iter().enumerate() {
                    let x = 8 * h + j;
                    if (fits >> x) & 1 == 0 {
                        continue;
                    }
                    let m = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(*col, zero)) as usize;
                    let perm = _mm256_loadu_si256(PACK8[m].as_ptr().cast());
                    // Memory safety does not rest on the counts matching the log.
                    assert!(len[x] + 8 <= STRIDE);
                    let at = x * STRIDE + len[x];
                    // SAFETY: 8 elements at `at` stay inside pixel x's STRIDE (checked).
                    unsafe {
                        _mm256_storeu_ps(scratch_ws.add(at), _mm256_permutevar8x32_ps(*col, perm));
                        _mm256_storeu_si256(
                            scratch_ids.add(at).cast(),
                            _mm256_permutevar8x32_epi32(ids, perm),
                        );
                    }
                    len[x] += m.count_ones() as usize;
                }
            }
        }
    }

    /// Transposes row `y` in place, 16 visits by 16 pixels at a time (16×16 in registers):
    /// entry `b + x` of block `b` becomes pixel x's column of the block's visits. Returns
    /// each pixel's contributions, counted on the visits before they are transposed.
    ///
    /// # Safety
    /// The caller must ensure the CPU supports AVX-512 F.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn transpose_avx512(&mut self, y: usize) -> [u32; T] {
        use std::arch::x86_64::*;
        debug_assert!(!self.transposed[y], "row {y} transposed twice");
        let n = self.n[y];
        let zero = _mm512_setzero_ps();
        let one = _mm512_set1_epi32(1);
        let mut counts = _mm512_setzero_si512();
        let w = &mut self.w[y];
        for b in (0..n).step_by(T) {
            // Visits past the last read as "no contribution". (Plain loops here and in the
            // transpose: closures would not inherit the target feature, nor be inlined.)
            let mut rows = [zero; T];
            for (v, row) in rows.iter_mut().enumerate().take(n - b) {
                // SAFETY: in bounds of the visit's 16 weights.
                *row = unsafe { _mm512_loadu_ps(w[b + v].as_ptr()) };
                let took = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(*row, zero);
                counts = _mm512_mask_add_epi32(counts, took, counts, one);
            }
            let columns = transpose16(rows);
            // ROW_CAP is a multiple of 16: the whole block is in the log.
            for (x, c) in columns.iter().enumerate() {
                // SAFETY: in bounds of the log entry's 16 lanes.
                unsafe { _mm512_storeu_ps(w[b + x].as_mut_ptr(), *c) };
            }
        }
        self.transposed[y] = true;
        let mut out = [0u32; T];
        // SAFETY: 16 u32 lanes into 16 u32.
        unsafe { _mm512_storeu_si512(out.as_mut_ptr().cast(), counts) };
        out
    }

    /// [`RowLog::write_lists`] 16 visits at a time: each block of 16 visits is transposed in
    /// place (16×16 in registers) into 16 pixel columns; then pixel by pixel, each column is
    /// compressed to the pixel's contributions and stored as a whole vector. Pixel by pixel,
    /// the stores run down the output in order (one stream per array, not 16 interleaved
    /// ones), and a vector's lanes past the list land where later lists (or the scratch's
    /// room past LIST_CAP) overwrite them: `dst.out_*` must hold 16 entries past the last list.
    ///
    /// # Safety
    /// The caller must ensure the CPU supports AVX-512 F and POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,popcnt")]
    unsafe fn write_lists_avx512(&mut self, y: usize, dst: &mut RowDst) {
        use std::arch::x86_64::*;
        if !self.transposed[y] {
            // SAFETY: the caller ensures AVX-512 F and POPCNT.
            unsafe { self.transpose_avx512(y) };
        }
        let n = self.n[y];
        let zero = _mm512_setzero_ps();
        let w = &self.w[y];
        let g = &self.g[y];
        for x in 0..T {
            // Nothing to write (pixels past a partial tile's edge have no region at all).
            if (dst.skip >> x) & 1 != 0 || dst.n[x] == 0 {
                continue;
            }
            // The pixel's destination, and the room behind it for whole-vector stores.
            let (at_ids, at_ws, room) = if (dst.to_scratch >> x) & 1 != 0 {
                (
                    dst.scratch_ids[x].as_mut_ptr(),
                    dst.scratch_ws[x].as_mut_ptr(),
                    STRIDE,
                )
            } else {
                let off = dst.off[x];
                let room = dst.out_ids.len().min(dst.out_ws.len());
                assert!(off <= room, "list offset past the output");
                // SAFETY: off ≤ len, just checked.
                unsafe {
                    (
                        dst.out_ids.as_mut_ptr().add(off),
                        dst.out_ws.as_mut_ptr().add(off),
                        room - off,
                    )
                }
            };
            let mut len = 0usize;
            for b in (0..n).step_by(T) {
                // SAFETY: block b's column x and ids are in the log (ROW_CAP is a multiple
                // of 16).
                let (column, ids) = unsafe {
                    (
                        _mm512_loadu_ps(w[b + x].as_ptr()),
                        _mm512_loadu_si512(g[b..b + T].as_ptr().cast()),
                    )
                };
                let m = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(column, zero);
                // Memory safety does not rest on the counts matching the log.
                assert!(len + T <= room, "list store past its room");
                // SAFETY: 16 lanes at len are within room, just checked.
                unsafe {
                    _mm512_storeu_ps(at_ws.add(len), _mm512_maskz_compress_ps(m, column));
                    _mm512_storeu_si512(
                        at_ids.add(len).cast(),
                        _mm512_maskz_compress_epi32(m, ids),
                    );
                }
                len += m.count_ones() as usize;
            }
            debug_assert_eq!(len, dst.n[x], "pixel {x}: log and counts disagree");
        }
    }
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

/// Transposes an 8×8 block of f32 (row v, lane x → row x, lane v).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn transpose8(r: [std::arch::x86_64::__m256; 8]) -> [std::arch::x86_64::__m256; 8] {
    use std::arch::x86_64::*;
    let t = [
        _mm256_unpacklo_ps(r[0], r[1]),
        _mm256_unpackhi_ps(r[0], r[1]),
        _mm256_unpacklo_ps(r[2], r[3]),
        _mm256_unpackhi_ps(r[2], r[3]),
        _mm256_unpacklo_ps(r[4], r[5]),
        _mm256_unpackhi_ps(r[4], r[5]),
        _mm256_unpacklo_ps(r[6], r[7]),
        _mm256_unpackhi_ps(r[6], r[7]),
    ];
    let u = [
        _mm256_shuffle_ps::<0x44>(t[0], t[2]),
        _mm256_shuffle_ps::<0xEE>(t[0], t[2]),
        _mm256_shuffle_ps::<0x44>(t[1], t[3]),
        _mm256_shuffle_ps::<0xEE>(t[1], t[3]),
        _mm256_shuffle_ps::<0x44>(t[4], t[6]),
        _mm256_shuffle_ps::<0xEE>(t[4], t[6]),
        _mm256_shuffle_ps::<0x44>(t[5], t[7]),
        _mm256_shuffle_ps::<0xEE>(t[5], t[7]),
    ];
    [
        _mm256_permute2f128_ps::<0x20>(u[0], u[4]),
        _mm256_permute2f128_ps::<0x20>(u[1], u[5]),
        _mm256_permute2f128_ps::<0x20>(u[2], u[6]),
        _mm256_permute2f128_ps::<0x20>(u[3], u[7]),
        _mm256_permute2f128_ps::<0x31>(u[0], u[4]),
        _mm256_permute2f128_ps::<0x31>(u[1], u[5]),
        _mm256_permute2f128_ps::<0x31>(u[2], u[6]),
        _mm256_permute2f128_ps::<0x31>(u[3], u[7]),
    ]
}

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

#[cfg(test)]
mod tests {
    use super::*;

    /// Lists of a row with `visits` visits (visit v reaches pixel x when (v + x) % 3 != 0),
    /// pixel x's going to the scratch lists if bit x of `to_scratch` is set, nowhere (None)
    /// if bit x of `skip` is, else to the output.
    fn lists(
        visits: usize,
        simd: ListSimd,
        to_scratch: u32,
        skip: u32,
    ) -> Vec<Option<Vec<(u32, f32)>>> {
        let weight = |v: usize, x: usize| {
            if !(v + x).is_multiple_of(3) {
                (v * T + x + 1) as f32
            } else {
                0.0
            }
        };
        lists_of(visits, weight, T, simd, to_scratch, skip, false)
    }

    /// [`lists`] for visit weights `weight(v, x)` on a tile `cols` pixels wide: pixels past
    /// it have no region in the output (offset 0, no entries), as at the image's edge. With
    /// `count_first`, the row is counted first (and the counts checked), as the renderer does.
    fn lists_of(
        visits: usize,
        weight: impl Fn(usize, usize) -> f32,
        cols: usize,
        simd: ListSimd,
        to_scratch: u32,
        skip: u32,
        count_first: bool,
    ) -> Vec<Option<Vec<(u32, f32)>>> {
        let mut log = RowLog::new();
        for v in 0..visits {
            let w: [f32; T] = std::array::from_fn(|x| if x < cols { weight(v, x) } else { 0.0 });
            log.push(5, 1000 + v as u32, &w);
        }
        let n: [usize; T] = std::array::from_fn(|x| {
            (0..visits)
                .filter(|&v| x < cols && weight(v, x) > 0.0)
                .count()
        });
        if count_first {
            let counted = log.counts(5, simd);
            assert!(
                counted.iter().zip(&n).all(|(&c, &n)| c as usize == n),
                "{simd:?}"
            );
        }
        let mut off = [0usize; T];
        for x in 1..cols {
            off[x] = off[x - 1] + n[x - 1];
        }
        let total = n.iter().sum::<usize>();
        // Filler the readers must overwrite exactly where lists go.
        let (mut out_ids, mut out_ws) = (vec![7u32; total + T], vec![-1.0f32; total + T]);
        let mut scratch_ids = Box::new([[0u32; STRIDE]; T]);
        let mut scratch_ws = Box::new([[0.0f32; STRIDE]; T]);
        let mut dst = RowDst {
            out_ids: &mut out_ids,
            out_ws: &mut out_ws,
            off,
            n,
            scratch_ids: &mut scratch_ids,
            scratch_ws: &mut scratch_ws,
            to_scratch,
            skip,
        };
        log.write_lists(5, simd, &mut dst);
        (0..T)
            .map(|x| {
                let (ids, ws) = if (skip >> x) & 1 != 0 {
                    return None;
                } else if (to_scratch >> x) & 1 != 0 {
                    (&scratch_ids[x][..n[x]], &scratch_ws[x][..n[x]])
                } else {
                    (
                        &out_ids[off[x]..off[x] + n[x]],
                        &out_ws[off[x]..off[x] + n[x]],
                    )
                };
                Some(ids.iter().copied().zip(ws.iter().copied()).collect())
            })
            .collect()
    }

    /// The list readers this CPU can run.
    fn simds_here() -> Vec<ListSimd> {
        #[allow(unused_mut)]
        let mut v = vec![ListSimd::Portable];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("popcnt")
            {
                v.push(ListSimd::Avx2);
            }
            if std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("popcnt")
            {
                v.push(ListSimd::Avx512);
            }
        }
        v
    }

    #[test]
    fn lists_are_each_pixels_visits_front_to_back() {
        // 37 visits: whole 8- and 16-visit blocks and a partial one; odd pixels to the scratch.
        for simd in simds_here() {
            let got = lists(37, simd, 0xAAAA, 0);
            for (x, list) in got.iter().enumerate() {
                let want: Vec<(u32, f32)> = (0..37)
                    .filter(|v| !(v + x).is_multiple_of(3))
                    .map(|v| (1000 + v as u32, (v * T + x + 1) as f32))
                    .collect();
                assert_eq!(list.as_ref(), Some(&want), "{simd:?} pixel {x}");
            }
        }
    }

    #[test]
    fn counts_then_lists_match_lists_alone() {
        // Counting first (which transposes the row on AVX-512) must not change the lists.
        let weight = |v: usize, x: usize| {
            if (v * 7 + x * 3) % 5 < 2 {
                (v * T + x + 1) as f32
            } else {
                0.0
            }
        };
        for simd in simds_here() {
            for visits in [1, 16, 37, 100] {
                for to_scratch in [0, 0x0F0F] {
                    assert_eq!(
                        lists_of(visits, weight, T, simd, to_scratch, 0, true),
                        lists_of(visits, weight, T, ListSimd::Portable, to_scratch, 0, false),
                        "{simd:?}, {visits} visits"
                    );
                }
            }
        }
    }

    #[test]
    fn pixels_without_contributions_write_nothing() {
        // A partial tile: pixels 12–15 are past the image edge (no region, offset 0), pixel 5
        // took nothing; the other lists lie back to back and must all come out whole.
        let weight = |v: usize, x: usize| if x != 5 { (v + 1) as f32 } else { 0.0 };
        for simd in simds_here() {
            let got = lists_of(21, weight, 12, simd, 0, 0, false);
            for (x, list) in got.iter().enumerate() {
                let want: Vec<(u32, f32)> = if x < 12 && x != 5 {
                    (0..21).map(|v| (1000 + v as u32, (v + 1) as f32)).collect()
                } else {
                    Vec::new()
                };
                assert_eq!(list.as_ref(), Some(&want), "{simd:?} pixel {x}");
            }
        }
    }

    #[test]
    fn skipped_pixels_may_have_more_than_the_scratch_holds() {
        // A full log: every pixel has ~683 contributions; pixels 0–3 and 9 go to the output,
        // the rest are skipped (they would not fit the scratch lists).
        let skip = !0x20F & 0xFFFF;
        for simd in simds_here() {
            let got = lists(ROW_CAP, simd, 0, skip);
            for (x, list) in got.iter().enumerate() {
                assert_eq!(list.is_none(), (skip >> x) & 1 != 0, "{simd:?} pixel {x}");
                if let Some(list) = list {
                    assert!(list.len() > LIST_CAP);
                    assert!(list.iter().zip(&list[1..]).all(|(a, b)| a.0 < b.0));
                }
            }
        }
    }

    #[test]
    fn simd_lists_match_portable() {
        for simd in simds_here() {
            for visits in [1, 8, 16, 37, 200] {
                for (to_scratch, skip) in [(0xAAAA, 0), (0x00F0, 0x0F00), (0, 0)] {
                    assert_eq!(
                        lists(visits, simd, to_scratch, skip),
                        lists(visits, ListSimd::Portable, to_scratch, skip),
                        "{simd:?}, {visits} visits"
                    );
                }
            }
        }
    }

    #[test]
    fn a_full_row_overflows() {
        let mut log = RowLog::new();
        for v in 0..ROW_CAP {
            log.push(2, v as u32, &[1.0; T]);
        }
        assert!(!log.overflowed(2));
        log.push(2, 7, &[1.0; T]);
        assert!(log.overflowed(2) && !log.overflowed(3));
        log.clear();
        assert!(!log.overflowed(2));
    }
}
