//! `cargo bench -p opengs-semantics --bench consensus`: see `opengs_semantics::bench`.

fn main() {
    opengs_semantics::bench::print_consensus_bench(50);
}
