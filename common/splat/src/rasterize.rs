//! Tile rasterizer (docs/METHOD.md §2–3): front-to-back alpha compositing of colour, depth and
//! silhouette, with GS Voting labels, top-K and visibility in the same pass.
//!
//! Each tile walks its depth-sorted list Gaussian by Gaussian and updates only the rows
//! where the Gaussian can reach α ≥ 1/255 (exact: other pixels would skip it anyway), one
//! 16-lane row at a time (one AVX-512 register, two AVX2 ones; a portable build too, all
//! bit-identical). For top-K every row visit is logged (one vector of 16 weights, see
//! `row_log`); at the end of the tile each row's log is packed into the band's top-K store
//! (per visit: id, lane mask, the reached pixels' weights; see `top_k`), counting each pixel's
//! contributions on the way. Pixels with more than K have their K heaviest chosen from their
//! gathered column (a quickselect on lane bit masks, see `keep_heaviest`) and the rest of
//! their entries unmarked. Voting (`row_votes`) costs nothing per visit while every Gaussian
//! of the tile carries one label (the silhouette is then that label's sum); after that each
//! tile row keeps the few labels it met and a 16-lane sum per label: one vector add per row
//! visit; rows meeting more labels are voted exactly at the end of the tile, from their
//! pixels' columns of the log or a replay.
//! Bands of 16 image rows run in parallel (rayon) with per-thread scratch kept across
//! frames; one kernel is compiled per combination of requested outputs and per SIMD level.

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::bin::TileBins;
use crate::blend::{alpha_of, gaussian_power, MIN_ALPHA, MIN_TRANSMITTANCE};
use crate::cpu::SimdLevel;
use crate::keep_heaviest::{keep_heaviest, KEEP_MAX};
use crate::output::{RenderOutput, RenderRequest};
use crate::project::Projected;
use crate::row_log::{Columns, PackDst, RowLog};
use crate::row_votes::RowVotes;
use crate::tiles::{TileGrid, TILE_SIZE};
use crate::top_k::{key_rank, topk_key, RowSpan, TopKBand, KEPT_SHIFT};
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

/// Sizes `v` to `n` elements, keeping its allocation. Contents are not reset when the size
/// already fits: the pass writes every pixel, and a memset of ~10 MB per frame is wasted.
fn fit<T: Clone>(v: &mut Vec<T>, n: usize, value: T) {
    if v.len() != n {
        v.clear();
        v.resize(n, value);
    }
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
    fit(&mut out.color, n, [0.0; 3]);
    fit(&mut out.depth, n, 0.0);
    fit(&mut out.silhouette, n, 0.0);
    fit(&mut out.final_transmittance, n, 1.0);
    fit(&mut out.n_contrib, n, 0);
    out.labels = match (request.labels, out.labels.take()) {
        (true, old) => {
            let mut v = old.unwrap_or_default();
            fit(&mut v, n, 0);
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
            t.tiles_x = grid.tiles_x;
            fit(&mut t.count, n, 0);
            fit(
                &mut t.rows,
                (grid.tiles_y * grid.tiles_x) as usize * T,
                RowSpan::default(),
            );
            // Band stores keep their length (they are truncated after writing).
            t.bands
                .resize_with(grid.tiles_y as usize, TopKBand::default);
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
        visible: visible.as_deref(),
        simd: SimdLevel::current(),
    };

    let band_len = T * w;
    let mut color = out.color.chunks_mut(band_len);
    let mut depth = out.depth.chunks_mut(band_len);
    let mut sil = out.silhouette.chunks_mut(band_len);
    let mut final_t = out.final_transmittance.chunks_mut(band_len);
    let mut n_contrib = out.n_contrib.chunks_mut(band_len);
    let mut label_img = out.labels.as_mut().map(|v| v.chunks_mut(band_len));
    let (mut tk_count, mut tk_rows, mut tk_bands) = match out.top_k.as_mut() {
        Some(t) => (
            Some(t.count.chunks_mut(band_len)),
            Some(t.rows.chunks_mut(grid.tiles_x as usize * T)),
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
            topk_count: tk_count.as_mut().and_then(|it| it.next()),
            topk_rows: tk_rows.as_mut().and_then(|it| it.next()),
            topk_band: tk_bands.as_mut().and_then(|it| it.next()),
            topk_visits: 0,
            topk_weights: 0,
        })
        .collect();

    let lists = top_k.is_some();
    bands.into_par_iter().for_each(|mut band| {
        SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let scratch = guard.get_or_insert_with(Scratch::new);
            for tx in 0..grid.tiles_x as usize {
                // One monomorphised kernel per combination, so unrequested outputs cost nothing.
                match (lists, request.labels) {
                    (false, false) => run_tile::<false, false>(&ctx, scratch, &mut band, tx),
                    (false, true) => run_tile::<false, true>(&ctx, scratch, &mut band, tx),
                    (true, false) => run_tile::<true, false>(&ctx, scratch, &mut band, tx),
                    (true, true) => run_tile::<true, true>(&ctx, scratch, &mut band, tx),
                }
            }
            if let Some(store) = band.topk_band.as_deref_mut() {
                store.ids.truncate(band.topk_visits);
                store.lanes.truncate(band.topk_visits);
                store.weights.truncate(band.topk_weights);
            }
        })
    });

    if let Some(vis) = visible {
        out.visible_per_label = Some(count_visible(&vis, labels));
    }
}

/// label → number of visible Gaussians; dense counting for the usual small label ids.
fn count_visible(vis: &[AtomicBool], labels: &[u32]) -> BTreeMap<u32, u32> {
    const DENSE: usize = 1 << 16;
    let mut dense: Vec<u32> = Vec::new();
    let mut sparse = BTreeMap::new();
    // Branch-free on visibility (about half the Gaussians are seen: a branch on it
    // mispredicts every other time, and this loop runs alone after the parallel pass).
    for (v, &label) in vis.iter().zip(labels) {
        let seen = v.load(Ordering::Relaxed) as u32;
        let l = label as usize;
        if l < DENSE {
            if l >= dense.len() {
                dense.resize(l + 1, 0);
            }
            dense[l] += seen;
        } else if seen != 0 {
            *sparse.entry(label).or_insert(0u32) += 1;
        }
    }
    for (l, &c) in dense.iter().enumerate() {
        if c > 0 {
            sparse.insert(l as u32, c);
        }
    }
    sparse
}

struct Ctx<'a> {
    projected: &'a Projected,
    bins: &'a TileBins,
    grid: &'a TileGrid,
    labels: &'a [u32],
    top_k: Option<usize>,
    visible: Option<&'a [AtomicBool]>,
    simd: SimdLevel,
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
    topk_count: Option<&'a mut [u16]>,
    /// The band's tile rows (tile tx, row y: `16·tx + y`).
    topk_rows: Option<&'a mut [RowSpan]>,
    topk_band: Option<&'a mut TopKBand>,
    /// Top-K visits and weights this band has written so far.
    topk_visits: usize,
    topk_weights: usize,
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
}

struct Scratch {
    st: Box<TileState>,
    /// GS Voting sums, per tile row.
    row_votes: Box<RowVotes>,
    log: RowLog,
    /// Gathered contributions (visit index, weight) of a row's pixels with more than K.
    long: (Vec<u32>, Vec<f32>),
    keys: Vec<u64>,
    votes: Vec<(u32, f32)>,
    replay: Vec<(u32, f32)>,
}

thread_local! {
    /// Per-thread tile scratch, kept across frames (no allocation or page faults per render).
    static SCRATCH: RefCell<Option<Scratch>> = const { RefCell::new(None) };
}

impl Scratch {
    fn new() -> Self {
        Self {
            row_votes: Box::new(RowVotes::new()),
            st: Box::new(TileState {
                t: [[1.0; T]; T],
                r: [[0.0; T]; T],
                g: [[0.0; T]; T],
                b: [[0.0; T]; T],
                d: [[0.0; T]; T],
                s: [[0.0; T]; T],
                last: [[0; T]; T],
                row_live: [0; T],
            }),
            log: RowLog::new(),
            long: (Vec::new(), Vec::new()),
            keys: Vec::new(),
            votes: Vec::new(),
            replay: Vec::new(),
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
}

/// Rasterizes tile `tx` of `band` and writes it out, with the best kernel for this CPU.
fn run_tile<const LISTS: bool, const VOTE: bool>(
    ctx: &Ctx,
    scratch: &mut Scratch,
    band: &mut BandOut,
    tx: usize,
) {
    match ctx.simd {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `SimdLevel::detected` chose Avx512 only after detecting avx512f/bw/vl and popcnt
        // on this CPU.
        SimdLevel::Avx512 => unsafe { tile_avx512::<LISTS, VOTE>(ctx, scratch, band, tx) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `SimdLevel::detected` chose Avx2 only after detecting avx2 and popcnt on this CPU.
        SimdLevel::Avx2 => unsafe { tile_avx2::<LISTS, VOTE>(ctx, scratch, band, tx) },
        SimdLevel::Portable => tile::<LISTS, VOTE>(ctx, scratch, band, tx),
    }
}

/// The tile compiled for AVX-512 (one 16-lane row per register, mask registers). No FMA is
/// enabled, so results are bit-identical to the portable build and the reference renderer.
///
/// # Safety
/// The caller must ensure the CPU supports AVX-512 F, BW and VL, and POPCNT.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,popcnt")]
unsafe fn tile_avx512<const LISTS: bool, const VOTE: bool>(
    ctx: &Ctx,
    scratch: &mut Scratch,
    band: &mut BandOut,
    tx: usize,
) {
    tile::<LISTS, VOTE>(ctx, scratch, band, tx)
}

/// The tile compiled for AVX2 (bit-identical results: no FMA).
///
/// # Safety
/// The caller must ensure the CPU supports AVX2 and POPCNT.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
unsafe fn tile_avx2<const LISTS: bool, const VOTE: bool>(
    ctx: &Ctx,
    scratch: &mut Scratch,
    band: &mut BandOut,
    tx: usize,
) {
    tile::<LISTS, VOTE>(ctx, scratch, band, tx)
}

#[inline(always)]
fn tile<const LISTS: bool, const VOTE: bool>(
    ctx: &Ctx,
    scratch: &mut Scratch,
    band: &mut BandOut,
    tx: usize,
) {
    let t = band.band * ctx.grid.tiles_x as usize + tx;
    tile_kernel::<LISTS, VOTE>(ctx, scratch, t);
    write_tile::<LISTS, VOTE>(ctx, scratch, band, tx, t);
}

#[inline(always)]
fn tile_kernel<const LISTS: bool, const VOTE: bool>(ctx: &Ctx, scratch: &mut Scratch, tile: usize) {
    let grid = ctx.grid;
    let tx0 = (tile % grid.tiles_x as usize) as u32 * TILE_SIZE;
    let ty0 = (tile / grid.tiles_x as usize) as u32 * TILE_SIZE;
    let cols = (grid.width - tx0).min(TILE_SIZE) as usize;
    let rows = (grid.height - ty0).min(TILE_SIZE) as usize;
    let st = &mut *scratch.st;
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
    if LISTS {
        scratch.log.clear();
    }
    if VOTE {
        scratch.row_votes.clear();
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
        };
        let label = if VOTE { ctx.labels[gi] } else { 0 };
        let vote_visits = VOTE && scratch.row_votes.per_visit(label, &st.s);
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
        let mut contributed = false;
        for py in y_lo..y_hi as u32 + 1 {
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
            // Conservative by 0.01 px: pixels outside fail the exact per-pixel tests anyway.
            let x_lo = (mx - (-b * dy + sq) * inv_a - 0.01).ceil() - tx0 as f32;
            let x_hi = (mx - (-b * dy - sq) * inv_a + 0.01).floor() - tx0 as f32;
            if x_hi < 0.0 || x_lo > (T - 1) as f32 || x_hi < x_lo {
                continue;
            }
            let mut w = [0.0f32; T];
            let (any, done_now) = blend_row(&g, dy, &lane_x, st, ly, &mut w);
            st.row_live[ly] -= done_now;
            live -= done_now;
            if !any {
                continue;
            }
            if vote_visits && label != 0 {
                scratch.row_votes.add(ly, label, &w);
            }
            if LISTS {
                scratch.log.push(ly, gid, &w);
            }
            contributed = true;
        }
        if contributed {
            if let Some(v) = ctx.visible {
                v[gi].store(true, Ordering::Relaxed);
            }
        }
    }
}

/// Composites one Gaussian over the 16 pixels of tile row `ly`. Writes each lane's weight
/// α·T (0 where it did not contribute) into `w`; returns (whether any lane contributed,
/// number of pixels that became done). (A bool, not a lane mask: a mask built lane by lane
/// compiles to a vector OR-reduction on the loop's critical path.)
#[inline(always)]
fn blend_row(
    g: &LaneGaussian,
    dy: f32,
    lane_x: &[f32; T],
    st: &mut TileState,
    ly: usize,
    w: &mut [f32; T],
) -> (bool, u32) {
    let t = &mut st.t[ly];
    let (r, gr, b) = (&mut st.r[ly], &mut st.g[ly], &mut st.b[ly]);
    let (d, s) = (&mut st.d[ly], &mut st.s[ly]);
    let last = &mut st.last[ly];
    let mut any = false;
    let mut newly_done = 0u32;
    for i in 0..T {
        let dx = g.mean_x - lane_x[i];
        let power = gaussian_power(g.conic, dx, dy);
        let alpha = alpha_of(g.opacity, power);
        let valid = (power <= 0.0) & (alpha >= MIN_ALPHA);
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
        any |= contrib;
        w[i] = wi;
    }
    (any, newly_done)
}

/// Weights (tile rank, α·T) of one pixel's contributions, front to back: the kernel's
/// arithmetic replayed for a single pixel (voting rows that met more labels than their table
/// holds when no log was kept; on-demand top-K).
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

/// Copies a finished tile into the band's images, and resolves labels and top-K.
#[inline(always)]
fn write_tile<const LISTS: bool, const VOTE: bool>(
    ctx: &Ctx,
    scratch: &mut Scratch,
    band: &mut BandOut,
    tx: usize,
    tile: usize,
) {
    let grid = ctx.grid;
    let w = grid.width as usize;
    let x0 = tx * T;
    let cols = (w - x0).min(T);
    let rows = band.color.len() / w;
    let st = &*scratch.st;
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
    if LISTS {
        build_top_k(ctx, scratch, band, tx, rows, cols);
    }
    if VOTE {
        if let Some(labels) = band.labels.as_deref_mut() {
            let Scratch {
                st,
                row_votes,
                log,
                votes,
                replay,
                ..
            } = scratch;
            if let Some(l) = row_votes.uniform() {
                // Every contributing Gaussian carried label l (weights are positive, so a
                // pixel took something exactly where its silhouette is above 0).
                for y in 0..rows {
                    let row = &mut labels[y * w + x0..][..cols];
                    for (label, &s) in row.iter_mut().zip(&st.s[y]) {
                        *label = if s > 0.0 { l } else { 0 };
                    }
                }
                return;
            }
            for y in 0..rows {
                let row = &mut labels[y * w + x0..][..cols];
                if !row_votes.overflowed(y) {
                    row.copy_from_slice(&row_votes.winners(y)[..cols]);
                    continue;
                }
                // More labels than the row tracks: vote over each pixel's column of the log,
                // or its replay when no log was kept.
                for (x, label) in row.iter_mut().enumerate() {
                    *label = if LISTS {
                        vote_list(log.column(y, x), ctx.labels, votes)
                    } else {
                        let (px, py) = ((x0 + x) as u32, (band.band * T + y) as u32);
                        replay_pixel(ctx.projected, list, px, py, replay);
                        let it = replay
                            .iter()
                            .map(|&(r, wt)| (ctx.labels[list[r as usize] as usize], wt));
                        vote(it, votes)
                    };
                }
            }
        }
    }
}

/// Label slots of the list vote before it falls back to the general [`vote`].
const LIST_VOTE_SLOTS: usize = 8;

/// GS Voting over one pixel's contributions (Gaussian id, weight), front to back: the same
/// sums, in the same order, as [`vote`] and the reference, so the same winner.
#[inline(always)]
fn vote_list(
    entries: impl Iterator<Item = (u32, f32)> + Clone,
    labels: &[u32],
    votes: &mut Vec<(u32, f32)>,
) -> u32 {
    let mut lab = [0u32; LIST_VOTE_SLOTS];
    let mut sum = [0.0f32; LIST_VOTE_SLOTS];
    let mut used = 0usize;
    // The running label's sum stays in a register (a store and reload per entry would
    // chain through store forwarding); it is written back when the label changes.
    let (mut cur, mut cur_label, mut acc) = (0usize, 0u32, 0.0f32);
    for (id, wt) in entries.clone() {
        let l = labels[id as usize];
        if l == 0 {
            continue;
        }
        if l != cur_label {
            if cur_label != 0 {
                sum[cur] = acc;
            }
            cur_label = l;
            cur = lab[..used].iter().position(|&x| x == l).unwrap_or(used);
            if cur == used {
                if used == LIST_VOTE_SLOTS {
                    let it = entries.map(|(i, w)| (labels[i as usize], w));
                    return vote(it, votes);
                }
                lab[used] = l;
                sum[used] = 0.0;
                used += 1;
            }
            cur &= LIST_VOTE_SLOTS - 1;
            acc = sum[cur];
        }
        // 0 + w == w exactly, so a new label's sum starts like the reference's.
        acc += wt;
    }
    if cur_label != 0 {
        sum[cur] = acc;
    }
    let mut best = (0u32, 0.0f32);
    for (&l, &s) in lab[..used].iter().zip(&sum[..used]) {
        if best.0 == 0 || s > best.1 || (s == best.1 && l < best.0) {
            best = (l, s);
        }
    }
    best.0
}

/// Writes the tile's top-K into the band store: each row's log is packed (its visits, lane
/// masks and weights, every contribution marked kept) and its pixels counted; pixels with
/// more than K contributions then keep only their K heaviest marked.
#[inline(always)]
fn build_top_k(
    ctx: &Ctx,
    scratch: &mut Scratch,
    band: &mut BandOut,
    tx: usize,
    rows: usize,
    cols: usize,
) {
    let w = ctx.grid.width as usize;
    let k = ctx.top_k.unwrap_or(usize::MAX);
    let (Some(count), Some(spans), Some(store)) = (
        band.topk_count.as_deref_mut(),
        band.topk_rows.as_deref_mut(),
        band.topk_band.as_deref_mut(),
    ) else {
        return;
    };
    let Scratch {
        log, long, keys, ..
    } = scratch;
    let simd = ctx.simd;
    let x0 = tx * T;
    for (y, span) in spans[tx * T..][..T].iter_mut().enumerate() {
        let (v0, w0) = (band.topk_visits, band.topk_weights);
        let n = if y < rows { log.len(y) } else { 0 };
        *span = RowSpan {
            visits: v0 as u32,
            len: n as u32,
            weights: w0 as u32,
        };
        if n == 0 {
            if y < rows {
                count[y * w + x0..][..cols].fill(0);
            }
            continue;
        }
        // The store keeps last frame's length: grow only (no per-frame memset); the band
        // truncates it to what it used when done. A visit's store writes 16 weights.
        if store.ids.len() < v0 + n {
            store.ids.resize(v0 + n, 0);
            store.lanes.resize(v0 + n, 0);
        }
        if store.weights.len() < w0 + T * n {
            store.weights.resize(w0 + T * n, half::f16::ZERO);
        }
        let packed = log.pack(
            y,
            simd,
            PackDst {
                ids: &mut store.ids[v0..v0 + n],
                lanes: &mut store.lanes[v0..v0 + n],
                weights: &mut store.weights[w0..w0 + T * n],
            },
        );
        band.topk_visits += n;
        band.topk_weights += packed.weights;
        let o = y * w + x0;
        let mut longer = 0u32;
        for (x, &c) in packed.counts.iter().enumerate().take(cols) {
            count[o + x] = c.min(k as u32) as u16;
            longer |= ((c as usize > k) as u32) << x;
        }
        if longer == 0 {
            continue;
        }
        // Pixels with more than K: their lighter entries are unmarked.
        let (long_visits, long_ws) = long;
        // Room for each gathered pixel's list, its last compressed store and keep_heaviest's
        // padding to 64 lanes.
        let stride = n.div_ceil(64) * 64 + T;
        if long_visits.len() < T * stride {
            long_visits.resize(T * stride, 0);
            long_ws.resize(T * stride, 0.0);
        }
        let len = log.gather(
            y,
            longer,
            simd,
            Columns {
                stride,
                visits: long_visits,
                ws: long_ws,
            },
        );
        let lanes = &mut store.lanes[v0..v0 + n];
        let mut xs = longer;
        while xs != 0 {
            let x = xs.trailing_zeros() as usize;
            xs &= xs - 1;
            let c = len[x];
            debug_assert_eq!(c, packed.counts[x] as usize);
            let (visits, ws) = (
                &long_visits[x * stride..][..stride],
                &mut long_ws[x * stride..][..stride],
            );
            let unmark = !(1u32 << (KEPT_SHIFT as usize + x));
            if c <= KEEP_MAX {
                ws[c..c.div_ceil(64) * 64].fill(0.0);
                let keep = keep_heaviest(ws, c, k, simd);
                for (b, &word) in keep.iter().enumerate().take(c.div_ceil(64)) {
                    let entries = (c - 64 * b).min(64);
                    let mut drop = !word & (!0u64 >> (64 - entries));
                    while drop != 0 {
                        let i = 64 * b + drop.trailing_zeros() as usize;
                        drop &= drop - 1;
                        lanes[visits[i] as usize] &= unmark;
                    }
                }
            } else {
                keys.clear();
                keys.extend((0..c).map(|i| topk_key(ws[i], i as u32)));
                // The lightest c − K: ranks past the K heaviest after the selection.
                keys.select_nth_unstable_by(k - 1, |a, b| b.cmp(a));
                for &key in &keys[k..] {
                    lanes[visits[key_rank(key) as usize] as usize] &= unmark;
                }
            }
        }
    }
}
