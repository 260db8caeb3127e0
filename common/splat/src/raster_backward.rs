//! Backward of the tile rasterizer (reference 3DGS `renderCUDA` backward, on the CPU):
//! given dL/dC and dL/dD per pixel, gradients w.r.t. every Gaussian's screen-space data.
//!
//! Each tile walks its depth-sorted list back to front from the last contributor, undoing
//! the compositing (T_before = T_after / (1 − α)) and keeping the colour/depth composited
//! behind each Gaussian, exactly as 3DGS does. A Gaussian touches only the rows of its
//! α-ellipse, in 16-lane row loops like the forward. Gradients go into a per-thread buffer
//! (one uncontended lock per tile, none per pixel); the buffers are summed afterwards.

use std::sync::Mutex;

use rayon::prelude::*;

use crate::bin::TileBins;
use crate::blend::{exp_approx, gaussian_power, MAX_ALPHA, MIN_ALPHA};
use crate::cpu::SimdLevel;
use crate::output::RenderOutput;
use crate::project::Projected;
use crate::tiles::{TileGrid, TILE_SIZE};

const T: usize = TILE_SIZE as usize;
/// Composited channels: r, g, b, depth.
const CH: usize = 4;

/// dL w.r.t. one Gaussian's screen-space data.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ScreenGrad {
    pub mean2d: [f32; 2],
    /// w.r.t. the conic (a, b, c) as the power uses it: −½(a·dx² + c·dy²) − b·dx·dy.
    pub conic: [f32; 3],
    /// w.r.t. the opacity after the sigmoid.
    pub opacity: f32,
    /// w.r.t. the rendered (clamped) colour.
    pub color: [f32; 3],
    /// w.r.t. the camera depth the depth image composites.
    pub depth: f32,
}

impl ScreenGrad {
    #[inline]
    fn add(&mut self, o: &ScreenGrad) {
        for k in 0..2 {
            self.mean2d[k] += o.mean2d[k];
        }
        for k in 0..3 {
            self.conic[k] += o.conic[k];
            self.color[k] += o.color[k];
        }
        self.opacity += o.opacity;
        self.depth += o.depth;
    }

    fn is_zero(&self) -> bool {
        *self == ScreenGrad::default()
    }
}

/// Per-thread gradient buffers, kept between steps so no memory is faulted in per step.
#[derive(Debug, Default)]
pub struct RasterBackward {
    buffers: Vec<Vec<ScreenGrad>>,
    /// Every entry is zero (the last gradients were drained by [`Self::drain_chunks`]): the
    /// next run need not clear megabytes it would only overwrite.
    zeroed: bool,
}

impl RasterBackward {
    pub fn new() -> Self {
        Self::default()
    }

    /// Runs the backward over all tiles; afterwards [`Self::drain_chunks`] sums the threads.
    pub fn run(
        &mut self,
        projected: &Projected,
        bins: &TileBins,
        output: &RenderOutput,
        dl_dcolor: &[[f32; 3]],
        dl_ddepth: &[f32],
    ) {
        let grid = TileGrid::new(output.width, output.height);
        let n_pix = (grid.width * grid.height) as usize;
        assert_eq!(dl_dcolor.len(), n_pix, "dL/dC must be one entry per pixel");
        assert_eq!(dl_ddepth.len(), n_pix, "dL/dD must be one entry per pixel");
        let threads = rayon::current_num_threads().max(1);
        let n = projected.len();
        let clean = self.zeroed
            && self.buffers.len() == threads
            && self.buffers.iter().all(|b| b.len() == n);
        if !clean {
            // One buffer per thread, zeroed in parallel.
            self.buffers.resize_with(threads, Vec::new);
            self.buffers.par_iter_mut().for_each(|b| {
                b.clear();
                b.resize(n, ScreenGrad::default());
            });
        }
        self.zeroed = false;
        let slots: Vec<Mutex<Vec<ScreenGrad>>> = self.buffers.drain(..).map(Mutex::new).collect();
        let ctx = Ctx {
            projected,
            bins,
            grid: &grid,
            output,
            dl_dcolor,
            dl_ddepth,
            simd: SimdLevel::current(),
        };
        (0..grid.tile_count())
            .into_par_iter()
            .for_each_init(TileBack::boxed, |st, tile| {
                let slot = rayon::current_thread_index().unwrap_or(0) % slots.len();
                // Only this thread ever takes its own slot: the lock is never contended.
                let mut buf = slots[slot].lock().expect("gradient buffer lock");
                run_tile(&ctx, st, tile, &mut buf);
            });
        self.buffers = slots
            .into_iter()
            .map(|m| m.into_inner().expect("gradient buffer lock"))
            .collect();
    }

    /// The gradients of Gaussians `c·chunk ..` in chunks to take in parallel; taking one
    /// zeroes it while it is in cache, so the next run skips clearing the buffers.
    pub fn drain_chunks(&mut self, chunk: usize) -> Vec<GradientChunk<'_>> {
        // Each chunk zeroes what its taker left when dropped: all entries end zero.
        self.zeroed = true;
        let n = self.buffers.first().map_or(0, Vec::len);
        let mut parts: Vec<_> = self
            .buffers
            .iter_mut()
            .map(|b| b.chunks_mut(chunk.max(1)))
            .collect();
        (0..n.div_ceil(chunk.max(1)))
            .map(|_| GradientChunk {
                parts: parts.iter_mut().filter_map(Iterator::next).collect(),
                taken: 0,
            })
            .collect()
    }
}

/// One chunk of [`RasterBackward::drain_chunks`]: its gradients, taken in order.
pub struct GradientChunk<'a> {
    /// The chunk's slice of each thread's buffer.
    parts: Vec<&'a mut [ScreenGrad]>,
    taken: usize,
}

impl GradientChunk<'_> {
    /// The next Gaussian's gradient summed over the threads (`None`: it touched no pixel),
    /// leaving zeros behind.
    #[inline]
    pub fn take_next(&mut self) -> Option<ScreenGrad> {
        let j = self.taken;
        self.taken += 1;
        let mut g = ScreenGrad::default();
        for part in &mut self.parts {
            if let Some(e) = part.get_mut(j) {
                g.add(e);
                *e = ScreenGrad::default();
            }
        }
        (!g.is_zero()).then_some(g)
    }
}

impl Drop for GradientChunk<'_> {
    fn drop(&mut self) {
        for part in &mut self.parts {
            if let Some(rest) = part.get_mut(self.taken..) {
                rest.fill(ScreenGrad::default());
            }
        }
    }
}

struct Ctx<'a> {
    projected: &'a Projected,
    bins: &'a TileBins,
    grid: &'a TileGrid,
    output: &'a RenderOutput,
    dl_dcolor: &'a [[f32; 3]],
    dl_ddepth: &'a [f32],
    /// Read on the calling thread: the workers have no cap of their own.
    simd: SimdLevel,
}

/// Per-pixel state of one tile while walking back to front.
struct TileBack {
    /// Transmittance in front of the Gaussian being undone.
    t: [[f32; T]; T],
    /// Colour/depth composited behind the current Gaussian (3DGS accum_rec).
    acc: [[[f32; T]; T]; CH],
    last_v: [[[f32; T]; T]; CH],
    last_a: [[f32; T]; T],
    dpix: [[[f32; T]; T]; CH],
    n_contrib: [[u32; T]; T],
    row_max: [u32; T],
}

impl TileBack {
    fn boxed() -> Box<Self> {
        Box::new(Self {
            t: [[0.0; T]; T],
            acc: [[[0.0; T]; T]; CH],
            last_v: [[[0.0; T]; T]; CH],
            last_a: [[0.0; T]; T],
            dpix: [[[0.0; T]; T]; CH],
            n_contrib: [[0; T]; T],
            row_max: [0; T],
        })
    }
}

fn run_tile(ctx: &Ctx, st: &mut TileBack, tile: usize, buf: &mut [ScreenGrad]) {
    match ctx.simd {
        // SAFETY: the Avx512 level has AVX-512 F/BW/VL and AVX2 (SimdLevel::detected).
        #[cfg(target_arch = "x86_64")]
        SimdLevel::Avx512 => unsafe { tile_backward_avx512(ctx, st, tile, buf) },
        // SAFETY: the Avx2 level has AVX2 (SimdLevel::detected).
        #[cfg(target_arch = "x86_64")]
        SimdLevel::Avx2 => unsafe { tile_backward_avx2(ctx, st, tile, buf) },
        SimdLevel::Portable => tile_backward(ctx, st, tile, buf),
    }
}

/// The kernel compiled for AVX-512: a 16-lane row is one register, masks are native.
///
/// # Safety
/// The caller must ensure the CPU supports avx512f, avx512bw and avx512vl.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2")]
unsafe fn tile_backward_avx512(ctx: &Ctx, st: &mut TileBack, tile: usize, buf: &mut [ScreenGrad]) {
    tile_backward(ctx, st, tile, buf)
}

/// # Safety
/// The caller must ensure the CPU supports AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn tile_backward_avx2(ctx: &Ctx, st: &mut TileBack, tile: usize, buf: &mut [ScreenGrad]) {
    tile_backward(ctx, st, tile, buf)
}

#[inline(always)]
fn tile_backward(ctx: &Ctx, st: &mut TileBack, tile: usize, buf: &mut [ScreenGrad]) {
    let grid = ctx.grid;
    let w = grid.width as usize;
    let tx0 = (tile % grid.tiles_x as usize) as u32 * TILE_SIZE;
    let ty0 = (tile / grid.tiles_x as usize) as u32 * TILE_SIZE;
    let cols = (grid.width - tx0).min(TILE_SIZE) as usize;
    let rows = (grid.height - ty0).min(TILE_SIZE) as usize;
    let out = ctx.output;
    let mut tile_max = 0u32;
    for y in 0..T {
        st.row_max[y] = 0;
        for x in 0..T {
            let inside = y < rows && x < cols;
            let p = if inside {
                (ty0 as usize + y) * w + tx0 as usize + x
            } else {
                0
            };
            // Pixels outside the image have no contributors.
            st.n_contrib[y][x] = if inside { out.n_contrib[p] } else { 0 };
            st.t[y][x] = if inside {
                out.final_transmittance[p]
            } else {
                0.0
            };
            let dc = if inside { ctx.dl_dcolor[p] } else { [0.0; 3] };
            st.dpix[0][y][x] = dc[0];
            st.dpix[1][y][x] = dc[1];
            st.dpix[2][y][x] = dc[2];
            st.dpix[3][y][x] = if inside { ctx.dl_ddepth[p] } else { 0.0 };
            st.row_max[y] = st.row_max[y].max(st.n_contrib[y][x]);
        }
        tile_max = tile_max.max(st.row_max[y]);
    }
    if tile_max == 0 {
        return;
    }
    st.acc = [[[0.0; T]; T]; CH];
    st.last_v = [[[0.0; T]; T]; CH];
    st.last_a = [[0.0; T]; T];
    let p = ctx.projected;
    let list = ctx.bins.tile(tile);
    let lane_x: [f32; T] = std::array::from_fn(|i| (tx0 + i as u32) as f32);
    for rank in (0..tile_max as usize).rev() {
        let gi = list[rank] as usize;
        // Its gradient slot is read and written after its rows: fetch it now (a miss per
        // Gaussian and tile otherwise, the largest single stall of this loop).
        prefetch(buf.as_ptr().wrapping_add(gi));
        let [mx, my] = p.means2d[gi];
        let e = p.ellipses[gi];
        let [a, b, c] = p.conics[gi];
        let g = LaneGaussian {
            mean_x: mx,
            conic: [a, b, c],
            opacity: p.opacities[gi],
            value: [
                p.colors[gi][0],
                p.colors[gi][1],
                p.colors[gi][2],
                p.depths[gi],
            ],
            rank: rank as u32,
        };
        // Same row and column ranges as the forward kernel (it is conservative; the lane
        // tests decide), so exactly the forward's contributions are undone.
        let disc = b * b - a * c;
        let inv_a = 1.0 / a;
        let y_lo = (my - e.half_h).ceil().max(ty0 as f32) as u32;
        let y_hi = (my + e.half_h)
            .floor()
            .min((ty0 as usize + rows - 1) as f32);
        if y_hi < y_lo as f32 {
            continue;
        }
        let mut acc = Accum::default();
        for py in y_lo..=y_hi as u32 {
            let ly = (py - ty0) as usize;
            if st.row_max[ly] <= g.rank {
                continue;
            }
            let dy = my - py as f32;
            let root = dy * dy * disc + a * e.q_max;
            if root < 0.0 {
                continue;
            }
            let sq = root.sqrt();
            let x_lo = (mx - (-b * dy + sq) * inv_a - 0.01).ceil() - tx0 as f32;
            let x_hi = (mx - (-b * dy - sq) * inv_a + 0.01).floor() - tx0 as f32;
            if x_hi < 0.0 || x_lo > (T - 1) as f32 || x_hi < x_lo {
                continue;
            }
            let x_lo = x_lo.max(0.0) as usize;
            let x_hi = x_hi.min((T - 1) as f32) as usize;
            undo_row(&g, dy, &lane_x, x_lo, x_hi, st, ly, &mut acc);
        }
        if acc.any {
            buf[gi].add(&acc.finish());
        }
    }
}

/// Asks for the cache line at `p` (a hint: no effect where there is no prefetch instruction).
#[inline(always)]
fn prefetch<V>(p: *const V) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: prefetching is a hint and never faults, whatever the address.
    unsafe {
        std::arch::x86_64::_mm_prefetch(p.cast::<i8>(), std::arch::x86_64::_MM_HINT_T0);
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// One Gaussian's data as the lane loop needs it.
struct LaneGaussian {
    mean_x: f32,
    conic: [f32; 3],
    opacity: f32,
    /// r, g, b, depth.
    value: [f32; CH],
    rank: u32,
}

/// Per-lane gradient sums of one Gaussian over the rows it touches in a tile. Both halves
/// of a row add into the same H lanes: the sums stay register-sized, and no load spans two
/// stores of another width (a store-forwarding stall that cost a tenth of the backward).
#[derive(Default)]
struct Accum {
    mx: [f32; H],
    my: [f32; H],
    ca: [f32; H],
    cb: [f32; H],
    cc: [f32; H],
    op: [f32; H],
    val: [[f32; H]; CH],
    any: bool,
}

impl Accum {
    fn finish(&self) -> ScreenGrad {
        let s = |v: &[f32; H]| v.iter().sum::<f32>();
        ScreenGrad {
            mean2d: [s(&self.mx), s(&self.my)],
            conic: [s(&self.ca), s(&self.cb), s(&self.cc)],
            opacity: s(&self.op),
            color: [s(&self.val[0]), s(&self.val[1]), s(&self.val[2])],
            depth: s(&self.val[3]),
        }
    }
}

/// Lanes per block: a row is undone in two halves, and a half the Gaussian's column range
/// misses is skipped (most Gaussians are a few pixels wide).
const H: usize = 8;

/// Undoes one Gaussian on lanes x_lo..=x_hi of tile row `ly`, adding its gradients to `acc`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn undo_row(
    g: &LaneGaussian,
    dy: f32,
    lane_x: &[f32; T],
    x_lo: usize,
    x_hi: usize,
    st: &mut TileBack,
    ly: usize,
    acc: &mut Accum,
) {
    for o in (0..T).step_by(H) {
        if x_hi >= o && x_lo < o + H {
            undo_lanes(g, dy, lane_x, x_lo, x_hi, st, ly, o, acc);
        }
    }
}

#[inline(always)]
fn lanes<V: Copy + Default>(row: &[V; T], o: usize) -> [V; H] {
    std::array::from_fn(|i| row[o + i])
}

/// [`undo_row`] on lanes o..o+H. The state is copied into locals and written back whole, so
/// lane selects become register blends rather than masked stores (which stall the reload).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn undo_lanes(
    g: &LaneGaussian,
    dy: f32,
    lane_x: &[f32; T],
    x_lo: usize,
    x_hi: usize,
    st: &mut TileBack,
    ly: usize,
    o: usize,
    acc: &mut Accum,
) {
    let [a, b, c] = g.conic;
    let t = lanes(&st.t[ly], o);
    let last_a = lanes(&st.last_a[ly], o);
    let behind: [[f32; H]; CH] = std::array::from_fn(|ch| lanes(&st.acc[ch][ly], o));
    let last_v: [[f32; H]; CH] = std::array::from_fn(|ch| lanes(&st.last_v[ch][ly], o));
    // Updated state goes to fresh arrays: every lane is written, so selects stay blends.
    // (Started as copies, not zeros: a zeroed template is built in memory with stores of
    // mixed widths, and reading it back stalls store forwarding.)
    let (mut t_out, mut last_a_out) = (t, last_a);
    let (mut behind_out, mut last_v_out) = (behind, last_v);
    let dpix: [[f32; H]; CH] = std::array::from_fn(|ch| lanes(&st.dpix[ch][ly], o));
    let n_contrib = lanes(&st.n_contrib[ly], o);
    let mut any = false;
    for i in 0..H {
        let dx = g.mean_x - lane_x[o + i];
        let power = gaussian_power(g.conic, dx, dy);
        let gauss = exp_approx(power);
        let raw = g.opacity * gauss;
        // Bit-identical to the forward's alpha_of.
        let alpha = raw.min(MAX_ALPHA);
        let in_row = (o + i >= x_lo) & (o + i <= x_hi);
        let active = in_row & (g.rank < n_contrib[i]) & (power <= 0.0) & (alpha >= MIN_ALPHA);
        let t_front = t[i] / (1.0 - alpha);
        let weight = alpha * t_front;
        let la = last_a[i];
        let mut dl_dalpha = 0.0;
        for ch in 0..CH {
            let v = g.value[ch];
            let bh = la * last_v[ch][i] + (1.0 - la) * behind[ch][i];
            // dC/dα_k = T_k·(v_k − what is composited behind k).
            dl_dalpha += (v - bh) * dpix[ch][i];
            acc.val[ch][i] += if active { weight * dpix[ch][i] } else { 0.0 };
            behind_out[ch][i] = if active { bh } else { behind[ch][i] };
            last_v_out[ch][i] = if active { v } else { last_v[ch][i] };
        }
        let dl_dalpha = dl_dalpha * t_front;
        // At the 0.99 clamp α does not depend on o or the Gaussian.
        let live = active & (raw < MAX_ALPHA);
        let dl_dpower = if live {
            g.opacity * dl_dalpha * gauss
        } else {
            0.0
        };
        acc.op[i] += if live { gauss * dl_dalpha } else { 0.0 };
        acc.mx[i] -= dl_dpower * (a * dx + b * dy);
        acc.my[i] -= dl_dpower * (b * dx + c * dy);
        acc.ca[i] -= 0.5 * dl_dpower * dx * dx;
        acc.cb[i] -= dl_dpower * dx * dy;
        acc.cc[i] -= 0.5 * dl_dpower * dy * dy;
        t_out[i] = if active { t_front } else { t[i] };
        last_a_out[i] = if active { alpha } else { la };
        any |= active;
    }
    st.t[ly][o..o + H].copy_from_slice(&t_out);
    st.last_a[ly][o..o + H].copy_from_slice(&last_a_out);
    for ch in 0..CH {
        st.acc[ch][ly][o..o + H].copy_from_slice(&behind_out[ch]);
        st.last_v[ch][ly][o..o + H].copy_from_slice(&last_v_out[ch]);
    }
    acc.any |= any;
}
