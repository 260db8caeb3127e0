//! Tile rasterizer (METHOD §2–3): front-to-back alpha compositing of colour, depth and
//! silhouette, with GS Voting labels, top-K and visibility in the same pass.
//!
//! Each tile walks its depth-sorted list Gaussian by Gaussian and updates only the rows
//! where the Gaussian can reach α ≥ 1/255 (exact: other pixels would skip it anyway), in
//! fixed 16-lane row loops that vectorise. Voting keeps 3 (label, sum) slots per pixel in
//! the same lane loop (pixels meeting more labels are replayed exactly at the end of the
//! tile). For top-K each touched row appends its 16 weights to a per-row log; at the end of
//! the tile every pixel reads its contributions back in depth order and keeps the K
//! heaviest. Bands of 16 image rows run in parallel (rayon); one kernel is compiled per
//! combination of requested outputs, so unrequested outputs cost nothing.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::bin::TileBins;
use crate::blend::{alpha_of, gaussian_power, MIN_ALPHA, MIN_TRANSMITTANCE};
use crate::output::{RenderOutput, RenderRequest};
use crate::project::Projected;
use crate::tiles::{TileGrid, TILE_SIZE};
use crate::topk::{
    key_rank, key_weight, select_top_k, topk_key, weight_positions, TopKBand, SMALL_LIST,
};
use crate::voting::vote;

const T: usize = TILE_SIZE as usize;

/// Rasterizes projected, binned Gaussians. `labels` are the map's labels (for voting).
pub fn rasterize(
    projected: &Projected,
    bins: &TileBins,
    grid: &TileGrid,
    labels: &[u32],
    request: &RenderRequest,
) -> RenderOutput {
    let mut out = RenderOutput::default();
    rasterize_into(projected, bins, grid, labels, request, &mut out);
    out
}

/// Resizes `v` to `n` elements of `value`, keeping its allocation.
fn reset<T: Clone>(v: &mut Vec<T>, n: usize, value: T) {
    v.clear();
    v.resize(n, value);
}

/// [`rasterize`] into an existing output, reusing its buffers: repeated renders then touch
/// no fresh memory (page faults on tens of MB of top-K entries cost more than filling them).
pub fn rasterize_into(
    projected: &Projected,
    bins: &TileBins,
    grid: &TileGrid,
    labels: &[u32],
    request: &RenderRequest,
    out: &mut RenderOutput,
) {
    let (w, h) = (grid.width as usize, grid.height as usize);
    let n = w * h;
    // Counts are stored as u16.
    let top_k = request
        .top_k
        .filter(|&k| k > 0)
        .map(|k| k.min(u16::MAX as usize));
    out.width = grid.width;
    out.height = grid.height;
    reset(&mut out.color, n, [0.0; 3]);
    reset(&mut out.depth, n, 0.0);
    reset(&mut out.silhouette, n, 0.0);
    reset(&mut out.final_transmittance, n, 1.0);
    reset(&mut out.n_contrib, n, 0);
    out.labels = match (request.labels, out.labels.take()) {
        (true, old) => {
            let mut v = old.unwrap_or_default();
            reset(&mut v, n, 0);
            Some(v)
        }
        (false, _) => None,
    };
    out.top_k = match (top_k, out.top_k.take()) {
        (Some(k), old) => {
            let mut t = old.unwrap_or_default();
            t.k = k;
            t.width = grid.width;
            t.height = grid.height;
            reset(&mut t.start, n, 0);
            reset(&mut t.count, n, 0);
            t.bands
                .resize_with(grid.tiles_y as usize, TopKBand::default);
            for b in &mut t.bands {
                b.ids.clear();
                b.weights.clear();
            }
            Some(t)
        }
        (None, _) => None,
    };
    out.visible_per_label = None;
    let visible: Option<Vec<AtomicBool>> = request.visible_counts.then(|| {
        (0..projected.len())
            .map(|_| AtomicBool::new(false))
            .collect()
    });
    let ctx = Ctx {
        projected,
        bins,
        grid,
        labels,
        top_k,
        sort_top_k: request.sort_top_k,
        visible: visible.as_deref(),
    };

    let band_len = T * w;
    let mut color = out.color.chunks_mut(band_len);
    let mut depth = out.depth.chunks_mut(band_len);
    let mut sil = out.silhouette.chunks_mut(band_len);
    let mut final_t = out.final_transmittance.chunks_mut(band_len);
    let mut n_contrib = out.n_contrib.chunks_mut(band_len);
    let mut label_img = out.labels.as_mut().map(|v| v.chunks_mut(band_len));
    let (mut tk_start, mut tk_count, mut tk_bands) = match out.top_k.as_mut() {
        Some(t) => (
            Some(t.start.chunks_mut(band_len)),
            Some(t.count.chunks_mut(band_len)),
            Some(t.bands.iter_mut()),
        ),
        None => (None, None, None),
    };
    let bands: Vec<BandOut> = (0..grid.tiles_y as usize)
        .map(|band| BandOut {
            band,
            color: color.next().expect("band count matches chunks"),
            depth: depth.next().expect("band"),
            silhouette: sil.next().expect("band"),
            final_t: final_t.next().expect("band"),
            n_contrib: n_contrib.next().expect("band"),
            labels: label_img.as_mut().and_then(|it| it.next()),
            topk_start: tk_start.as_mut().and_then(|it| it.next()),
            topk_count: tk_count.as_mut().and_then(|it| it.next()),
            topk_band: tk_bands.as_mut().and_then(|it| it.next()),
        })
        .collect();

    let (log, vote) = (top_k.is_some(), request.labels);
    bands
        .into_par_iter()
        .for_each_init(Scratch::new, |scratch, mut band| {
            for tx in 0..grid.tiles_x as usize {
                let tile = band.band * grid.tiles_x as usize + tx;
                // One monomorphised kernel per combination, so unrequested outputs cost nothing.
                match (log, vote) {
                    (false, false) => run_tile::<false, false>(&ctx, scratch, tile),
                    (false, true) => run_tile::<false, true>(&ctx, scratch, tile),
                    (true, false) => run_tile::<true, false>(&ctx, scratch, tile),
                    (true, true) => run_tile::<true, true>(&ctx, scratch, tile),
                }
                write_tile(&ctx, scratch, &mut band, tx, tile);
            }
        });

    if let Some(vis) = visible {
        let mut counts = BTreeMap::new();
        for (i, v) in vis.iter().enumerate() {
            if v.load(Ordering::Relaxed) {
                *counts.entry(labels[i]).or_insert(0u32) += 1;
            }
        }
        out.visible_per_label = Some(counts);
    }
}

struct Ctx<'a> {
    projected: &'a Projected,
    bins: &'a TileBins,
    grid: &'a TileGrid,
    labels: &'a [u32],
    top_k: Option<usize>,
    sort_top_k: bool,
    visible: Option<&'a [AtomicBool]>,
}

/// Output slices of one band of 16 image rows.
struct BandOut<'a> {
    band: usize,
    color: &'a mut [[f32; 3]],
    depth: &'a mut [f32],
    silhouette: &'a mut [f32],
    final_t: &'a mut [f32],
    n_contrib: &'a mut [u32],
    labels: Option<&'a mut [u32]>,
    topk_start: Option<&'a mut [u32]>,
    topk_count: Option<&'a mut [u16]>,
    topk_band: Option<&'a mut TopKBand>,
}

/// Per-pixel accumulators of one tile, as 16 rows of 16 lanes. Transmittance is stored
/// negated once a pixel is done, so "done" costs no extra state and the final T survives.
struct TileState {
    t: [[f32; T]; T],
    r: [[f32; T]; T],
    g: [[f32; T]; T],
    b: [[f32; T]; T],
    d: [[f32; T]; T],
    s: [[f32; T]; T],
    last: [[u32; T]; T],
    row_live: [u32; T],
    /// GS Voting: VOTE_SLOTS (label, weight sum) slots per pixel, filled in order; a pixel
    /// meeting more labels is flagged and re-walked exactly at the end of the tile.
    vote_label: [[[u32; T]; T]; VOTE_SLOTS],
    vote_sum: [[[f32; T]; T]; VOTE_SLOTS],
    vote_overflow: [[u32; T]; T],
}

/// Label slots per pixel held in vector registers (few labels meet at a pixel).
const VOTE_SLOTS: usize = 3;

/// Weights each Gaussian left on one tile row, in depth order (for top-K).
#[derive(Default)]
struct RowLog {
    ranks: Vec<u32>,
    weights: Vec<[f32; T]>,
}

#[derive(Default)]
struct Scratch {
    state: Option<Box<TileState>>,
    logs: Vec<RowLog>,
    keys: Vec<u64>,
    votes: Vec<(u32, f32)>,
    replay: Vec<(u32, f32)>,
}

impl Scratch {
    fn new() -> Self {
        Self {
            state: Some(Box::new(TileState {
                t: [[1.0; T]; T],
                r: [[0.0; T]; T],
                g: [[0.0; T]; T],
                b: [[0.0; T]; T],
                d: [[0.0; T]; T],
                s: [[0.0; T]; T],
                last: [[0; T]; T],
                row_live: [0; T],
                vote_label: [[[0; T]; T]; VOTE_SLOTS],
                vote_sum: [[[0.0; T]; T]; VOTE_SLOTS],
                vote_overflow: [[0; T]; T],
            })),
            logs: (0..T).map(|_| RowLog::default()).collect(),
            ..Default::default()
        }
    }
}

/// One Gaussian's data as the lane loop needs it.
struct LaneGaussian {
    mean_x: f32,
    conic: [f32; 3],
    opacity: f32,
    color: [f32; 3],
    depth: f32,
    rank1: u32,
    label: u32,
}

fn run_tile<const LOG: bool, const VOTE: bool>(ctx: &Ctx, scratch: &mut Scratch, tile: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { tile_kernel_avx2::<LOG, VOTE>(ctx, scratch, tile) };
            return;
        }
    }
    tile_kernel::<LOG, VOTE>(ctx, scratch, tile);
}

/// The same kernel compiled for AVX2 (wider lane loops, identical IEEE results: no FMA).
///
/// # Safety
/// The caller must ensure the CPU supports AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn tile_kernel_avx2<const LOG: bool, const VOTE: bool>(
    ctx: &Ctx,
    scratch: &mut Scratch,
    tile: usize,
) {
    tile_kernel::<LOG, VOTE>(ctx, scratch, tile)
}

#[inline(always)]
fn tile_kernel<const LOG: bool, const VOTE: bool>(ctx: &Ctx, scratch: &mut Scratch, tile: usize) {
    let grid = ctx.grid;
    let tx0 = (tile % grid.tiles_x as usize) as u32 * TILE_SIZE;
    let ty0 = (tile / grid.tiles_x as usize) as u32 * TILE_SIZE;
    let cols = (grid.width - tx0).min(TILE_SIZE) as usize;
    let rows = (grid.height - ty0).min(TILE_SIZE) as usize;
    let st = scratch.state.as_deref_mut().expect("scratch state");
    // Pixels outside the image start "done".
    for y in 0..T {
        for x in 0..T {
            st.t[y][x] = if y < rows && x < cols { 1.0 } else { -1.0 };
        }
        st.row_live[y] = if y < rows { cols as u32 } else { 0 };
    }
    for a in [&mut st.r, &mut st.g, &mut st.b, &mut st.d, &mut st.s] {
        *a = [[0.0; T]; T];
    }
    st.last = [[0; T]; T];
    if VOTE {
        st.vote_label = [[[0; T]; T]; VOTE_SLOTS];
        st.vote_sum = [[[0.0; T]; T]; VOTE_SLOTS];
        st.vote_overflow = [[0; T]; T];
    }
    if LOG {
        for log in &mut scratch.logs {
            log.ranks.clear();
            log.weights.clear();
        }
    }
    let mut live = (rows * cols) as u32;
    let lane_x: [f32; T] = std::array::from_fn(|i| (tx0 + i as u32) as f32);
    let p = ctx.projected;
    let list = ctx.bins.tile(tile);
    for (rank, &gid) in list.iter().enumerate() {
        if live == 0 {
            break;
        }
        let gi = gid as usize;
        let [mx, my] = p.means2d[gi];
        let g = LaneGaussian {
            mean_x: mx,
            conic: p.conics[gi],
            opacity: p.opacities[gi],
            color: p.colors[gi],
            depth: p.depths[gi],
            rank1: rank as u32 + 1,
            label: if VOTE { ctx.labels[gi] } else { 0 },
        };
        let e = p.ellipses[gi];
        let [a, b, c] = g.conic;
        let disc = b * b - a * c;
        let inv_a = 1.0 / a;
        let y_lo = (my - e.half_h).ceil().max(ty0 as f32) as u32;
        let y_hi = (my + e.half_h)
            .floor()
            .min((ty0 as usize + rows - 1) as f32);
        if y_hi < y_lo as f32 {
            continue;
        }
        let mut contributed = 0u32;
        for py in y_lo..=y_hi as u32 {
            let ly = (py - ty0) as usize;
            if st.row_live[ly] == 0 {
                continue;
            }
            let dy = my - py as f32;
            // Columns with q(dx, dy) ≤ q_max: a·dx² + 2b·dy·dx + (c·dy² − q_max) ≤ 0.
            let root = dy * dy * disc + a * e.q_max;
            if root < 0.0 {
                continue;
            }
            let sq = root.sqrt();
            // Conservative by 0.01 px: the lane loop applies the exact per-pixel tests.
            let x_lo = (mx - (-b * dy + sq) * inv_a - 0.01).ceil() - tx0 as f32;
            let x_hi = (mx - (-b * dy - sq) * inv_a + 0.01).floor() - tx0 as f32;
            if x_hi < 0.0 || x_lo > (T - 1) as f32 || x_hi < x_lo {
                continue;
            }
            let x_lo = x_lo.max(0.0) as usize;
            let x_hi = x_hi.min((T - 1) as f32) as usize;
            let mut w = [0.0f32; T];
            let mut done_now = 0u32;
            let mut n_contrib = 0u32;
            // Both halves always: two independent dependency chains beat skipping one.
            for half in 0..T / H {
                let (d, n) = blend_lanes::<VOTE>(&g, dy, &lane_x, x_lo, x_hi, st, ly, half, &mut w);
                done_now += d;
                n_contrib += n;
            }
            st.row_live[ly] -= done_now;
            live -= done_now;
            if LOG && n_contrib > 0 {
                let log = &mut scratch.logs[ly];
                log.ranks.push(rank as u32);
                log.weights.push(w);
            }
            contributed += n_contrib;
        }
        if contributed > 0 {
            if let Some(v) = ctx.visible {
                v[gi].store(true, Ordering::Relaxed);
            }
        }
    }
}

/// Lanes per vector block (one AVX2 register).
const H: usize = 8;

#[inline(always)]
fn lanes8<V>(a: &mut [V; T], o: usize) -> &mut [V; H] {
    (&mut a[o..o + H]).try_into().expect("8 lanes")
}

/// Composites one Gaussian over lanes x_lo..=x_hi within half `half` of tile row `ly`.
/// Writes each lane's weight α·T (0 where it did not contribute) into `w`; returns
/// (pixels that became done, pixels it contributed to).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn blend_lanes<const VOTE: bool>(
    g: &LaneGaussian,
    dy: f32,
    lane_x: &[f32; T],
    x_lo: usize,
    x_hi: usize,
    st: &mut TileState,
    ly: usize,
    half: usize,
    w: &mut [f32; T],
) -> (u32, u32) {
    let o = half * H;
    let t = lanes8(&mut st.t[ly], o);
    let (r, gr, b) = (
        lanes8(&mut st.r[ly], o),
        lanes8(&mut st.g[ly], o),
        lanes8(&mut st.b[ly], o),
    );
    let (d, s) = (lanes8(&mut st.d[ly], o), lanes8(&mut st.s[ly], o));
    let last = lanes8(&mut st.last[ly], o);
    let wl = lanes8(w, o);
    let lx: &[f32; H] = lane_x[o..o + H].try_into().expect("8 lanes");
    let mut newly_done = 0u32;
    let mut contributed = 0u32;
    for i in 0..H {
        let dx = g.mean_x - lx[i];
        let power = gaussian_power(g.conic, dx, dy);
        let alpha = alpha_of(g.opacity, power);
        let in_row = (o + i >= x_lo) & (o + i <= x_hi);
        let valid = in_row & (power <= 0.0) & (alpha >= MIN_ALPHA);
        let ti = t[i];
        let test_t = ti * (1.0 - alpha);
        // ti < 0 (done) makes test_t < 0, so done pixels never contribute again.
        let contrib = valid & (test_t >= MIN_TRANSMITTANCE);
        let done_now = valid & (ti > 0.0) & (test_t < MIN_TRANSMITTANCE);
        let wi = if contrib { alpha * ti } else { 0.0 };
        r[i] += g.color[0] * wi;
        gr[i] += g.color[1] * wi;
        b[i] += g.color[2] * wi;
        d[i] += g.depth * wi;
        s[i] += wi;
        t[i] = if contrib {
            test_t
        } else if done_now {
            -ti
        } else {
            ti
        };
        last[i] = if contrib { g.rank1 } else { last[i] };
        newly_done += done_now as u32;
        contributed += contrib as u32;
        wl[i] = wi;
    }
    if VOTE && g.label != 0 {
        vote_lanes(g.label, wl, st, ly, o);
    }
    (newly_done, contributed)
}

/// Adds this Gaussian's weights to its label's slot in every lane (branch-free): the first
/// slot holding the label or still empty takes it; if none, the pixel is flagged.
#[inline(always)]
fn vote_lanes(label: u32, w: &[f32; H], st: &mut TileState, ly: usize, o: usize) {
    let mut pending = [true; H];
    for slot in 0..VOTE_SLOTS {
        let l = lanes8(&mut st.vote_label[slot][ly], o);
        let s = lanes8(&mut st.vote_sum[slot][ly], o);
        for i in 0..H {
            let c = w[i] > 0.0;
            let (same, empty) = (l[i] == label, l[i] == 0);
            let take = c & pending[i] & (same | empty);
            // An empty slot's sum is 0, and 0 + w == w exactly.
            s[i] += if take { w[i] } else { 0.0 };
            l[i] = if take { label } else { l[i] };
            pending[i] &= !(same | empty);
        }
    }
    let ov = lanes8(&mut st.vote_overflow[ly], o);
    for i in 0..H {
        ov[i] |= ((w[i] > 0.0) & pending[i]) as u32;
    }
}

/// Weights (tile rank, α·T) of one pixel's contributions, front to back: the kernel's
/// arithmetic replayed for a single pixel (vote-slot overflow, on-demand top-K).
pub(crate) fn replay_pixel(
    p: &Projected,
    list: &[u32],
    px: u32,
    py: u32,
    out: &mut Vec<(u32, f32)>,
) {
    out.clear();
    let mut t = 1.0f32;
    for (rank, &gid) in list.iter().enumerate() {
        let gi = gid as usize;
        let [mx, my] = p.means2d[gi];
        let power = gaussian_power(p.conics[gi], mx - px as f32, my - py as f32);
        if power > 0.0 {
            continue;
        }
        let alpha = alpha_of(p.opacities[gi], power);
        if alpha < MIN_ALPHA {
            continue;
        }
        let test_t = t * (1.0 - alpha);
        if test_t < MIN_TRANSMITTANCE {
            break;
        }
        out.push((rank as u32, alpha * t));
        t = test_t;
    }
}

/// Copies a finished tile into the band's images, and resolves labels (vote slots) and
/// top-K (row logs).
fn write_tile(ctx: &Ctx, scratch: &mut Scratch, band: &mut BandOut, tx: usize, tile: usize) {
    let grid = ctx.grid;
    let w = grid.width as usize;
    let x0 = tx * T;
    let cols = (w - x0).min(T);
    let rows = band.color.len() / w;
    let st = scratch.state.as_deref().expect("scratch state");
    for y in 0..rows {
        let o = y * w + x0;
        for x in 0..cols {
            band.color[o + x] = [st.r[y][x], st.g[y][x], st.b[y][x]];
        }
        band.depth[o..o + cols].copy_from_slice(&st.d[y][..cols]);
        band.silhouette[o..o + cols].copy_from_slice(&st.s[y][..cols]);
        for x in 0..cols {
            band.final_t[o + x] = st.t[y][x].abs();
        }
        band.n_contrib[o..o + cols].copy_from_slice(&st.last[y][..cols]);
    }
    let list = ctx.bins.tile(tile);
    if let Some(labels) = band.labels.as_mut() {
        for y in 0..rows {
            for x in 0..cols {
                let label = if st.vote_overflow[y][x] != 0 {
                    let contribs = &mut scratch.replay;
                    let (px, py) = ((x0 + x) as u32, (band.band * T + y) as u32);
                    replay_pixel(ctx.projected, list, px, py, contribs);
                    let it = contribs
                        .iter()
                        .map(|&(r, wt)| (ctx.labels[list[r as usize] as usize], wt));
                    vote(it, &mut scratch.votes)
                } else {
                    let mut best = (0u32, 0.0f32);
                    for slot in 0..VOTE_SLOTS {
                        let (l, s) = (st.vote_label[slot][y][x], st.vote_sum[slot][y][x]);
                        if l != 0 && (best.0 == 0 || s > best.1 || (s == best.1 && l < best.0)) {
                            best = (l, s);
                        }
                    }
                    best.0
                };
                labels[y * w + x0 + x] = label;
            }
        }
    }
    if let (Some(k), Some(start), Some(count), Some(store)) = (
        ctx.top_k,
        band.topk_start.as_mut(),
        band.topk_count.as_mut(),
        band.topk_band.as_mut(),
    ) {
        let ctx_rows = TopKRows {
            list,
            logs: &scratch.logs,
            last: &st.last,
            rows,
            cols,
            k,
            sort: ctx.sort_top_k,
        };
        let mut sink = TopKSink {
            start,
            count,
            store,
            width: w,
            x0,
        };
        resolve_top_k(&ctx_rows, &mut sink, &mut scratch.keys);
    }
}

/// Inputs for resolving one tile's top-K lists from its row logs.
struct TopKRows<'a> {
    list: &'a [u32],
    logs: &'a [RowLog],
    last: &'a [[u32; T]; T],
    rows: usize,
    cols: usize,
    k: usize,
    sort: bool,
}

/// Where one tile's top-K lists go in the band's storage.
struct TopKSink<'a, 'b> {
    start: &'a mut &'b mut [u32],
    count: &'a mut &'b mut [u16],
    store: &'a mut &'b mut TopKBand,
    width: usize,
    x0: usize,
}

fn resolve_top_k(rows: &TopKRows, sink: &mut TopKSink, keys: &mut Vec<u64>) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { resolve_top_k_avx2(rows, sink, keys) };
            return;
        }
    }
    resolve_top_k_impl(rows, sink, keys);
}

/// # Safety
/// The caller must ensure the CPU supports AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn resolve_top_k_avx2(rows: &TopKRows, sink: &mut TopKSink, keys: &mut Vec<u64>) {
    resolve_top_k_impl(rows, sink, keys)
}

/// Gathers each pixel's contributions (front to back) from its row log and keeps the K
/// heaviest: short lists by branch-free ranking, long ones by selection + sort.
#[inline(always)]
fn resolve_top_k_impl(rows: &TopKRows, sink: &mut TopKSink, keys: &mut Vec<u64>) {
    let k = rows.k;
    let mut ws = [0.0f32; SMALL_LIST];
    let mut rk = [0u32; SMALL_LIST];
    let mut pos = [0u32; SMALL_LIST];
    for y in 0..rows.rows {
        let log = &rows.logs[y];
        let n_rec = log.weights.len();
        keys.resize(n_rec, 0);
        for x in 0..rows.cols {
            let o = y * sink.width + sink.x0 + x;
            let mut n = 0;
            if rows.last[y][x] > 0 {
                for r in 0..n_rec {
                    let wt = log.weights[r][x];
                    keys[n] = topk_key(wt, log.ranks[r]);
                    n += (wt > 0.0) as usize;
                }
            }
            let base = sink.store.ids.len();
            sink.start[o] = base as u32;
            if n <= SMALL_LIST && (rows.sort || n > k) {
                // Front-to-back keys → weights padded with −1 (never outrank a real weight).
                ws.fill(-1.0);
                for i in 0..n {
                    ws[i] = key_weight(keys[i]);
                    rk[i] = key_rank(keys[i]);
                }
                if n <= SMALL_LIST / 2 {
                    // Half-width compares for the common short lists.
                    let (ws16, pos16) = (ws.first_chunk::<16>(), pos.first_chunk_mut::<16>());
                    weight_positions(ws16.expect("32 ≥ 16"), n, pos16.expect("32 ≥ 16"));
                } else {
                    weight_positions(&ws, n, &mut pos);
                }
                let m = n.min(k);
                sink.store.ids.resize(base + m, 0);
                sink.store.weights.resize(base + m, 0.0);
                if rows.sort {
                    for i in 0..n {
                        let p = pos[i] as usize;
                        if p < m {
                            sink.store.ids[base + p] = rows.list[rk[i] as usize];
                            sink.store.weights[base + p] = ws[i];
                        }
                    }
                } else {
                    let mut j = base;
                    for i in 0..n {
                        if (pos[i] as usize) < m {
                            sink.store.ids[j] = rows.list[rk[i] as usize];
                            sink.store.weights[j] = ws[i];
                            j += 1;
                        }
                    }
                }
                sink.count[o] = m as u16;
            } else {
                let top = select_top_k(&mut keys[..n], k, rows.sort);
                sink.count[o] = top.len() as u16;
                for &key in top {
                    sink.store.ids.push(rows.list[key_rank(key) as usize]);
                    sink.store.weights.push(key_weight(key));
                }
            }
        }
    }
}
