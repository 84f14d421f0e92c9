#!/usr/bin/env bash
# A body on the PoCL CPU device sharing its cores with a busy process (bench/bench_contention.cpp):
# the library's default and PoCL limited to one thread (POCL_MAX_PTHREAD_COUNT=1), each quiet and
# with a process spinning on CPU 0, in turns, ROUNDS times. Prints the median step time of every
# configuration (the median over the rounds of each run's median) and whether the default with a
# busy core is no slower than PoCL on one thread with it (exit 1 if it is slower).
#
#   bench/contention.sh [build folder, default build] [output folder, default /tmp/corofem-contention]
#   ROUNDS=3 by default; PRECONDITIONER=name (auto, the library's default, unless given).
set -euo pipefail
build=${1:-build}
out=${2:-/tmp/corofem-contention}
rounds=${ROUNDS:-3}
bin=$build/bench/bench_contention
[ -x "$bin" ] || { echo "contention.sh: $bin is not built (cmake --build $build --target bench_contention)" >&2; exit 2; }
mkdir -p "$out"
configs=(default_quiet default_busy onethread_quiet onethread_busy)
for ((r = 1; r <= rounds; ++r)); do
  for c in "${configs[@]}"; do
    env=()
    args=(--benchmark_format=json --benchmark_out_format=json --benchmark_out="$out/${c}_round$r.json"
          --preconditioner="${PRECONDITIONER:-auto}")
    [[ $c == onethread_* ]] && env=(POCL_MAX_PTHREAD_COUNT=1)
    [[ $c == *_busy ]] && args+=(--busy_cpu=0)
    env "${env[@]}" "$bin" "${args[@]}" > /dev/null
    echo "round $r: $c done" >&2
  done
done
/usr/bin/python3 - "$out" "$rounds" <<'EOF'
import json, statistics, sys
out, rounds = sys.argv[1], int(sys.argv[2])
med = {}
for c in ["default_quiet", "default_busy", "onethread_quiet", "onethread_busy"]:
    runs = []
    for r in range(1, rounds + 1):
        b = json.load(open(f"{out}/{c}_round{r}.json"))["benchmarks"][0]
        if b.get("error_occurred"):
            sys.exit(f"{c} round {r}: {b.get('error_message')}")
        runs.append(b["median_ms_per_step"])
    med[c] = statistics.median(runs)
    print(f"{c:16s} median step {med[c]:7.1f} ms   (rounds: {', '.join(f'{v:.1f}' for v in runs)})")
ratio = med["default_busy"] / med["onethread_busy"]
print(f"with a busy core: default / PoCL on one thread = {ratio:.2f}")
sys.exit(0 if ratio <= 1.0 else 1)
EOF
