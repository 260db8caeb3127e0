//! Consensus timing: one 640×480 keyframe with ~100 input and ~100 rendered labels (target
//! ≤ 20 ms per keyframe on one core). `opengs bench consensus` and `cargo bench` print it.

use std::collections::BTreeMap;
use std::time::Instant;

use crate::{
    ConsensusConfig, GlobalLabelTable, InputLabelClass, LabelConsensus, Overlap, RenderedInput,
    SegmenterInput,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const W: usize = 640;
const H: usize = 480;
const SEGMENTS: usize = 100;

/// Label of the nearest seed (Voronoi cells look like segments); 0 beyond `max_x`.
fn voronoi(seeds: &[(f32, f32, u32)], max_x: usize) -> Vec<u32> {
    let mut map = vec![0; W * H];
    for y in 0..H {
        for x in 0..max_x {
            let (px, py) = (x as f32, y as f32);
            let nearest = seeds.iter().min_by(|a, b| {
                let da = (a.0 - px).powi(2) + (a.1 - py).powi(2);
                let db = (b.0 - px).powi(2) + (b.1 - py).powi(2);
                da.total_cmp(&db)
            });
            map[y * W + x] = nearest.map_or(0, |s| s.2);
        }
    }
    map
}

/// Prints the median time of one 640×480 keyframe with ~100 input and ~100 rendered labels
/// over `runs` runs (one core), then the per-pixel-noise worst case.
pub fn print_consensus_bench(runs: usize) {
    let runs = runs.max(1);
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let seeds: Vec<(f32, f32)> = (0..SEGMENTS)
        .map(|_| (rng.gen_range(0.0..W as f32), rng.gen_range(0.0..H as f32)))
        .collect();
    // Input: one cell per seed, labels 1..=100.
    let input_seeds: Vec<_> = seeds
        .iter()
        .enumerate()
        .map(|(i, &(x, y))| (x, y, i as u32 + 1))
        .collect();
    // Rendered: jittered seeds (Full / Partial / Whole / other mixes), every 10th dropped,
    // every 7th split in two; nothing rendered in the right 60 columns (New segments).
    let mut rendered_seeds = Vec::new();
    for (i, &(x, y)) in seeds.iter().enumerate() {
        let label = i as u32 + 1;
        if i % 10 == 9 {
            continue;
        }
        let jitter = |rng: &mut ChaCha8Rng| rng.gen_range(-8.0..8.0f32);
        rendered_seeds.push((x + jitter(&mut rng), y + jitter(&mut rng), label));
        if i % 7 == 0 {
            rendered_seeds.push((x + 20.0, y + 15.0, 1000 + label));
        }
    }
    let input_map = voronoi(&input_seeds, W);
    let rendered_map = voronoi(&rendered_seeds, W - 60);

    let confidence: BTreeMap<u32, f32> = (1..=SEGMENTS as u32)
        .map(|l| (l, rng.gen_range(0.3..1.0)))
        .collect();
    let classes: BTreeMap<u32, InputLabelClass> = (1..=SEGMENTS as u32)
        .map(|l| {
            (
                l,
                InputLabelClass {
                    class: Some(format!("class{}", l % 17)),
                    score: 0.5,
                },
            )
        })
        .collect();
    let completeness: BTreeMap<u32, f32> = rendered_seeds
        .iter()
        .map(|s| (s.2, rng.gen_range(0.3..1.0)))
        .collect();

    let config = ConsensusConfig::default();
    let mut table = GlobalLabelTable::new(config.max_labels);
    for _ in 0..SEGMENTS {
        let c = rng.gen_range(0.3..1.0);
        let _ = table.allocate(None, 0.0, c);
    }
    let prepared = match LabelConsensus::with_table(config, table) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("bad config: {e}");
            return;
        }
    };
    let input = SegmenterInput {
        width: W,
        height: H,
        label_map: &input_map,
        confidence: &confidence,
        classes: &classes,
    };
    let rendered = RenderedInput {
        label_map: &rendered_map,
        completeness: &completeness,
    };

    let mut times = Vec::with_capacity(runs);
    let mut last = None;
    for _ in 0..runs {
        let mut consensus = prepared.clone();
        let start = Instant::now();
        let out = consensus.process(&input, &rendered);
        times.push(start.elapsed().as_secs_f64() * 1e3);
        last = Some(out);
    }
    times.sort_by(f64::total_cmp);
    let median = times[runs / 2];
    match &last {
        Some(Ok(out)) => {
            let mut relations = BTreeMap::new();
            for a in &out.assignments {
                *relations.entry(format!("{:?}", a.relation)).or_insert(0) += 1;
            }
            let distinct: std::collections::BTreeSet<_> =
                rendered_map.iter().filter(|&&l| l != 0).collect();
            println!(
                "consensus {W}×{H}: {} input labels, {} rendered labels, relations {relations:?}, \
                 {} relabels, {} prune regions",
                out.assignments.len(),
                distinct.len(),
                out.relabels.len(),
                out.counter_pruning.len()
            );
        }
        Some(Err(e)) => eprintln!("consensus failed: {e}"),
        None => {}
    }
    println!(
        "median {median:.3} ms per keyframe over {runs} runs (min {:.3}, max {:.3}); target ≤ 20 ms",
        times[0],
        times[runs - 1]
    );
    if let Some(Ok(out)) = &last {
        application(out, &rendered_map, runs);
    }
    worst_case(&prepared, &mut rng, runs);
}

/// What the mapper does with the answer: the counter-pruning selection over a render's
/// top-K (a Gaussian every 2 pixels each way, 16 per pixel: those of the 4×4 cells around
/// it, labelled by the rendered map at their centre), tile row by tile row and, side by
/// side, pixel by pixel.
fn application(out: &crate::ConsensusOutput, rendered_map: &[u32], runs: usize) {
    const STEP: usize = 2;
    let (gw, gh) = (W / STEP, H / STEP);
    let lists: Vec<Vec<(u32, f32)>> = (0..W * H)
        .map(|p| {
            let (cx, cy) = ((p % W) / STEP, (p / W) / STEP);
            let (x0, y0) = (cx.saturating_sub(1), cy.saturating_sub(1));
            (y0..(y0 + 4).min(gh))
                .flat_map(|y| (x0..(x0 + 4).min(gw)).map(move |x| ((y * gw + x) as u32, 0.05)))
                .collect()
        })
        .collect();
    let top_k = opengs_splat::TopK::from_lists(W as u32, H as u32, &lists);
    let labels: Vec<u32> = (0..gw * gh)
        .map(|g| rendered_map[(g / gw) * STEP * W + (g % gw) * STEP])
        .collect();
    let scale = |g: usize| 0.02 + 0.02 * (g % 7) as f32;
    let theta = ConsensusConfig::default().counter_prune_scale;
    let regions = &out.counter_pruning;
    let pixels: usize = regions.iter().map(|r| r.pixels.len()).sum();
    let time = |per_pixel: bool| {
        let mut times: Vec<f64> = (0..runs)
            .map(|_| {
                let start = Instant::now();
                let selected = match per_pixel {
                    true => crate::select_counter_gaussians_per_pixel(
                        &top_k, &labels, scale, theta, regions,
                    ),
                    false => {
                        crate::select_counter_gaussians(&top_k, &labels, scale, theta, regions)
                    }
                };
                let elapsed = start.elapsed().as_secs_f64() * 1e3;
                std::hint::black_box(selected.map(|s| s.len()).unwrap_or(0));
                elapsed
            })
            .collect();
        times.sort_by(f64::total_cmp);
        times[times.len() / 2]
    };
    let (rows, per_pixel) = (time(false), time(true));
    let selected = crate::select_counter_gaussians(&top_k, &labels, scale, theta, regions)
        .map_or(0, |s| s.len());
    println!(
        "counter pruning in the mapper ({} regions, {pixels} pixels, {} of {} Gaussians \
         selected, top-{}): median {rows:.3} ms by tile rows, {per_pixel:.3} ms pixel by \
         pixel ({:.1}×)",
        regions.len(),
        selected,
        labels.len(),
        top_k.k,
        per_pixel / rows.max(1e-9)
    );
}

/// Salt-and-pepper maps (a new (ℓs, ℓr) pair at almost every pixel): the hashing worst case.
fn worst_case(prepared: &LabelConsensus, rng: &mut ChaCha8Rng, runs: usize) {
    let input_map: Vec<u32> = (0..W * H)
        .map(|_| rng.gen_range(1..=SEGMENTS as u32))
        .collect();
    let rendered_map: Vec<u32> = (0..W * H)
        .map(|_| rng.gen_range(0..=SEGMENTS as u32))
        .collect();
    let confidence: BTreeMap<u32, f32> = (1..=SEGMENTS as u32).map(|l| (l, 0.5)).collect();
    let completeness: BTreeMap<u32, f32> = (1..=SEGMENTS as u32).map(|l| (l, 0.5)).collect();
    let classes = BTreeMap::new();
    let input = SegmenterInput {
        width: W,
        height: H,
        label_map: &input_map,
        confidence: &confidence,
        classes: &classes,
    };
    let rendered = RenderedInput {
        label_map: &rendered_map,
        completeness: &completeness,
    };
    let mut times: Vec<f64> = (0..(runs / 5).max(1))
        .map(|_| {
            let mut consensus = prepared.clone();
            let start = Instant::now();
            let _ = consensus.process(&input, &rendered);
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let mut count_times: Vec<f64> = (0..(runs / 5).max(1))
        .map(|_| {
            let start = Instant::now();
            let overlap = Overlap::count(&input_map, &rendered_map);
            let elapsed = start.elapsed().as_secs_f64() * 1e3;
            std::hint::black_box(overlap);
            elapsed
        })
        .collect();
    count_times.sort_by(f64::total_cmp);
    println!(
        "worst case (per-pixel noise): median {:.3} ms per keyframe ({:.3} ms counting overlaps)",
        times[times.len() / 2],
        count_times[count_times.len() / 2]
    );
}
