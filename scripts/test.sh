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
  # A failed step leaves no venv or cargo-machete install behind it.
  local pid
  for pid in "${venvs_pid:-}" "${machete_pid:-}" "${cargo_pid:-}" "${tail_pid:-}"; do
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

# Clippy runs inside the build: cargo compiles the workspace's own crates with clippy-driver
# (rustc with clippy's lints; the wrapper `cargo clippy` itself sets) and the dependencies with
# rustc, so the lints cost their passes over our crates only (23 s of wall). A separate `cargo
# clippy` re-checked all ~830 dependencies (check metadata is not the build's): 537 s beside
# the tests and 188 s after them on a CI machine (docs/benchmarks.md). The tests and the wheel
# below reuse this build, as they inherit the same wrapper; a plain `cargo build` (the README's
# demo) compiles our crates once more into artifacts of its own, the dependencies not again.
RUSTC_WORKSPACE_WRAPPER=$(rustup which clippy-driver 2>/dev/null || command -v clippy-driver) || {
  echo "clippy-driver not found: the tests lint with clippy (rustup component add clippy)"
  exit 1
}
export RUSTC_WORKSPACE_WRAPPER
# cargo-clippy's encoding of `-- -D warnings`: each argument followed by the separator.
export CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__"
# scaledp-experiment records the commit it was built from (git-version's `git describe --dirty`,
# rebuilt when .git/index moves). On a fresh clone the index's entries are racily clean (written
# in the same second as the files), so that describe rewrote the index in the middle of the
# build, and `cargo test` then compiled scaledp-experiment and the CLI again (~1 min). Refreshed
# here, at least a second after the checkout, the index stays as it is.
sleep 1
git update-index -q --refresh 2>/dev/null || true
# One build for everything. The `tests` crate lists every dev-dependency as a normal one, so
# building tests adds no features to a shared crate and nothing compiles twice.
cargo build --release --workspace --all-targets --locked --timings
step "cargo build --release (clippy)"
# Where the build went (the slowest units, our test executables' share): the report is
# target/cargo-timings/cargo-timing.html.
python3 scripts/timings.py target/cargo-timings/cargo-timing.html 15 || true

wait_venvs
step "waiting for the venvs"

bash scripts/build-python.sh   # the scaledp_data wheel, reusing that build
step "scaledp_data wheel"

# cargo-machete's install uses what the tests leave (they wait on child processes and sockets
# much of the time: a fresh clone's ran at 1.4 of the 2 cores), niced so that the rate-bound
# tests keep their cores. It builds in its own target dir, and with plain rustc: `cargo install`
# counts the crate it installs as the workspace, which the clippy wrapper would lint.
nice -n 19 env -u RUSTC_WORKSPACE_WRAPPER -u CLIPPY_ARGS \
  bash scripts/check-deps.sh --install-only > target/check-deps.log 2>&1 &
machete_pid=$!
# The Python processes the tests start (simulators, LeRobot, torch) cache their bytecode in
# target/pycache, so that only the first compiles each module: the venvs are installed without
# it, and a CI image may set PYTHONDONTWRITEBYTECODE.
unset PYTHONDONTWRITEBYTECODE
export PYTHONPYCACHEPREFIX="$PWD/target/pycache"
# --no-fail-fast: every test executable runs, so one failure does not hide the others'.
# The output goes to target/test.log and is followed from there: a pipe into tee would wait
# for every process holding its end, and a test's leaked descendant could hold it for ever.
test_rc=0
cargo test --release --workspace --locked --no-fail-fast > target/test.log 2>&1 &
cargo_pid=$!
tail -n +1 -f --pid="$cargo_pid" target/test.log &
tail_pid=$!
wait "$cargo_pid" || test_rc=$?
wait "$tail_pid" || true
step "cargo test"
# A CI log keeps the start and the end of the output and cuts the middle, where cargo lists
# why each test failed (stop 52's flake left only a name). So the failed tests' names and the
# first one's own output come again last: its first 4 lines (the panic) and its last 20 (a
# failed command's error), backtraces left out.
failed_output() {
  awk '
    /^---- .* (stdout|stderr) ----$/ {
      n++; keep = (n == 1); skip = 0
      name = $0; sub(/^---- /, "", name); sub(/ (stdout|stderr) ----$/, "", name)
      if (n <= 10) names = names "failed: " name "\n"
    }
    /^failures:$/ { keep = 0 }
    /^stack backtrace:$/ { skip = 1; next }
    /^note: Some details are omitted/ { skip = 0; next }
    keep && !skip { buf[++held] = substr($0, 1, 400) }
    END {
      printf "%s", names
      if (n > 10) print "(and " n - 10 " more)"
      for (i = 1; i <= held && i <= 4; i++) print buf[i]
      from = held - 19 > 5 ? held - 19 : 5
      if (from > 5) print "  [" from - 5 " lines left out: target/test.log]"
      for (i = from; i <= held; i++) print buf[i]
    }
  ' "$1"
}
if [ "$test_rc" -ne 0 ]; then
  echo "== the failed tests' own output (all of it: target/test.log) =="
  failed_output target/test.log
  echo "cargo test failed (exit $test_rc)"
  exit "$test_rc"
fi

wait "$machete_pid" || { cat target/check-deps.log; exit 1; }
env -u RUSTC_WORKSPACE_WRAPPER -u CLIPPY_ARGS bash scripts/check-deps.sh
step "unused dependencies"
