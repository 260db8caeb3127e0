#!/usr/bin/env bash
# The project's one test command (README and .ci/run both call it): fetches the
# ONNX Runtime library, builds every stage binary the end-to-end tests launch,
# then checks formatting and lints and runs all tests, the ONNX ones included. The Python
# environment (rosbags) lets the ROS 2 bag tests check our reader and writer against an
# independent implementation; they fail rather than skip here.
set -euo pipefail
cd "$(dirname "$0")/.."
ORT_DYLIB_PATH="$(scripts/setup-ort.sh)"
export ORT_DYLIB_PATH OPENGS_REQUIRE_ORT=1
OPENGS_PYTHON="$(scripts/setup-python.sh)"
export OPENGS_PYTHON OPENGS_REQUIRE_PYTHON=1
features=(--features opengs-perception/onnx)
cargo fmt --all -- --check
cargo build --release --workspace --bins "${features[@]}"
cargo clippy --release --workspace --all-targets "${features[@]}" -- -D warnings
cargo test --release --workspace "${features[@]}"
