#!/usr/bin/env bash
# Installs what is missing, builds everything once (library, command, tests, benchmarks; OpenCL
# backend on, run by PoCL on the CPU) and runs the whole test suite through CTest in parallel.
set -euo pipefail
cd "$(dirname "$0")/.."
bash cmake/debian-deps.sh
bash cmake/configure-build.sh
ctest --test-dir build -j"$(nproc)" --output-on-failure --timeout 900
