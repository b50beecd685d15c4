#!/usr/bin/env bash
# Builds the Python module scaledp_data (python/) into a wheel in target/wheels with maturin, in
# the workspace's target dir and release profile: with the feature unify-with-workspace the
# module resolves dependency features exactly as `cargo build --workspace` does, so after that
# build only pyo3, numpy and the module itself compile here. Also puts the numpy wheel in
# target/wheels/deps, so tests install the module into a fresh venv offline.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || bash scripts/setup-python.sh
PIP=(.venv/bin/python -m pip --disable-pip-version-check)
"${PIP[@]}" install --quiet maturin==1.16.0
rm -f target/wheels/scaledp_data-*.whl
.venv/bin/maturin build --quiet --release --strip --locked --features unify-with-workspace \
  --manifest-path python/Cargo.toml --interpreter .venv/bin/python --out target/wheels
NUMPY=$(.venv/bin/python -c 'import numpy; print(numpy.__version__)')
"${PIP[@]}" download --quiet --only-binary=:all: --dest target/wheels/deps "numpy==$NUMPY"
ls target/wheels/scaledp_data-*.whl
