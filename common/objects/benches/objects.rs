//! `cargo bench -p opengs-objects --bench objects`: `list` and `extract` on a 100k-Gaussian
//! map (the splat crate's synthetic room), in memory; prints medians. The CLI adds reading the
//! PLY (also timed here) and, for extract, writing the object's file.

use std::time::Instant;

use opengs_objects::{list_objects, split, Selection};
use opengs_splat::{read_ply, scene::indoor_scene, write_ply};

const REPEATS: usize = 11;

/// Median milliseconds of `REPEATS` runs of `f`.
fn median_ms(mut f: impl FnMut()) -> f64 {
    let mut times: Vec<f64> = (0..REPEATS)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[REPEATS / 2]
}

fn main() {
    let map = indoor_scene(100_000, 1);
    let mut ply = Vec::new();
    write_ply(&map, &mut ply).expect("PLY to memory");
    let objects = list_objects(&map, None);
    // The largest object by volume, as `extract --label` would pick it from the list.
    let label = objects.first().expect("the room has objects").id;
    let selection = Selection::of_labels(&map, None, &[label]).expect("label of the map");
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "{} Gaussians, {} objects; medians of {REPEATS} runs (loadavg {})",
        map.len(),
        objects.len(),
        load.trim()
    );
    let read = median_ms(|| {
        read_ply(&ply).expect("read back");
    });
    let list = median_ms(|| {
        list_objects(&map, None);
    });
    let mut size = 0;
    let extract = median_ms(|| {
        let (object, _) = split(&map, &selection);
        let mut out = Vec::new();
        write_ply(&object, &mut out).expect("PLY to memory");
        size = object.len();
    });
    println!("read PLY ({} MB)      {read:7.1} ms", ply.len() / 1_000_000);
    println!("list                  {list:7.1} ms");
    println!("extract label {label} ({size} Gaussians, split + PLY bytes) {extract:7.1} ms");
}
