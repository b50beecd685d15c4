#!/usr/bin/env bash
# The whole test suite, from a fresh clone (what CI runs, through .ci/run): Python peers into
# .venv, formatting, one release build shared by the binaries, the tests and the demo, clippy
# with warnings as errors, the scaledp_data wheel, every test, and a check for unused
# dependencies. Prints how long each step took and the total.
set -euo pipefail
cd "$(dirname "$0")/.."

start=$(date +%s)
step_start=$start
steps=()
step() {
  local now
  now=$(date +%s)
  steps+=("$(printf '%-28s %4d s' "$1" $((now - step_start)))")
  step_start=$now
}
report() {
  local rc=$?
  echo
  echo "== scripts/test.sh timings =="
  printf '%s\n' "${steps[@]}"
  echo "disk: $(free_disk) at the end"
  printf 'total %d min %d s (exit %d)\n' $((($(date +%s) - start) / 60)) $((($(date +%s) - start) % 60)) "$rc"
}
trap report EXIT
# A fresh clone used 14.4 GB at 764788e (the three venvs 10.4, target/ 4.0; cargo's registry aside;
# LeRobot's venv is 0.7 GB smaller since):
# say what the disk had, so a run that fills it is told apart from a failing test.
free_disk() { df -Ph . | awk 'NR == 2 {print $4 " free on " $6}'; }
echo "scripts/test.sh: $(free_disk) at the start"

bash scripts/setup-python.sh
step "python peers (.venv)"

# LeRobot 0.4.4 and torch (several GB from PyPI, kept in .venv-bench between runs): the video
# conformance tests read what LeRobot itself writes and returns, and the PyTorch route's tests
# (tests/tests/torch_route) train with this torch: one copy of it for both.
bash scripts/setup-bench-python.sh
step "lerobot (.venv-bench)"

# MetaWorld 3.1 and gym-aloha on MuJoCo 3.3 (.venv-sims): the simulation benchmarks' bridges,
# their kinematics tests and the MetaWorld end-to-end test.
bash scripts/setup-sims.sh
step "simulators (.venv-sims)"

cargo fmt --all -- --check
step "cargo fmt --check"

# One build for everything: `cargo run --release --bin scaledp -- demo` (the README) selects the
# same packages, so its dependencies are these artifacts too. The `tests` crate lists every
# dev-dependency as a normal one, so building tests adds no features to a shared crate and
# nothing compiles twice.
cargo build --release --workspace --all-targets --locked
step "cargo build --release"

# Check mode in the release profile: build scripts and proc-macros are the ones just built.
cargo clippy --release --workspace --all-targets --locked -- -D warnings
step "cargo clippy -D warnings"

bash scripts/build-python.sh   # the scaledp_data wheel, reusing that build
step "scaledp_data wheel"

cargo test --release --workspace --locked
step "cargo test"

bash scripts/check-deps.sh
step "unused dependencies"
