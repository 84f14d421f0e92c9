#!/usr/bin/env bash
# Installs what is missing, builds everything once (library, command, tests, benchmarks; OpenCL
# backend on, run by PoCL on the CPU) and runs the whole test suite through CTest in parallel; then
# the sanitizer job (tests/sanitize.sh: the debug preset, AddressSanitizer + UBSan, on the mesh,
# scene, cli and solve tests) and a short run of every fuzz target (tests/fuzz/run_fuzz.sh, 10 s
# each). All three run; the script fails when any of them does. See docs/reliability.md.
set -euo pipefail
cd "$(dirname "$0")/.."
bash cmake/debian-deps.sh

failed=()
stage() {  # name command...
  local name=$1 start=$SECONDS
  shift
  if "$@"; then
    echo "run_all.sh: $name passed in $((SECONDS - start)) s"
  else
    echo "run_all.sh: $name FAILED after $((SECONDS - start)) s" >&2
    failed+=("$name")
  fi
}
suite() {  # (in an `if`, set -e does not stop a function: hence &&)
  bash cmake/configure-build.sh && ctest --test-dir build -j"$(nproc)" --output-on-failure --timeout 900
}
stage "build and test suite" suite
stage "sanitizer job" bash tests/sanitize.sh
stage "fuzz targets" bash tests/fuzz/run_fuzz.sh --seconds 10
echo "run_all.sh: total $SECONDS s"
if ((${#failed[@]})); then
  echo "run_all.sh: failed: ${failed[*]}" >&2
  exit 1
fi
