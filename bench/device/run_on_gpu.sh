#!/usr/bin/env bash
# Runs on the lent GPU machine (see pack.sh): points the carried OpenCL ICD loader at NVIDIA's
# OpenCL driver, runs every test binary (each OpenCL test runs on every device present, here the
# GPU) and the OpenCL benchmarks, and leaves logs and JSON in $OUT. STAGES (default
# "probe tests bench vulkan precond") chooses what runs, among: probe, tests, bench (bench_opencl; BENCH_FILTER
# narrows it), vulkan (bench_vulkan on the GPU, VULKAN_FILTER narrows it, and the renderer sample's
# frames on the GPU's own VkDevice), profile (bench_opencl --profile on the 10k and 1M steps), ab (the dynamic steps of
# the bench_opencl binaries named in AB, in turns), tuningab (bench_opencl under each tuning in
# TUNINGAB, in turns: space-separated --tuning values such as "groupPcg=0 groupPcg=1,workGroupSize=128";
# "-" for the defaults), sweep (work-group sizes), more (bench_backends,
# bench_embed, bench_batch), batch (bench_batch alone; BATCH_FILTER), meshorder (bench_mesh_order: real meshes in their files' numbering and
# in the device's Morton order), precond (bench_precond: issue 29's 12,960-tet beam with the diagonal and the
# multigrid, OpenCL and Vulkan in float; PRECOND_FILTER narrows it). The tests stage also runs five suites again with the Morton order
# forced on every body (the test binaries' --corofem_morton flag), as CTest does, at the same time; TEST_TIMEOUT and
# MORTON_TIMEOUT (seconds, 400 and TEST_TIMEOUT: they all run at once now) bound each binary, MORTON_SUITES (those five by
# default; "" for none) names the suites run again, TEST_SUITES (all by default) the suites run, and test_opencl runs in OPENCL_SHARDS
# (6) gtest shards in each numbering. vulkanab: bench_vulkan's steps under each VulkanTuning::groupPcgNodes in
# VULKANAB ("3000 -1": the 1k and 10k boxes in one dispatch, against a dispatch per phase; the default, 0, puts
# the 10k box's 2,100 nodes on the per-phase path), in turns. profile also profiles the multigrid's
# iteration (pcg_iteration_amg, 10k). vulkanstep: bench_vulkan's steps from the binaries in VULKANSTEP, in
# turns (see the stage). fusedab: bench_vulkan's iterations and steps with VulkanTuning::fusedPcg 0 and 1
# in turns (FUSEDAB_FILTER, FUSEDAB_ROUNDS). storeab: bench_vulkan's steps with VulkanTuning::deviceStore 0
# (the host's vectors) and 1 (the device's) in turns (STOREAB_FILTER, STOREAB_ROUNDS). Call it as `bash bench/device/run_on_gpu.sh 2>&1` with nothing after it:
# the device tool gives back nothing of a pipeline it kills at the call's limit (a `| grep` lost a whole call).
set -uo pipefail
root=$(pwd)
g=$root/.gpu
if [[ -f $g/pack.tar.xz ]]; then tar -C "$g" -xJf "$g/pack.tar.xz" && rm -f "$g/pack.tar.xz"; fi  # pack.sh's archive
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT" /tmp/logs
stages=${STAGES:-probe tests bench vulkan precond}
has() { [[ " $stages " == *" $1 "* ]]; }
export LD_LIBRARY_PATH=$g/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
export COROFEM_DATA_DIR=$g/data COROFEM_CACHE_DIR=/tmp/corofem-cache  # built kernels (and calibrations) there
# The test binaries know the project as /work/main and the data as ../shared/data beside it.
if [[ $root != /work/main ]] && { [[ ! -e /work/main ]] || [[ -L /work/main ]]; }; then mkdir -p /work; ln -sfn "$root" /work/main; fi
[[ -e /work/shared ]] || ln -sfn "$g" /work/shared
# The CLI tests run the command where the build put it.
[[ -x $root/build/corofem ]] || { mkdir -p "$root/build" && cp "$g/bin/corofem" "$root/build/corofem"; }
for f in "$g"/lib/libcorofem_c.so.*; do [[ -e $root/build/$(basename "$f") ]] || cp "$f" "$root/build/"; done
icd=$(find /usr/local/nvidia /usr/lib /usr/lib64 /usr/local/cuda* -name 'libnvidia-opencl.so.1' 2>/dev/null | head -1)
mkdir -p /tmp/icd && echo "${icd:-libnvidia-opencl.so.1}" > /tmp/icd/nvidia.icd
export OCL_ICD_VENDORS=/tmp/icd OCL_ICD_FILENAMES=${icd:-libnvidia-opencl.so.1}
# NVIDIA's Vulkan driver, for the carried loader (the device tool's README: where the image keeps it).
vkicd=$(find /usr/local/nvidia /usr/share/vulkan /etc/vulkan -name 'nvidia_icd*.json' 2>/dev/null | head -1)
[[ -n $vkicd ]] && export VK_DRIVER_FILES=$vkicd VK_ICD_FILENAMES=$vkicd

if has probe; then
  {
    nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.sm,clocks.mem --format=csv
    grep PRETTY /etc/os-release; ldd --version | head -1; nproc
    echo "NVIDIA OpenCL driver: ${icd:-not found}"
    ls /etc/OpenCL/vendors 2>&1
    echo "NVIDIA Vulkan driver: ${vkicd:-not found}"
    VK_LOADER_DEBUG=error,warn,driver "$g/bin/bench_vulkan" --benchmark_list_tests=true 2>&1 | grep -v "^Searching\|^   " | head -30 || true
    "$g/bin/bench_opencl" --benchmark_list_tests=true 2>&1 | grep -E "dynamic_step_10k|device" || true
  } 2>&1 | tee "$OUT/probe.log"
fi

if has tests; then  # every suite and the Morton reruns at once (16 cores; the GPU is shared by all)
  # test_opencl, the longest (over 230 s on an H200 machine with the others beside it, 2026-11-26),
  # runs in OPENCL_SHARDS gtest shards in each numbering (tests' temporary folders are per process).
  shards=${OPENCL_SHARDS:-6}
  rm -rf /tmp/logs && mkdir -p /tmp/logs  # a warm machine's earlier run must not mix in
  pids=()
  run_one() {  # log name, extra flag of the test binary (or ""), timeout, binary, shard index or ""
    local log=$1 flag=$2 limit=$3 bin=$4 shard=$5
    (cd "$root" || exit 1; if [[ -n $shard ]]; then export GTEST_TOTAL_SHARDS=$shards GTEST_SHARD_INDEX=$shard; fi
     timeout "$limit" "$bin" --gtest_brief=1 ${flag:+"$flag"} > "/tmp/logs/$log.log" 2>&1; echo "$log exit $?" >> /tmp/logs/exits) &
    pids+=($!)
  }
  for t in "$g"/bin/test_*; do
    n=$(basename "$t")
    [[ -z ${TEST_SUITES:-} || " $TEST_SUITES " == *" $n "* ]] || continue
    if [[ $n == test_opencl ]]; then
      for ((k = 0; k < shards; ++k)); do run_one "${n}_$k" "" "${TEST_TIMEOUT:-400}" "$t" $k; done
    else
      run_one "$n" "" "${TEST_TIMEOUT:-400}" "$t" ""
    fi
  done
  for n in ${MORTON_SUITES-test_batch test_embed test_opencl test_solve test_schedule}; do
    [[ -x $g/bin/$n ]] || continue
    if [[ $n == test_opencl ]]; then
      for ((k = 0; k < shards; ++k)); do run_one "morton_${n}_$k" --corofem_morton "${MORTON_TIMEOUT:-${TEST_TIMEOUT:-400}}" "$g/bin/$n" $k; done
    else
      run_one "morton_$n" --corofem_morton "${MORTON_TIMEOUT:-${TEST_TIMEOUT:-400}}" "$g/bin/$n" ""
    fi
  done
  wait "${pids[@]}"
  echo "tests took $SECONDS s since the script began"
  sort /tmp/logs/exits
  logs=(/tmp/logs/test_*.log); [[ -n $(compgen -G '/tmp/logs/morton_*.log') ]] && logs+=(/tmp/logs/morton_*.log)
  for f in "${logs[@]}"; do echo "$(basename $f): $(grep -E '^\[  (PASSED|SKIPPED) ' $f | tr '\n' ' ')"; done
  grep -h -E '^\[  FAILED  \]' "${logs[@]}" | head -40
fi

B=$g/bin
if has bench; then
  timeout 420 "$B/bench_opencl" --benchmark_filter="${BENCH_FILTER:-dev0}" \
    --benchmark_out="$OUT/bench_opencl.json" --benchmark_out_format=json > /tmp/logs/bench_opencl.txt 2>&1
  echo "bench_opencl exit $?"
  grep -E 'median' /tmp/logs/bench_opencl.txt | cut -c1-160
fi

if has profile; then  # per kernel: launches, device time, device idle before it
  for size in 10k 1M amg; do
    f="dynamic_step_20pcg/dev0/$size"; [[ $size == amg ]] && f="pcg_iteration_amg/dev0/10k"
    timeout 120 "$B/bench_opencl" --profile --benchmark_filter="$f" \
      --benchmark_repetitions=1 --benchmark_min_time=1 2>&1 | grep -E '^\[profile|median' > "/tmp/logs/profile_$size.txt"
    echo "== profile $size"; cat "/tmp/logs/profile_$size.txt" | cut -c25-160
  done
fi

if has ab; then  # A/B: the binaries named in AB (in .gpu/bin), in turns, twice
  for round in 1 2; do
    for b in ${AB:-bench_opencl}; do
      timeout 150 "$B/$b" --benchmark_filter='dynamic_step' --benchmark_repetitions=3 \
        --benchmark_report_aggregates_only=true 2>/dev/null | grep median | awk -v b=$b '{print b, $1, $2, $3, "cpu", $4, $5}'
    done
  done | tee /tmp/logs/ab.txt
fi

if has tuningab; then  # A/B of OpenCLTuning settings (TUNINGAB, e.g. "- groupPcg=0"), in turns
  for round in $(seq "${TUNINGAB_ROUNDS:-2}"); do
    for v in ${TUNINGAB:--}; do
      t=(); [[ $v != - ]] && t=("--tuning=$v")
      timeout 150 "$B/bench_opencl" "${t[@]}" --benchmark_filter="${TUNINGAB_FILTER:-dynamic_step|pcg_iteration/dev0/(1k|10k|1M)}" \
        --benchmark_repetitions=3 --benchmark_report_aggregates_only=true 2>/dev/null | grep median | awk -v b=$v '{print b, $1, $2, $3}'
    done
  done | tee /tmp/logs/tuningab.txt
fi

if has sweep; then  # work-group sizes on the GPU
  for wg in 64 128 256; do
    timeout 120 "$B/bench_opencl" --tuning=workGroupSize=$wg --benchmark_filter='(product|pcg_iteration|rotation_polar|internal_force)/dev0/(10k|1M)|dynamic_step_20pcg/dev0/(10k|1M)' \
      --benchmark_repetitions=3 --benchmark_report_aggregates_only=true 2>/dev/null | grep median | awk -v wg=$wg '{print "wg" wg, $1, $2, $3}'
  done | tee /tmp/logs/sweep.txt
fi

if has more; then
  timeout 240 "$B/bench_backends" --benchmark_repetitions=5 --benchmark_report_aggregates_only=true \
    --benchmark_out="$OUT/bench_backends.json" --benchmark_out_format=json > /tmp/logs/bench_backends.txt 2>&1
  echo "bench_backends exit $?"
  timeout 150 "$B/bench_embed" --benchmark_filter='DeviceSurface1M|DeviceSurfaceFromDevice1M' \
    --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
    --benchmark_out="$OUT/bench_embed.json" --benchmark_out_format=json > /tmp/logs/bench_embed.txt 2>&1
  echo "bench_embed exit $?"
  timeout 240 "$B/bench_batch" --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
    --benchmark_out="$OUT/bench_batch.json" --benchmark_out_format=json > /tmp/logs/bench_batch.txt 2>&1
  echo "bench_batch exit $?"
  grep -h median /tmp/logs/bench_backends.txt /tmp/logs/bench_embed.txt /tmp/logs/bench_batch.txt | cut -c1-150
fi
if has batch; then  # bench_batch alone (the 100 bodies batched and separate)
  timeout 200 "$B/bench_batch" --benchmark_filter="${BATCH_FILTER:-HundredBodies/}" --benchmark_repetitions=3 \
    --benchmark_report_aggregates_only=true --benchmark_out="$OUT/bench_batch.json" --benchmark_out_format=json \
    > /tmp/logs/bench_batch.txt 2>&1
  echo "bench_batch exit $?"
  grep -h -E 'median|ratio' /tmp/logs/bench_batch.txt | cut -c1-200
fi
if has meshorder; then
  (cd "$root" && timeout 300 "$B/bench_mesh_order" --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
    --benchmark_out="$OUT/bench_mesh_order.json" --benchmark_out_format=json > /tmp/logs/bench_mesh_order.txt 2>&1)
  echo "bench_mesh_order exit $?"
  grep -h median /tmp/logs/bench_mesh_order.txt | cut -c1-150
fi
if has vulkan; then  # the Vulkan backend on the GPU: its benchmark, then the renderer sample's frames
  timeout 300 "$B/bench_vulkan" --benchmark_filter="${VULKAN_FILTER:-.}" --benchmark_repetitions=3 \
    --benchmark_report_aggregates_only=true --benchmark_out="$OUT/bench_vulkan.json" --benchmark_out_format=json \
    > /tmp/logs/bench_vulkan.txt 2>&1
  echo "bench_vulkan exit $?"
  grep -h median /tmp/logs/bench_vulkan.txt | cut -c1-200
  if [[ -x $B/renderer ]]; then
    (cd "$root" && timeout 120 "$B/renderer" --out "$OUT/renderer" --png-every 40 > /tmp/logs/renderer.txt 2>&1)
    echo "renderer exit $?"; cat /tmp/logs/renderer.txt
  fi
fi
if has vulkanab; then  # Vulkan PCG paths in turns: bench_vulkan's steps under each groupPcgNodes in VULKANAB
  for round in $(seq "${VULKANAB_ROUNDS:-2}"); do
    for v in ${VULKANAB:-3000 -1}; do
      timeout 200 "$B/bench_vulkan" --group_pcg_nodes="$v" --benchmark_filter="${VULKANAB_FILTER:-^step/0/(1k|10k)/}" \
        --benchmark_repetitions=3 --benchmark_report_aggregates_only=true 2>/dev/null | grep median | \
        awk -v g="$v" '{print "group_pcg_nodes=" g, $1, $2, $3, $4, $5}'
    done
  done | tee /tmp/logs/vulkanab.txt
fi
if has vulkanstep; then  # bench_vulkan's whole steps from several binaries (an A/B of two commits), in turns
  # VULKANSTEP: space-separated binary[:groupPcgNodes] (binaries in .gpu/bin, e.g. a bench_vulkan_old
  # built at the commit before), VULKANSTEP_FILTER the sizes; VULKANSTEP_ROUNDS rounds (2).
  for round in $(seq "${VULKANSTEP_ROUNDS:-2}"); do
    for e in ${VULKANSTEP:-bench_vulkan}; do
      b=${e%%:*}; g=${e#*:}; [[ $g == "$e" ]] && g=0
      timeout 200 "$B/$b" --group_pcg_nodes="$g" --benchmark_filter="${VULKANSTEP_FILTER:-^step/0/}" \
        --benchmark_repetitions=3 --benchmark_report_aggregates_only=true 2>/dev/null | grep median | \
        awk -v r="$round" -v e="$e" '{print "round " r, e, $1, $2, $3, $4, $5, $9, $10}'
    done
  done | tee /tmp/logs/vulkanstep.txt
fi
# bench_vulkan's medians with a VulkanTuning flag at 0 and at 1, in turns: ab <flag> <filter> <rounds>
ab() {
  for round in $(seq "$3"); do
    for v in 0 1; do
      timeout 200 "$B/bench_vulkan" "--$1=$v" --benchmark_filter="$2" \
        --benchmark_repetitions=3 --benchmark_report_aggregates_only=true 2>/dev/null | grep median | \
        awk -v r="$round" -v f="$1=$v" '{print "round " r, f, $1, $2, $3, $4, $5, $7, $9, $10}'
    done
  done
}
if has fusedab; then  # VulkanTuning::fusedPcg in turns: an iteration in four dispatches (0) against two (1)
  ab fused_pcg "${FUSEDAB_FILTER:-^(pcg_iterations|step)/0/}" "${FUSEDAB_ROUNDS:-2}" | tee /tmp/logs/fusedab.txt
fi
if has storeab; then  # VulkanTuning::deviceStore in turns: the dynamics' vectors on the host (0) or the device (1)
  ab device_store "${STOREAB_FILTER:-^step/0/}" "${STOREAB_ROUNDS:-2}" | tee /tmp/logs/storeab.txt
fi
if has precond; then  # the preconditioners per converged step on the GPU (issue 29's beam, both APIs)
  (cd "$root" && timeout 240 "$B/bench_precond" \
    --benchmark_filter="${PRECOND_FILTER:-precondStep/(opencl|vulkan)_float/(diagonal|amg)/}" \
    --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
    --benchmark_out="$OUT/bench_precond.json" --benchmark_out_format=json > /tmp/logs/bench_precond.txt 2>&1)
  echo "bench_precond exit $?"
  grep -h median /tmp/logs/bench_precond.txt | cut -c1-200
fi
tar -C /tmp -czf "$OUT/logs.tar.gz" logs
