#!/usr/bin/env bash
# Builds the libFuzzer targets (clang-14, AddressSanitizer + UndefinedBehaviorSanitizer) in
# ./build-fuzz and runs each for a bounded time, as many side by side as there are cores. Fails
# (exit 1) when a target finds a crash, a leak, a timeout, an out-of-memory or a violated
# invariant; the input that did it is saved under build-fuzz/artifacts/<target>/ and the log under
# build-fuzz/logs/<target>.log.
#
#   tests/fuzz/run_fuzz.sh                      # every target, 10 s each (what CI runs)
#   tests/fuzz/run_fuzz.sh --seconds 600        # the long run: 10 minutes per target
#   tests/fuzz/run_fuzz.sh --seconds 60 --targets "scene gmsh"
#   tests/fuzz/run_fuzz.sh --build-only
#
# The corpus of each target grows in build-fuzz/corpus/<target>/ from run to run; every run first
# adds the seeds committed in tests/fuzz/corpus/<target>/ and, when ../shared/data/meshes (or
# $COROFEM_DATA_DIR/meshes) is there, the shared meshes of the target's format up to 128 KiB.
# Reproduce a finding with: build-fuzz/fuzz_<target> build-fuzz/artifacts/<target>/crash-...
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)

seconds=10
targets="gmsh medit vtk veg tetgen obj scene capi_scene"
build_only=0
while (($#)); do
  case "$1" in
    --seconds) seconds="$2"; shift 2 ;;
    --seconds=*) seconds="${1#*=}"; shift ;;
    --targets) targets="$2"; shift 2 ;;
    --targets=*) targets="${1#*=}"; shift ;;
    --build-only) build_only=1; shift ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    *) echo "run_fuzz.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
if ! [[ "$seconds" =~ ^[0-9]+$ ]] || ((seconds < 1)); then
  echo "run_fuzz.sh: --seconds needs a whole number >= 1, got '$seconds'" >&2
  exit 2
fi

compiler=$(command -v clang++-14 || command -v clang++ || true)
if [[ -z "$compiler" ]]; then
  echo "run_fuzz.sh: clang++ is missing; install clang-14 and libclang-rt-14-dev (cmake/debian-deps.sh)" >&2
  exit 1
fi
build=build-fuzz
launcher=()
if command -v ccache >/dev/null 2>&1; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
cmake -S tests/fuzz -B "$build" -DCMAKE_CXX_COMPILER="$compiler" "${launcher[@]}" >/dev/null
cmake --build "$build" -j"$(nproc)" >/dev/null
echo "run_fuzz.sh: built the fuzz targets in $build"
((build_only)) && exit 0

data="${COROFEM_DATA_DIR:-$root/../shared/data}/meshes"

# Shared meshes of a target's format (up to 128 KiB: larger ones only slow each run down).
add_shared_seeds() {  # target corpus-dir
  local target=$1 dir=$2 pattern f
  [[ -d "$data" ]] || return 0
  case "$target" in
    gmsh) pattern='*.msh' ;; medit) pattern='*.mesh' ;; vtk) pattern='*.vtk' ;; veg) pattern='*.veg' ;;
    obj) pattern='*.obj' ;;
    tetgen)
      # One input per .node/.ele pair: the .node text, the line "@@ele@@", the .ele text.
      while IFS= read -r -d '' f; do
        local ele="${f%.node}.ele"
        [[ -f "$ele" ]] || continue
        (($(stat -c %s "$f") + $(stat -c %s "$ele") <= 131072)) || continue
        { cat "$f"; printf '\n@@ele@@\n'; cat "$ele"; } > "$dir/shared-$(basename "${f%.node}")"
      done < <(find "$data" -name '*.node' -print0)
      return 0 ;;
    *) return 0 ;;
  esac
  while IFS= read -r -d '' f; do
    cp "$f" "$dir/shared-$(basename "$(dirname "$f")")-$(basename "$f")"
  done < <(find "$data" -name "$pattern" -size -129k -print0)
}

max_len_of() {
  case "$1" in scene | capi_scene) echo 8192 ;; *) echo 65536 ;; esac
}

# One target's run; its summary line and exit status go to build-fuzz/logs/<target>.{summary,status}.
run_target() {  # target
  local target=$1
  local corpus="$build/corpus/$target" artifacts="$build/artifacts/$target" log="$build/logs/$target.log"
  local status=0 execs cov
  # -timeout: one input running 10 s is a hang; -rss_limit_mb: 2 GiB is an out-of-memory.
  timeout $((seconds + 120)) "$build/fuzz_$target" "$corpus" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
    -max_len="$(max_len_of "$target")" -dict=tests/fuzz/dict/"$target".dict -artifact_prefix="$artifacts/" \
    -print_final_stats=1 >"$log" 2>&1 || status=$?
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  cov=$(grep -oE 'cov: [0-9]+ ft: [0-9]+' "$log" | tail -1 || true)
  printf '%-7s %10s execs  %-22s  %s\n' "$target" "${execs:-?}" "${cov:-cov: ?}" \
    "$( ((status == 0)) && echo ok || echo "FAILED (exit $status)")" >"$build/logs/$target.summary"
  echo "$status" >"$build/logs/$target.status"
}

# Every name checked (and each taken once) before any target starts.
unique=""
for target in $targets; do
  if [[ ! -x "$build/fuzz_$target" ]]; then
    echo "run_fuzz.sh: no target '$target' (targets: gmsh medit vtk veg tetgen obj scene capi_scene)" >&2
    exit 2
  fi
  [[ " $unique " == *" $target "* ]] || unique+="${unique:+ }$target"
done
targets=$unique

# The targets run side by side, as many at a time as there are cores (each libFuzzer run is one
# thread): each still fuzzes for `seconds`, the whole in about 1/nproc of the time. A run stopped
# or failed part way stops the targets still running.
trap 'kill $(jobs -p) 2>/dev/null || true' EXIT INT TERM
jobs=$(nproc)
for target in $targets; do
  corpus="$build/corpus/$target"
  mkdir -p "$corpus" "$build/artifacts/$target" "$build/logs"
  rm -f "$build/logs/$target.summary" "$build/logs/$target.status"
  cp tests/fuzz/corpus/"$target"/* "$corpus"/
  add_shared_seeds "$target" "$corpus"
  if [[ "$target" == scene || "$target" == capi_scene ]]; then
    for f in samples/*/*.json docs/examples/*.json; do [[ -f "$f" ]] && cp "$f" "$corpus/repo-$(basename "$f")"; done
  fi
  while (($(jobs -rp | wc -l) >= jobs)); do wait -n || true; done
  echo "run_fuzz.sh: fuzz_$target for $seconds s ($(ls "$corpus" | wc -l) inputs in its corpus)"
  run_target "$target" &
done
wait || true

failed=()
summary=()
for target in $targets; do
  status=$(cat "$build/logs/$target.status" 2>/dev/null || echo "no status")
  summary+=("$(cat "$build/logs/$target.summary" 2>/dev/null || echo "$target: no summary")")
  if [[ "$status" != 0 ]]; then
    failed+=("$target")
    echo "run_fuzz.sh: fuzz_$target FAILED (exit $status); the end of $build/logs/$target.log:" >&2
    tail -40 "$build/logs/$target.log" >&2 || true
    ls -1 "$build/artifacts/$target" >&2 || true
  fi
done

echo "run_fuzz.sh: summary ($seconds s per target)"
printf '  %s\n' "${summary[@]}"
if ((${#failed[@]})); then
  echo "run_fuzz.sh: findings in: ${failed[*]} (inputs in $build/artifacts/<target>/)" >&2
  exit 1
fi
