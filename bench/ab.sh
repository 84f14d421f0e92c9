#!/usr/bin/env bash
# A/B of one benchmark binary from two builds (e.g. the commit before a change and after it), run
# in turns ROUNDS times on the same machine, so that both see the same noise. Prints, per benchmark
# and counter, the median over the rounds for A and B and the ratio B / A.
#
#   bench/ab.sh <build A> <build B> <binary> [benchmark filter] [counter ...]
#   e.g. bench/ab.sh /tmp/before/build build bench_opencl '^dynamic_step' real_time
#        bench/ab.sh /tmp/before/build build bench_batch 'varied:1' ratio_batched_vs_separate
# Counters: "real_time" (the benchmark's time per iteration, in its unit) or any user counter; a
# binary that reports aggregates only contributes its median of each round;
# default real_time. ROUNDS=3, OUT=/tmp/corofem-ab. Extra arguments to both binaries: AB_ARGS.
set -euo pipefail
a=$1 b=$2 bin=$3 filter=${4:-.}
shift $(( $# < 4 ? $# : 4 ))
counters=("$@")
[ ${#counters[@]} -gt 0 ] || counters=(real_time)
rounds=${ROUNDS:-3}
out=${OUT:-/tmp/corofem-ab}
mkdir -p "$out"
for side in a b; do
  dir=$([ $side = a ] && echo "$a" || echo "$b")
  [ -x "$dir/bench/$bin" ] || { echo "ab.sh: $dir/bench/$bin is not built" >&2; exit 2; }
done
for ((r = 1; r <= rounds; ++r)); do
  for side in a b; do
    dir=$([ $side = a ] && echo "$a" || echo "$b")
    # shellcheck disable=SC2086
    "$dir/bench/$bin" --benchmark_filter="$filter" --benchmark_out="$out/${bin}_${side}_$r.json" \
      --benchmark_out_format=json ${AB_ARGS:-} > /dev/null
    echo "round $r: $side done" >&2
  done
done
/usr/bin/python3 - "$out" "$bin" "$rounds" "${counters[@]}" <<'EOF'
import json, statistics, sys
out, binary, rounds, counters = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4:]
def values(side):
    v = {}
    for r in range(1, rounds + 1):
        for b in json.load(open(f"{out}/{binary}_{side}_{r}.json"))["benchmarks"]:
            # Each repetition, or the median where a binary reports aggregates only.
            if b.get("error_occurred") or (b.get("run_type") == "aggregate" and b.get("aggregate_name") != "median"):
                continue
            for c in counters:
                if c in b:
                    v.setdefault((b["run_name"] if "run_name" in b else b["name"], c), []).append(b[c])
    return v
A, B = values("a"), values("b")
print(f"{'benchmark':58s} {'counter':28s} {'A median':>11s} {'B median':>11s} {'B/A':>6s}")
for key in sorted(set(A) & set(B)):
    ma, mb = statistics.median(A[key]), statistics.median(B[key])
    print(f"{key[0][:58]:58s} {key[1][:28]:28s} {ma:11.4g} {mb:11.4g} {mb / ma if ma else float('nan'):6.3f}")
EOF
