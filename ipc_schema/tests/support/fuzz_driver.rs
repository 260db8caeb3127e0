//! The fuzz driver the fuzz targets share (ipc_schema, geometry, splat, datasets include it
//! with `#[path]`): seeded inputs on a watched thread, a panic or a hang named by its seed.
//! `OPENGS_FUZZ_CASES=N` sets the inputs per target (20,000 by default; 10^6 for a full run),
//! `OPENGS_FUZZ_SEED=S` the first seed (with `OPENGS_FUZZ_CASES=1`, replays one input).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub type R = ChaCha8Rng;

const QUICK: u64 = 20_000;
/// One input taking this long is a hang (they take microseconds).
const HANG: Duration = Duration::from_secs(10);

fn env_u64(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

/// Runs `case` on inputs from seeds `first..first + cases` on a watched thread; `case` says
/// whether the input was accepted. A panic or a hang names the seed that reproduces it.
pub fn fuzz(name: &str, case: fn(&mut R) -> bool) {
    let cases = env_u64("OPENGS_FUZZ_CASES").unwrap_or(QUICK);
    let first = env_u64("OPENGS_FUZZ_SEED").unwrap_or(0);
    let current = Arc::new(AtomicU64::new(first));
    let worker = {
        let current = current.clone();
        std::thread::spawn(move || {
            let mut accepted = 0u64;
            for seed in first..first + cases {
                current.store(seed, Ordering::Relaxed);
                accepted += case(&mut R::seed_from_u64(seed)) as u64;
            }
            accepted
        })
    };
    let start = Instant::now();
    let (mut seen, mut since) = (first, Instant::now());
    while !worker.is_finished() {
        std::thread::sleep(Duration::from_millis(20));
        let now = current.load(Ordering::Relaxed);
        if now != seen {
            (seen, since) = (now, Instant::now());
        } else if since.elapsed() > HANG {
            panic!("{name}: input OPENGS_FUZZ_SEED={now} hangs");
        }
    }
    let Ok(accepted) = worker.join() else {
        let seed = current.load(Ordering::Relaxed);
        panic!("{name}: input OPENGS_FUZZ_SEED={seed} panicked");
    };
    eprintln!(
        "fuzz {name}: {cases} inputs ({accepted} accepted) in {:.1} s",
        start.elapsed().as_secs_f64()
    );
}

pub fn pick<T: Copy>(rng: &mut R, xs: &[T]) -> T {
    xs[rng.gen_range(0..xs.len())]
}
