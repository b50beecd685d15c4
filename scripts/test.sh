#!/usr/bin/env bash
# The whole test suite, from a fresh clone: Python peers into .venv, then one release build
# shared by the binaries and every test (the end-to-end tests drive target/release/scaledp).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup-python.sh
cargo fmt --all -- --check
cargo build --release --workspace --bins --locked
bash scripts/build-python.sh   # the scaledp_data wheel, reusing that build
cargo test --release --workspace --locked
