#!/usr/bin/env bash
# Builds `scaledp` with candle's CUDA backend (`--features scaledp-policy/cuda`) on a machine with
# neither a GPU nor a CUDA install: nvcc, the CUDA headers and the libraries to link against come
# from NVIDIA's wheels on PyPI in target/cuda-sdk (CUDA 13.0: the CUDA 12 nvcc wheels hold ptxas
# but no nvcc driver; CUDA 13 needs an NVIDIA driver >= 580 on the GPU machine); the
# driver library, which only a GPU machine has, is replaced at link time by a stub exporting the
# driver API cudarc calls (the real libcuda.so.1 is loaded on the GPU machine at run time). The
# kernels are compiled for CUDA_COMPUTE_CAP (default 80: A100; 90 for H100), into their own
# target dir (CARGO_TARGET_DIR, default target/cuda) so the CPU build is untouched.
#
#   bash scripts/build-cuda.sh            # -> target/cuda/release/scaledp
#
# Run the result where the NVIDIA driver is installed, with the wheels' libraries on the path:
#   LD_LIBRARY_PATH=target/cuda-sdk/lib target/cuda/release/scaledp train DATASET --device cuda ...
set -euo pipefail
cd "$(dirname "$0")/.."
export CUDA_COMPUTE_CAP=${CUDA_COMPUTE_CAP:-80}
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-target/cuda}
SDK=$PWD/target/cuda-sdk
PY=${PYTHON:-python3}
CUDA_WHEELS=(nvidia-cuda-nvcc==13.0.88 nvidia-cuda-crt==13.0.88 nvidia-nvvm==13.0.88
  nvidia-cuda-runtime==13.0.96 nvidia-cuda-nvrtc==13.0.88 nvidia-cublas==13.0.2.14
  nvidia-curand==10.4.0.35 nvidia-cuda-cccl==13.0.85)

[ -x "$SDK/venv/bin/python" ] || "$PY" -m venv "$SDK/venv"
"$SDK/venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps "${CUDA_WHEELS[@]}"
CU=$("$SDK/venv/bin/python" -c 'import nvidia; print(nvidia.__path__[0])')/cu13

# A CUDA_HOME-shaped tree: nvcc, every wheel's headers, unversioned names of the libraries.
rm -rf "${SDK:?}/include" "${SDK:?}/lib" && mkdir -p "$SDK/include" "$SDK/lib"
cp -rs "$CU/include"/. "$SDK/include/"
for so in "$CU"/lib/lib*.so.*; do
  base=$(basename "$so")
  ln -sf "$so" "$SDK/lib/$base"
  ln -sf "$so" "$SDK/lib/${base%%.so.*}.so"
done

# The driver stub: every cu* function cudarc's driver bindings declare, as an empty symbol.
cargo fetch --locked --quiet
CUDARC=$(sed -n '/^name = "cudarc"/{n;s/version = "\(.*\)"/\1/p}' Cargo.lock | head -n 1)
SYS=$(ls -d "${CARGO_HOME:-$HOME/.cargo}"/registry/src/*/"cudarc-$CUDARC"/src/driver/sys | head -n 1)
grep -A2 'extern "C" {' "$SYS/mod.rs" | grep -o 'fn cu[A-Za-z0-9_]*' | sed 's/^fn //' | sort -u \
  | sed 's/.*/void &(void) {}/' > "$SDK/cuda_stub.c"
cc -shared -fPIC -Wl,-soname,libcuda.so.1 -o "$SDK/lib/libcuda.so" "$SDK/cuda_stub.c"
echo "driver stub: $(wc -l < "$SDK/cuda_stub.c") symbols of cudarc $CUDARC"

export CUDA_HOME=$SDK CUDA_PATH=$SDK
export PATH="$CU/bin:$PATH"
# CUDA 13 keeps libcu++ (<nv/target>, which cuda_fp16.h includes) under include/cccl.
export NVCC_APPEND_FLAGS="-I$SDK/include -isystem $SDK/include/cccl"
export LIBRARY_PATH="$SDK/lib${LIBRARY_PATH:+:$LIBRARY_PATH}"
nvcc --version | tail -n 2
start=$(date +%s)
cargo build --release --locked --workspace --bins --features scaledp-policy/cuda
echo "built $CARGO_TARGET_DIR/release/scaledp with CUDA (compute capability $CUDA_COMPUTE_CAP) in $(( $(date +%s) - start )) s"
