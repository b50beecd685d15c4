#!/usr/bin/env bash
# Fails when a crate lists a dependency it never uses (cargo-machete, pinned, installed once
# into .tools/, where `--install-only` stops; a dependency kept on purpose is listed, with the
# reason, under [package.metadata.cargo-machete] in its Cargo.toml).
set -euo pipefail
cd "$(dirname "$0")/.."
MACHETE_VERSION=0.9.2
if ! .tools/bin/cargo-machete --version 2>/dev/null | grep -q "$MACHETE_VERSION"; then
  # Its own target dir: never the workspace's, whose lock a `cargo test` beside it holds.
  cargo install --quiet --locked --root .tools --target-dir target/cargo-machete-build \
    cargo-machete --version "$MACHETE_VERSION"
fi
# --install-only: scripts/test.sh installs it beside the tests, then checks after them.
[ "${1:-}" = "--install-only" ] && exit 0
.tools/bin/cargo-machete
