//! `cargo bench -p opengs-splat --bench map`: one mapping step (colour + depth render, loss,
//! backward, Adam) with 100k Gaussians at 640×480 and 320×240; prints medians.
//! `-- --steps N` sets the timed steps per case (default 15).

use opengs_splat::bench_train_steps;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let steps = args
        .iter()
        .position(|a| a == "--steps")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(15);
    // The machine may be shared: the load average says how much the wall times can be trusted.
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "mapping step benchmark ({steps} timed steps per case, medians; loadavg {})",
        load.trim()
    );
    for (w, h) in [(640, 480), (320, 240)] {
        println!("{}", bench_train_steps(100_000, w, h, steps));
    }
}
