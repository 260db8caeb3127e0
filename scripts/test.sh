#!/usr/bin/env bash
# The project's one test command (README and .ci/run both call it):
# builds every stage binary the end-to-end tests launch, then runs all tests.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo fmt --all -- --check
cargo build --release --workspace --bins
cargo clippy --release --workspace --all-targets -- -D warnings
cargo test --release --workspace
