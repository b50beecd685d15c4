#!/usr/bin/env bash
# The whole test suite, from a fresh clone (what CI runs, through .ci/run): Python peers into
# .venv, formatting, one release build shared by the binaries, the tests and the demo, the
# scaledp_data wheel, every test with clippy (warnings as errors) beside them, and a check for
# unused dependencies. Prints how long each step took and the total.
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
  # A failed step leaves no venv, cargo-machete install, clippy or test run behind it.
  local pid
  for pid in "${venvs_pid:-}" "${machete_pid:-}" "${clippy_pid:-}" "${test_pid:-}"; do
    if [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; then
      pkill -P "$pid" 2>/dev/null || true
      kill "$pid" 2>/dev/null || true
    fi
  done
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

# The Python peers (.venv), LeRobot 0.4.4 with torch (.venv-bench: several GB from PyPI, kept
# between runs; the video conformance tests read what LeRobot itself writes, and the PyTorch
# route's tests train with this torch) and MetaWorld 3.1 + gym-aloha on MuJoCo 3.3 (.venv-sims:
# the simulation benchmarks' bridges). Mostly downloads and unpacking: they run beside the
# release build, which is all CPU, and the tests wait for them.
mkdir -p target
venvs_log=target/test-venvs.log
venvs_start=$(date +%s)
# Niced: unpacking several GB of wheels is CPU the build would otherwise lose, and the venvs
# still finish long before it does.
( nice -n 19 bash scripts/setup-python.sh && nice -n 19 bash scripts/setup-bench-python.sh &&
  nice -n 19 bash scripts/setup-sims.sh
  echo "venvs done after $(( $(date +%s) - venvs_start )) s" ) > "$venvs_log" 2>&1 &
venvs_pid=$!
wait_venvs() {
  if ! wait "$venvs_pid"; then
    echo "setting up the Python venvs failed (their log, $venvs_log):"
    cat "$venvs_log"
    exit 1
  fi
  steps+=("$(printf '%-28s %4d s' "  (venvs, beside the build)" "$(sed -n 's/^venvs done after \([0-9]*\) s$/\1/p' "$venvs_log")")")
  grep -v '^venvs done' "$venvs_log" | sed 's/^/  /'
}
step "venvs started"

cargo fmt --all -- --check
step "cargo fmt --check"

# One build for everything: `cargo run --release --bin scaledp -- demo` (the README) selects the
# same packages, so its dependencies are these artifacts too. The `tests` crate lists every
# dev-dependency as a normal one, so building tests adds no features to a shared crate and
# nothing compiles twice.
cargo build --release --workspace --all-targets --locked --timings
step "cargo build --release"
# Where the build went (the slowest units, our test executables' share): the report is
# target/cargo-timings/cargo-timing.html.
python3 scripts/timings.py target/cargo-timings/cargo-timing.html 15 || true

wait_venvs
step "waiting for the venvs"

bash scripts/build-python.sh   # the scaledp_data wheel, reusing that build
step "scaledp_data wheel"

# The tests wait on child processes and sockets much of the time (a fresh clone's ran at 1.4 of
# the 2 cores): clippy and cargo-machete's install use what they leave, niced so that the
# rate-bound tests keep their cores. cargo-machete builds in its own target dir.
nice -n 19 bash scripts/check-deps.sh --install-only > target/check-deps.log 2>&1 &
machete_pid=$!
# The Python processes the tests start (simulators, LeRobot, torch) cache their bytecode in
# target/pycache, so that only the first compiles each module: the venvs are installed without
# it, and a CI image may set PYTHONDONTWRITEBYTECODE.
unset PYTHONDONTWRITEBYTECODE
export PYTHONPYCACHEPREFIX="$PWD/target/pycache"
# --no-fail-fast: every test executable runs, so one failure does not hide the others'.
test_log=target/cargo-test.stderr
cargo test --release --workspace --locked --no-fail-fast 2> >(tee "$test_log" >&2) &
test_pid=$!
# Clippy needs the build directory's lock, which `cargo test` holds until its executables are
# built and released before it runs the first: start clippy then (check mode in the release
# profile, so build scripts and proc-macros are the ones already built; dependencies are
# re-checked, as check metadata is not the build's: ~2.5 min of CPU).
for _ in $(seq 1200); do
  grep -q '^ *Running ' "$test_log" 2>/dev/null && break
  kill -0 "$test_pid" 2>/dev/null || break
  sleep 0.5
done
clippy_log=target/clippy.log
clippy_start=$(date +%s)
( rc=0
  nice -n 19 cargo clippy --release --workspace --all-targets --locked -- -D warnings || rc=$?
  echo "clippy done after $(( $(date +%s) - clippy_start )) s"
  exit "$rc" ) > "$clippy_log" 2>&1 &
clippy_pid=$!
test_rc=0
wait "$test_pid" || test_rc=$?
step "cargo test"
clippy_rc=0
wait "$clippy_pid" || clippy_rc=$?
step "cargo clippy -D warnings (rest)"
steps+=("$(printf '%-28s %4s s' "  (clippy, from the tests)" "$(sed -n 's/^clippy done after \([0-9]*\) s$/\1/p' "$clippy_log")")")
if [ "$clippy_rc" -ne 0 ]; then
  echo "cargo clippy -D warnings failed (its log, $clippy_log):"
  cat "$clippy_log"
  exit 1
fi
[ "$test_rc" -eq 0 ] || { echo "cargo test failed (exit $test_rc): the failures are listed above"; exit "$test_rc"; }

wait "$machete_pid" || { cat target/check-deps.log; exit 1; }
bash scripts/check-deps.sh
step "unused dependencies"
