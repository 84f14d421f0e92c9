#!/usr/bin/env bash
# Configures and builds corofem in ./build (Release, OpenCL backend on: PoCL runs it on the CPU).
# Usage: cmake/configure-build.sh [extra cmake --build arguments, e.g. --target corofem_cli]
set -euo pipefail
cd "$(dirname "$0")/.."
launcher=()
if command -v ccache >/dev/null 2>&1; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
cmake --preset opencl "${launcher[@]}" >/dev/null
cmake --build build -j"$(nproc)" "$@"
