//! The mapping loss and its gradient in one streaming pass over the image (what
//! [`crate::Loss::eval`] runs; the plane-by-plane twin it replaced is `reference::loss_reference`).
//!
//! The image is cut into bands of rows, one rayon task each. A band walks its rows top to
//! bottom, four at a time, and keeps per colour channel two rings of 16 rows (a vertical
//! block's 14-row window plus slack):
//! 1. the horizontal blurs of x, y, x², y², xy of each new input row;
//! 2. per moment row m: the vertical blurs give the five moments (μx, μy, m_xx, m_yy, m_xy),
//!    from which SSIM and scale·∂ssim/∂(μx, m_xx, m_xy) follow; those three are blurred
//!    horizontally into the second ring;
//! 3. per gradient row g (5 rows behind): their vertical blurs give
//!    ∂Σssim/∂x = G∗(∂/∂μx) + 2x·G∗(∂/∂m_xx) + y·G∗(∂/∂m_xy) (see [`crate::ssim`]), written
//!    with the L1 term, the row's L1, squared error and depth term in the same place.
//!
//! Each moment is computed once and used by both the value and the gradient; a band
//! recomputes the 10 rows above and below it that its neighbours also compute, so each
//! pixel's arithmetic does not depend on the split. Zero padding (3DGS's
//! `conv2d(padding = 5)`) is a zero row outside the image and zero columns in the padded row
//! buffers. The symmetric kernel shares one multiply per pair of taps; vertical blurs make
//! four rows per pass (14 loads instead of 44); the AVX levels fuse multiply-adds. Every
//! buffer belongs to [`BandScratch`], reused across steps.

use crate::cpu::SimdLevel;
use crate::ssim::{kernel, RADIUS, SSIM_C1, SSIM_C2, TAPS};

/// Moments per channel: x, y, x², y², xy.
const MOMENTS: usize = 5;
/// Gradient planes per channel: ∂/∂μx, ∂/∂m_xx, ∂/∂m_xy.
const DPLANES: usize = 3;
/// Lanes of the f32 partial sums (one AVX-512 register).
const LANES: usize = 16;
/// Rows blurred vertically at once.
const BLOCK: usize = 4;
/// Input rows of a vertical block.
const WINDOW: usize = BLOCK + 2 * RADIUS;
/// Ring slots: a block's window plus the rows a pending gradient block still needs.
const RING: usize = 16;

/// Inputs and per-term factors of one evaluation.
pub(crate) struct LossInputs<'a> {
    pub color: &'a [[f32; 3]],
    pub depth: &'a [f32],
    pub target_rgb: [&'a [f32]; 3],
    pub target_depth: &'a [f32],
    pub width: usize,
    pub height: usize,
    /// dL/dC of the L1 term per unit sign: w_l1 / 3n.
    pub k_l1: f32,
    /// dL/dssim_p: −w_ssim / 3n.
    pub k_ssim: f32,
    /// dL/dD per unit sign: w_depth / (valid depth pixels).
    pub k_depth: f32,
}

/// Unnormalised sums of a band.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct BandSums {
    /// Σ ssim over pixels and channels.
    pub ssim: f64,
    /// Σ |C − Ĉ| over pixels and channels.
    pub l1: f64,
    /// Σ (clamp(C, 0, 1) − Ĉ)².
    pub sq_err: f64,
    /// Σ |D − D̂| over pixels with valid target depth.
    pub depth: f64,
}

impl BandSums {
    pub fn add(self, o: Self) -> Self {
        Self {
            ssim: self.ssim + o.ssim,
            l1: self.l1 + o.l1,
            sq_err: self.sq_err + o.sq_err,
            depth: self.depth + o.depth,
        }
    }
}

/// One band's buffers (a few hundred KB at 640 wide: the rings stay in L2).
#[derive(Debug, Default)]
pub(crate) struct BandScratch {
    width: usize,
    /// Ring of horizontal moment blurs: [channel][moment][slot][x].
    hm: Vec<f32>,
    /// Ring of horizontal blurs of the gradient planes: [channel][plane][slot][x].
    hd: Vec<f32>,
    /// Zero-padded rows (RADIUS zeros each side): the five moment inputs of a row, then
    /// the three gradient planes of a row.
    pad: Vec<f32>,
    /// Row buffers of `width`: BLOCK rows of each of the five moments and the three blurred
    /// gradient planes, ssim, x, then BLOCK rows of each channel's gradient.
    rows: Vec<f32>,
    /// A row of zeros: the rows outside the image.
    zero: Vec<f32>,
}

impl BandScratch {
    fn prepare(&mut self, w: usize) {
        if self.width == w {
            return;
        }
        self.width = w;
        let pw = w + 2 * RADIUS;
        self.hm = vec![0.0; 3 * MOMENTS * RING * w];
        self.hd = vec![0.0; 3 * DPLANES * RING * w];
        self.pad = vec![0.0; (MOMENTS + DPLANES) * pw];
        self.rows = vec![0.0; ((MOMENTS + DPLANES + 3) * BLOCK + 2) * w];
        self.zero = vec![0.0; w];
    }
}

/// Rows per band for an image `height` rows high on `threads` threads: two bands per
/// thread (balance on a shared machine), at least 48 rows (the 20 rows a band recomputes).
pub(crate) fn band_rows(height: usize, threads: usize) -> usize {
    height
        .div_ceil(2 * threads.max(1))
        .max(48)
        .min(height.max(1))
}

/// Loss sums of rows `r0..r1`, writing their dL/dC (`gc`) and dL/dD (`gd`), which hold
/// exactly those rows.
pub(crate) fn band(
    simd: SimdLevel,
    inp: &LossInputs,
    r0: usize,
    r1: usize,
    gc: &mut [[f32; 3]],
    gd: &mut [f32],
    s: &mut BandScratch,
) -> BandSums {
    #[cfg(target_arch = "x86_64")]
    let fma = std::arch::is_x86_feature_detected!("fma");
    match simd {
        // SAFETY: the Avx512 level has AVX-512F (SimdLevel::detected), FMA was detected.
        #[cfg(target_arch = "x86_64")]
        SimdLevel::Avx512 if fma => unsafe { band_avx512(inp, r0, r1, gc, gd, s) },
        // SAFETY: the Avx2 level has AVX2 (SimdLevel::detected), FMA was detected.
        #[cfg(target_arch = "x86_64")]
        SimdLevel::Avx2 | SimdLevel::Avx512 if fma => unsafe { band_avx2(inp, r0, r1, gc, gd, s) },
        _ => band_portable::<false>(inp, r0, r1, gc, gd, s),
    }
}

/// # Safety
/// The caller must ensure the CPU supports AVX-512F and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn band_avx512(
    inp: &LossInputs,
    r0: usize,
    r1: usize,
    gc: &mut [[f32; 3]],
    gd: &mut [f32],
    s: &mut BandScratch,
) -> BandSums {
    band_portable::<true>(inp, r0, r1, gc, gd, s)
}

/// # Safety
/// The caller must ensure the CPU supports AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn band_avx2(
    inp: &LossInputs,
    r0: usize,
    r1: usize,
    gc: &mut [[f32; 3]],
    gd: &mut [f32],
    s: &mut BandScratch,
) -> BandSums {
    band_portable::<true>(inp, r0, r1, gc, gd, s)
}

/// `a·b + c`, fused where the caller's level has FMA (`mul_add` without it is a libm call).
#[inline(always)]
fn madd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

// Hand-written streaming kernel: the loss runs every mapping step (the hot path), and only a
// fused pass keeps its ~20 planes per channel out of memory. Every helper below is
// `inline(always)` so that the SIMD wrappers above compile the whole band for their level.
#[inline(always)]
fn band_portable<const FMA: bool>(
    inp: &LossInputs,
    r0: usize,
    r1: usize,
    gc: &mut [[f32; 3]],
    gd: &mut [f32],
    s: &mut BandScratch,
) -> BandSums {
    let (w, h) = (inp.width, inp.height);
    debug_assert!(r0 < r1 && r1 <= h);
    debug_assert!(gc.len() == (r1 - r0) * w && gd.len() == (r1 - r0) * w);
    s.prepare(w);
    let k = kernel();
    let pw = w + 2 * RADIUS;
    let mut sums = BandSums::default();
    let m_lo = r0.saturating_sub(RADIUS);
    let m_hi = (r1 + RADIUS).min(h);
    let mut next_in = m_lo.saturating_sub(RADIUS);
    let mut next_g = r0;
    let BandScratch {
        hm,
        hd,
        pad,
        rows,
        zero,
        ..
    } = s;
    let (pad_m, pad_d) = pad.split_at_mut(MOMENTS * pw);
    let (mom, rest) = rows.split_at_mut(MOMENTS * BLOCK * w);
    let (bd, rest) = rest.split_at_mut(DPLANES * BLOCK * w);
    let (ssim_row, rest) = rest.split_at_mut(w);
    let (x_row, g_rows) = rest.split_at_mut(w);
    let ring_len = RING * w;

    let mut m = m_lo;
    while m < m_hi {
        let m_end = (m + BLOCK).min(m_hi);
        // 1. Horizontal moment blurs of the input rows up to m_end − 1 + RADIUS.
        let need = (m_end - 1 + RADIUS).min(h - 1);
        while next_in <= need {
            let y = next_in;
            let slot = (y % RING) * w;
            for c in 0..3 {
                let (px, rest) = pad_m.split_at_mut(pw);
                let (py, rest) = rest.split_at_mut(pw);
                let (pxx, rest) = rest.split_at_mut(pw);
                let (pyy, pxy) = rest.split_at_mut(pw);
                let color = &inp.color[y * w..(y + 1) * w];
                let t = &inp.target_rgb[c][y * w..(y + 1) * w];
                moment_inputs(
                    color,
                    c,
                    t,
                    &mut px[RADIUS..RADIUS + w],
                    &mut py[RADIUS..RADIUS + w],
                    &mut pxx[RADIUS..RADIUS + w],
                    &mut pyy[RADIUS..RADIUS + w],
                    &mut pxy[RADIUS..RADIUS + w],
                );
                for j in 0..MOMENTS {
                    let ring = &mut hm[(c * MOMENTS + j) * ring_len..][..ring_len];
                    hblur::<FMA>(&k, &pad_m[j * pw..(j + 1) * pw], &mut ring[slot..slot + w]);
                }
            }
            next_in += 1;
        }

        // 2. Moments of rows m..m_end, SSIM, and the horizontal blurs of the gradient planes.
        for c in 0..3 {
            for j in 0..MOMENTS {
                let ring = &hm[(c * MOMENTS + j) * ring_len..][..ring_len];
                let src = window_rows(ring, zero, m, h, w);
                vblur_block::<FMA>(&k, &src, &mut mom[j * BLOCK * w..(j + 1) * BLOCK * w]);
            }
            for r in m..m_end {
                let o = (r - m) * w;
                let plane = |j: usize| &mom[(j * BLOCK) * w + o..][..w];
                let (d_mu, rest) = pad_d.split_at_mut(pw);
                let (d_xx, d_xy) = rest.split_at_mut(pw);
                ssim_terms(
                    inp.k_ssim,
                    plane(0),
                    plane(1),
                    plane(2),
                    plane(3),
                    plane(4),
                    ssim_row,
                    &mut d_mu[RADIUS..RADIUS + w],
                    &mut d_xx[RADIUS..RADIUS + w],
                    &mut d_xy[RADIUS..RADIUS + w],
                );
                if (r0..r1).contains(&r) {
                    sums.ssim += lane_sum(ssim_row);
                }
                let slot = (r % RING) * w;
                for j in 0..DPLANES {
                    let ring = &mut hd[(c * DPLANES + j) * ring_len..][..ring_len];
                    hblur::<FMA>(&k, &pad_d[j * pw..(j + 1) * pw], &mut ring[slot..slot + w]);
                }
            }
        }

        // 3. Gradient rows whose window of gradient-plane rows is complete, in blocks.
        let ready = if m_end == h {
            Some(h - 1)
        } else {
            (m_end - 1).checked_sub(RADIUS)
        };
        m = m_end;
        let Some(ready) = ready else { continue };
        while next_g < r1 && next_g <= ready {
            let g0 = next_g;
            let g_end = (g0 + BLOCK).min(ready + 1).min(r1);
            for c in 0..3 {
                for j in 0..DPLANES {
                    let ring = &hd[(c * DPLANES + j) * ring_len..][..ring_len];
                    let src = window_rows(ring, zero, g0, h, w);
                    vblur_block::<FMA>(&k, &src, &mut bd[j * BLOCK * w..(j + 1) * BLOCK * w]);
                }
                for g in g0..g_end {
                    let o = (g - g0) * w;
                    let plane = |j: usize| &bd[(j * BLOCK) * w + o..][..w];
                    let (l1, sq) = color_gradient(
                        inp.k_l1,
                        &inp.color[g * w..(g + 1) * w],
                        c,
                        &inp.target_rgb[c][g * w..(g + 1) * w],
                        plane(0),
                        plane(1),
                        plane(2),
                        x_row,
                        &mut g_rows[(c * BLOCK) * w + o..][..w],
                    );
                    sums.l1 += l1;
                    sums.sq_err += sq;
                }
            }
            for g in g0..g_end {
                let (o, og) = ((g - g0) * w, (g - r0) * w);
                let ch = |c: usize| &g_rows[(c * BLOCK) * w + o..][..w];
                interleave(ch(0), ch(1), ch(2), &mut gc[og..og + w]);
                sums.depth += depth_row(
                    inp.k_depth,
                    &inp.depth[g * w..(g + 1) * w],
                    &inp.target_depth[g * w..(g + 1) * w],
                    &mut gd[og..og + w],
                );
            }
            next_g = g_end;
        }
    }
    debug_assert_eq!(next_g, r1);
    sums
}

/// The WINDOW rows `row − RADIUS .. row + BLOCK + RADIUS` of a ring (slot = row mod RING),
/// zero rows outside the image (rows past the block's end may be stale: their outputs are
/// not used).
#[inline(always)]
fn window_rows<'a>(
    ring: &'a [f32],
    zero: &'a [f32],
    row: usize,
    h: usize,
    w: usize,
) -> [&'a [f32]; WINDOW] {
    std::array::from_fn(|t| {
        let r = row as isize + t as isize - RADIUS as isize;
        if r < 0 || r >= h as isize {
            &zero[..w]
        } else {
            let slot = (r as usize % RING) * w;
            &ring[slot..slot + w]
        }
    })
}

/// x, y, x², y², xy of one row of channel `c`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn moment_inputs(
    color: &[[f32; 3]],
    c: usize,
    t: &[f32],
    px: &mut [f32],
    py: &mut [f32],
    pxx: &mut [f32],
    pyy: &mut [f32],
    pxy: &mut [f32],
) {
    let w = px.len();
    let (color, t) = (&color[..w], &t[..w]);
    let (py, pxx, pyy, pxy) = (&mut py[..w], &mut pxx[..w], &mut pyy[..w], &mut pxy[..w]);
    for i in 0..w {
        let (x, y) = (color[i][c], t[i]);
        px[i] = x;
        py[i] = y;
        pxx[i] = x * x;
        pyy[i] = y * y;
        pxy[i] = x * y;
    }
}

/// `dst = g ∗ src` along a row: `src` is the row with RADIUS zeros on each side. The kernel
/// is symmetric: pairs of taps share one multiply.
#[inline(always)]
fn hblur<const FMA: bool>(k: &[f32; TAPS], src: &[f32], dst: &mut [f32]) {
    let w = dst.len();
    let s: [&[f32]; TAPS] = std::array::from_fn(|t| &src[t..t + w]);
    symmetric_sum::<FMA>(k, &s, dst);
}

/// `dst` (BLOCK rows) `= g ∗` the rows of the window, along the column: each loaded value
/// serves up to four output rows (14 loads for 4 rows instead of 44).
#[inline(always)]
fn vblur_block<const FMA: bool>(k: &[f32; TAPS], rows: &[&[f32]; WINDOW], dst: &mut [f32]) {
    let w = dst.len() / BLOCK;
    let s: [&[f32]; WINDOW] = std::array::from_fn(|t| &rows[t][..w]);
    let (d0, rest) = dst.split_at_mut(w);
    let (d1, rest) = rest.split_at_mut(w);
    let (d2, d3) = rest.split_at_mut(w);
    let d3 = &mut d3[..w];
    let [k0, k1, k2, k3, k4, k5, ..] = *k;
    let [s0, s1, s2, s3, s4, s5, s6, s7, s8, s9, s10, s11, s12, s13] = s;
    for i in 0..w {
        let v = [
            s0[i], s1[i], s2[i], s3[i], s4[i], s5[i], s6[i], s7[i], s8[i], s9[i], s10[i], s11[i],
            s12[i], s13[i],
        ];
        macro_rules! out {
            ($o:expr) => {{
                let acc = madd::<FMA>(k4, v[$o + 4] + v[$o + 6], k5 * v[$o + 5]);
                let acc = madd::<FMA>(k3, v[$o + 3] + v[$o + 7], acc);
                let acc = madd::<FMA>(k2, v[$o + 2] + v[$o + 8], acc);
                let acc = madd::<FMA>(k1, v[$o + 1] + v[$o + 9], acc);
                madd::<FMA>(k0, v[$o] + v[$o + 10], acc)
            }};
        }
        d0[i] = out!(0);
        d1[i] = out!(1);
        d2[i] = out!(2);
        d3[i] = out!(3);
    }
}

#[inline(always)]
fn symmetric_sum<const FMA: bool>(k: &[f32; TAPS], s: &[&[f32]; TAPS], dst: &mut [f32]) {
    let w = dst.len();
    let [s0, s1, s2, s3, s4, s5, s6, s7, s8, s9, s10] = s.map(|r| &r[..w]);
    let [k0, k1, k2, k3, k4, k5, ..] = *k;
    for i in 0..w {
        let acc = madd::<FMA>(k4, s4[i] + s6[i], k5 * s5[i]);
        let acc = madd::<FMA>(k3, s3[i] + s7[i], acc);
        let acc = madd::<FMA>(k2, s2[i] + s8[i], acc);
        let acc = madd::<FMA>(k1, s1[i] + s9[i], acc);
        dst[i] = madd::<FMA>(k0, s0[i] + s10[i], acc);
    }
}

/// Per pixel of a row: ssim from the five moments, and `k_ssim · ∂ssim/∂(μx, m_xx, m_xy)`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn ssim_terms(
    k_ssim: f32,
    mux: &[f32],
    muy: &[f32],
    mxx: &[f32],
    myy: &[f32],
    mxy: &[f32],
    ssim: &mut [f32],
    d_mu: &mut [f32],
    d_xx: &mut [f32],
    d_xy: &mut [f32],
) {
    let w = ssim.len();
    let (mux, muy, mxx, myy, mxy) = (&mux[..w], &muy[..w], &mxx[..w], &myy[..w], &mxy[..w]);
    let (d_mu, d_xx, d_xy) = (&mut d_mu[..w], &mut d_xx[..w], &mut d_xy[..w]);
    for i in 0..w {
        let (ux, uy) = (mux[i], muy[i]);
        let a1 = 2.0 * ux * uy + SSIM_C1;
        let a2 = 2.0 * (mxy[i] - ux * uy) + SSIM_C2;
        let b1 = ux * ux + uy * uy + SSIM_C1;
        let b2 = (mxx[i] - ux * ux) + (myy[i] - uy * uy) + SSIM_C2;
        // Two divisions instead of three (1/(b1·b2) as their product).
        let (inv_b1, inv_b2) = (1.0 / b1, 1.0 / b2);
        let inv = inv_b1 * inv_b2;
        let v = a1 * a2 * inv;
        ssim[i] = v;
        d_mu[i] = k_ssim * (2.0 * uy * (a2 - a1) * inv + v * 2.0 * ux * (inv_b2 - inv_b1));
        d_xx[i] = k_ssim * (-v * inv_b2);
        d_xy[i] = k_ssim * 2.0 * a1 * inv;
    }
}

/// dL/dC of channel `c` along a row (L1 sign term + the blurred SSIM terms); returns the
/// row's Σ|C − Ĉ| and Σ(clamp(C, 0, 1) − Ĉ)².
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn color_gradient(
    k_l1: f32,
    color: &[[f32; 3]],
    c: usize,
    t: &[f32],
    b_mu: &[f32],
    b_xx: &[f32],
    b_xy: &[f32],
    x_row: &mut [f32],
    out: &mut [f32],
) -> (f64, f64) {
    let w = out.len();
    let (color, t, x_row) = (&color[..w], &t[..w], &mut x_row[..w]);
    let (b_mu, b_xx, b_xy) = (&b_mu[..w], &b_xx[..w], &b_xy[..w]);
    for i in 0..w {
        x_row[i] = color[i][c];
    }
    for i in 0..w {
        let (x, y) = (x_row[i], t[i]);
        out[i] = k_l1 * sign(x - y) + (b_mu[i] + 2.0 * x * b_xx[i] + y * b_xy[i]);
    }
    let mut abs = [0.0f32; LANES];
    let mut sq = [0.0f32; LANES];
    let (xc, tc) = (x_row.chunks_exact(LANES), t.chunks_exact(LANES));
    let tail = xc.remainder().iter().zip(tc.remainder());
    let (mut a, mut q) = tail.fold((0.0f64, 0.0f64), |(a, q), (&x, &y)| {
        let e = x.clamp(0.0, 1.0) - y;
        (a + (x - y).abs() as f64, q + (e * e) as f64)
    });
    for (xs, ts) in xc.zip(tc) {
        for l in 0..LANES {
            abs[l] += (xs[l] - ts[l]).abs();
            let e = xs[l].clamp(0.0, 1.0) - ts[l];
            sq[l] += e * e;
        }
    }
    a += abs.iter().map(|&v| v as f64).sum::<f64>();
    q += sq.iter().map(|&v| v as f64).sum::<f64>();
    (a, q)
}

/// The three channel rows into the interleaved gradient.
#[inline(always)]
fn interleave(g0: &[f32], g1: &[f32], g2: &[f32], out: &mut [[f32; 3]]) {
    let w = out.len();
    let (g0, g1, g2) = (&g0[..w], &g1[..w], &g2[..w]);
    for i in 0..w {
        out[i] = [g0[i], g1[i], g2[i]];
    }
}

/// dL/dD along a row (0 where the target has no depth); returns Σ|D − D̂| over valid pixels.
#[inline(always)]
fn depth_row(k_depth: f32, d: &[f32], t: &[f32], out: &mut [f32]) -> f64 {
    let w = out.len();
    let (d, t) = (&d[..w], &t[..w]);
    let mut acc = [0.0f32; LANES];
    let mut i = 0;
    while i + LANES <= w {
        for l in 0..LANES {
            let (dv, tv) = (d[i + l], t[i + l]);
            let valid = tv > 0.0;
            out[i + l] = if valid { k_depth * sign(dv - tv) } else { 0.0 };
            acc[l] += if valid { (dv - tv).abs() } else { 0.0 };
        }
        i += LANES;
    }
    let mut sum = acc.iter().map(|&v| v as f64).sum::<f64>();
    for i in i..w {
        let valid = t[i] > 0.0;
        out[i] = if valid {
            k_depth * sign(d[i] - t[i])
        } else {
            0.0
        };
        if valid {
            sum += (d[i] - t[i]).abs() as f64;
        }
    }
    sum
}

/// Σ of a row in f64, via 16 f32 lanes (vectorises; rows are short).
#[inline(always)]
fn lane_sum(v: &[f32]) -> f64 {
    let mut acc = [0.0f32; LANES];
    let mut chunks = v.chunks_exact(LANES);
    for ch in &mut chunks {
        for l in 0..LANES {
            acc[l] += ch[l];
        }
    }
    let tail: f64 = chunks.remainder().iter().map(|&x| x as f64).sum();
    acc.iter().map(|&x| x as f64).sum::<f64>() + tail
}

/// sign(v), 0 at 0 (and for NaN): the L1 subgradient.
#[inline(always)]
pub(crate) fn sign(v: f32) -> f32 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}
