//! `cargo bench -p opengs-perception --bench segment`

fn main() {
    if let Err(e) = opengs_perception::bench::print_segment_bench(8, 5) {
        eprintln!("segment bench failed: {e}");
        std::process::exit(1);
    }
}
