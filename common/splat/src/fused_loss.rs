//! The mapping loss and its gradient in one streaming pass over the image (what
//! [`crate::Loss::eval`] runs; the plane-by-plane twin it replaced is `reference::loss_reference`).
//!
//! The image is cut into bands of rows, one rayon task each. A band walks its rows top to
//! bottom and keeps, per colour channel, two rings of 11 rows (the window's height):
//! 1. the horizontal blurs of x, y, x², y², xy of each new input row;
//! 2. per moment row m: the vertical blurs give the five moments (μx, μy, m_xx, m_yy, m_xy),
//!    from which SSIM and scale·∂ssim/∂(μx, m_xx, m_xy) follow; those three are blurred
//!    horizontally into the second ring;
//! 3. per gradient row g (5 rows behind): their vertical blurs give
//!    ∂Σssim/∂x = G∗(∂/∂μx) + 2x·G∗(∂/∂m_xx) + y·G∗(∂/∂m_xy) (see [`crate::ssim`]), written
//!    with the L1 term, the row's L1, squared error and depth term in the same place.
//!
//! Each moment is computed once and used by both the value and the gradient; a band
//! recomputes the 10 rows above and below it that its neighbours also compute. Zero padding
//! (3DGS's `conv2d(padding = 5)`) is a zero row outside the image and zero columns in the
//! padded row buffers. Every buffer belongs to [`BandScratch`], reused across steps.

use crate::cpu::SimdLevel;
use crate::ssim::{kernel, RADIUS, SSIM_C1, SSIM_C2, TAPS};

/// Moments per channel: x, y, x², y², xy.
const MOMENTS: usize = 5;
/// Gradient planes per channel: ∂/∂μx, ∂/∂m_xx, ∂/∂m_xy.
const DPLANES: usize = 3;
/// Lanes of the f32 partial sums (one AVX-512 register).
const LANES: usize = 16;

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
    /// Row buffers of `width`: five moments, three blurred gradient planes, ssim, x, then
    /// three per-channel gradient rows.
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
        self.hm = vec![0.0; 3 * MOMENTS * TAPS * w];
        self.hd = vec![0.0; 3 * DPLANES * TAPS * w];
        self.pad = vec![0.0; (MOMENTS + DPLANES) * pw];
        self.rows = vec![0.0; (MOMENTS + DPLANES + 2 + 3) * w];
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
    match simd {
        // SAFETY: the Avx512 level has AVX-512F (SimdLevel::detected).
        #[cfg(target_arch = "x86_64")]
        SimdLevel::Avx512 => unsafe { band_avx512(inp, r0, r1, gc, gd, s) },
        // SAFETY: the Avx2 level has AVX2 (SimdLevel::detected).
        #[cfg(target_arch = "x86_64")]
        SimdLevel::Avx2 => unsafe { band_avx2(inp, r0, r1, gc, gd, s) },
        SimdLevel::Portable => band_portable(inp, r0, r1, gc, gd, s),
    }
}

/// # Safety
/// The caller must ensure the CPU supports AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
unsafe fn band_avx512(
    inp: &LossInputs,
    r0: usize,
    r1: usize,
    gc: &mut [[f32; 3]],
    gd: &mut [f32],
    s: &mut BandScratch,
) -> BandSums {
    band_portable(inp, r0, r1, gc, gd, s)
}

/// # Safety
/// The caller must ensure the CPU supports AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn band_avx2(
    inp: &LossInputs,
    r0: usize,
    r1: usize,
    gc: &mut [[f32; 3]],
    gd: &mut [f32],
    s: &mut BandScratch,
) -> BandSums {
    band_portable(inp, r0, r1, gc, gd, s)
}

// Hand-written streaming kernel: the loss runs every mapping step (the hot path), and only a
// fused pass keeps its ~20 planes per channel out of memory. Every helper below is
// `inline(always)` so that the SIMD wrappers above compile the whole band for their level.
#[inline(always)]
fn band_portable(
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
    let (mom, rest) = rows.split_at_mut(MOMENTS * w);
    let (bd, rest) = rest.split_at_mut(DPLANES * w);
    let (ssim_row, rest) = rest.split_at_mut(w);
    let (x_row, g_rows) = rest.split_at_mut(w);
    let ring_len = TAPS * w;

    for m in m_lo..m_hi {
        // 1. Horizontal moment blurs of the input rows up to m + RADIUS.
        let need = (m + RADIUS).min(h - 1);
        while next_in <= need {
            let y = next_in;
            let slot = (y % TAPS) * w;
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
                    hblur(&k, &pad_m[j * pw..(j + 1) * pw], &mut ring[slot..slot + w]);
                }
            }
            next_in += 1;
        }

        // 2. Moments of row m, SSIM, and the horizontal blurs of the gradient planes.
        let counted = (r0..r1).contains(&m);
        for c in 0..3 {
            for j in 0..MOMENTS {
                let ring = &hm[(c * MOMENTS + j) * ring_len..][..ring_len];
                let src = window_rows(ring, zero, m, h, w);
                vblur(&k, &src, &mut mom[j * w..(j + 1) * w]);
            }
            {
                let (mux, rest) = mom.split_at(w);
                let (muy, rest) = rest.split_at(w);
                let (mxx, rest) = rest.split_at(w);
                let (myy, mxy) = rest.split_at(w);
                let (d_mu, rest) = pad_d.split_at_mut(pw);
                let (d_xx, d_xy) = rest.split_at_mut(pw);
                ssim_terms(
                    inp.k_ssim,
                    mux,
                    muy,
                    mxx,
                    myy,
                    mxy,
                    ssim_row,
                    &mut d_mu[RADIUS..RADIUS + w],
                    &mut d_xx[RADIUS..RADIUS + w],
                    &mut d_xy[RADIUS..RADIUS + w],
                );
            }
            if counted {
                sums.ssim += lane_sum(ssim_row);
            }
            let slot = (m % TAPS) * w;
            for j in 0..DPLANES {
                let ring = &mut hd[(c * DPLANES + j) * ring_len..][..ring_len];
                hblur(&k, &pad_d[j * pw..(j + 1) * pw], &mut ring[slot..slot + w]);
            }
        }

        // 3. Gradient rows whose window of gradient-plane rows is complete.
        let ready = if m + 1 == h {
            Some(h - 1)
        } else {
            m.checked_sub(RADIUS)
        };
        let Some(ready) = ready else { continue };
        while next_g < r1 && next_g <= ready {
            let g = next_g;
            let color = &inp.color[g * w..(g + 1) * w];
            for c in 0..3 {
                for j in 0..DPLANES {
                    let ring = &hd[(c * DPLANES + j) * ring_len..][..ring_len];
                    let src = window_rows(ring, zero, g, h, w);
                    vblur(&k, &src, &mut bd[j * w..(j + 1) * w]);
                }
                let t = &inp.target_rgb[c][g * w..(g + 1) * w];
                let (b_mu, rest) = bd.split_at(w);
                let (b_xx, b_xy) = rest.split_at(w);
                let (l1, sq) = color_gradient(
                    inp.k_l1,
                    color,
                    c,
                    t,
                    b_mu,
                    b_xx,
                    b_xy,
                    x_row,
                    &mut g_rows[c * w..(c + 1) * w],
                );
                sums.l1 += l1;
                sums.sq_err += sq;
            }
            let o = (g - r0) * w;
            interleave(g_rows, &mut gc[o..o + w]);
            sums.depth += depth_row(
                inp.k_depth,
                &inp.depth[g * w..(g + 1) * w],
                &inp.target_depth[g * w..(g + 1) * w],
                &mut gd[o..o + w],
            );
            next_g += 1;
        }
    }
    debug_assert_eq!(next_g, r1);
    sums
}

/// The TAPS rows `row − RADIUS ..= row + RADIUS` of a ring (slot = row mod TAPS), zero rows
/// outside the image.
#[inline(always)]
fn window_rows<'a>(
    ring: &'a [f32],
    zero: &'a [f32],
    row: usize,
    h: usize,
    w: usize,
) -> [&'a [f32]; TAPS] {
    std::array::from_fn(|t| {
        let r = row as isize + t as isize - RADIUS as isize;
        if r < 0 || r >= h as isize {
            &zero[..w]
        } else {
            let slot = (r as usize % TAPS) * w;
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
fn hblur(k: &[f32; TAPS], src: &[f32], dst: &mut [f32]) {
    let w = dst.len();
    let s: [&[f32]; TAPS] = std::array::from_fn(|t| &src[t..t + w]);
    symmetric_sum(k, &s, dst);
}

/// `dst = g ∗` the rows of the window, along the column.
#[inline(always)]
fn vblur(k: &[f32; TAPS], rows: &[&[f32]; TAPS], dst: &mut [f32]) {
    symmetric_sum(k, rows, dst);
}

#[inline(always)]
fn symmetric_sum(k: &[f32; TAPS], s: &[&[f32]; TAPS], dst: &mut [f32]) {
    let w = dst.len();
    let [s0, s1, s2, s3, s4, s5, s6, s7, s8, s9, s10] = s.map(|r| &r[..w]);
    let [k0, k1, k2, k3, k4, k5, ..] = *k;
    for i in 0..w {
        dst[i] = k5 * s5[i]
            + k4 * (s4[i] + s6[i])
            + k3 * (s3[i] + s7[i])
            + k2 * (s2[i] + s8[i])
            + k1 * (s1[i] + s9[i])
            + k0 * (s0[i] + s10[i]);
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
        let inv = 1.0 / (b1 * b2);
        let v = a1 * a2 * inv;
        ssim[i] = v;
        d_mu[i] = k_ssim * (2.0 * uy * (a2 - a1) * inv + v * 2.0 * ux * (1.0 / b2 - 1.0 / b1));
        d_xx[i] = k_ssim * (-v / b2);
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
    let mut abs = [0.0f32; LANES];
    let mut sq = [0.0f32; LANES];
    let mut i = 0;
    while i + LANES <= w {
        for l in 0..LANES {
            let (x, y) = (x_row[i + l], t[i + l]);
            let d = x - y;
            out[i + l] = k_l1 * sign(d) + (b_mu[i + l] + 2.0 * x * b_xx[i + l] + y * b_xy[i + l]);
            abs[l] += d.abs();
            let e = x.clamp(0.0, 1.0) - y;
            sq[l] += e * e;
        }
        i += LANES;
    }
    let (mut a, mut q) = (0.0f64, 0.0f64);
    for i in i..w {
        let (x, y) = (x_row[i], t[i]);
        let d = x - y;
        out[i] = k_l1 * sign(d) + (b_mu[i] + 2.0 * x * b_xx[i] + y * b_xy[i]);
        a += d.abs() as f64;
        let e = x.clamp(0.0, 1.0) - y;
        q += (e * e) as f64;
    }
    a += abs.iter().map(|&v| v as f64).sum::<f64>();
    q += sq.iter().map(|&v| v as f64).sum::<f64>();
    (a, q)
}

/// The three channel rows into the interleaved gradient.
#[inline(always)]
fn interleave(g_rows: &[f32], out: &mut [[f32; 3]]) {
    let w = out.len();
    let (g0, rest) = g_rows.split_at(w);
    let (g1, g2) = rest.split_at(w);
    let g2 = &g2[..w];
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
