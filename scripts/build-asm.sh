#!/usr/bin/env bash
# The release build with the video codecs' hand-written SIMD assembly: rav1d (AV1 decoding in
# the loader, 3.7x faster), rav1e (AV1 encoding in `convert --video av1`) and openh264 (whose
# build script uses nasm whenever it finds one). They need nasm >= 2.14 at build time: this
# script installs Debian's package when nasm is missing and it may (root, or sudo without a
# password), else it stops and says so. Everything else is the plain build's; without this,
# `cargo build --release` works anywhere, only slower on video.
#
#   bash scripts/build-asm.sh [extra cargo build arguments]
#
# The binary is target/release/scaledp as usual. Building without the feature afterwards (e.g.
# `cargo run --release --bin scaledp -- demo`) recompiles the codec crates and what depends on
# them, and the other way round.
set -euo pipefail
cd "$(dirname "$0")/.."

have_nasm() {
  command -v nasm >/dev/null 2>&1 || return 1
  local v
  v=$(nasm -v | sed -n 's/^NASM version \([0-9]*\)\.\([0-9]*\).*/\1 \2/p')
  read -r major minor <<<"$v"
  [ "${major:-0}" -gt 2 ] || { [ "${major:-0}" -eq 2 ] && [ "${minor:-0}" -ge 14 ]; }
}

if ! have_nasm; then
  if [ "$(id -u)" -eq 0 ]; then
    sudo=()
  elif sudo -n true 2>/dev/null; then
    sudo=(sudo -n)
  else
    echo "build-asm.sh: nasm >= 2.14 is needed and cannot be installed without root; install it (apt-get install nasm) or use plain 'cargo build --release'" >&2
    exit 1
  fi
  if ! command -v apt-get >/dev/null 2>&1; then
    echo "build-asm.sh: nasm >= 2.14 is needed and this system has no apt-get; install nasm with its package manager" >&2
    exit 1
  fi
  echo "build-asm.sh: installing nasm (Debian package)" >&2
  timeout 300 "${sudo[@]}" apt-get install -y -qq nasm >/dev/null 2>&1 ||
    { timeout 300 "${sudo[@]}" apt-get update -qq && timeout 300 "${sudo[@]}" apt-get install -y -qq nasm; }
  have_nasm || { echo "build-asm.sh: nasm still missing or older than 2.14 after apt-get" >&2; exit 1; }
fi

exec cargo build --release --workspace --locked --features scaledp-codec/asm "$@"
