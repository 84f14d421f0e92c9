#!/usr/bin/env bash
# Runs on the lent GPU machine (see pack.sh): points the carried OpenCL ICD loader at NVIDIA's
# OpenCL driver, runs every test binary (each OpenCL test runs on every device present, here the
# GPU) and the OpenCL benchmarks, and leaves logs and JSON in $OUT. STAGES (default
# "probe tests bench") chooses what runs; BENCH_FILTER narrows bench_opencl.
set -uo pipefail
root=$(pwd)
g=$root/.gpu
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT" /tmp/logs
stages=${STAGES:-probe tests bench}
export LD_LIBRARY_PATH=$g/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
export COROFEM_DATA_DIR=$g/data COROFEM_KERNEL_CACHE=/tmp/corofem-kernels
# The test binaries know the project as /work/main and the data as ../shared/data beside it.
if [[ $root != /work/main ]]; then mkdir -p /work; ln -sfn "$root" /work/main; fi
[[ -e /work/shared ]] || ln -sfn "$g" /work/shared
# The CLI tests run the command where the build put it.
[[ -x $root/build/corofem ]] || { mkdir -p "$root/build" && cp "$g/bin/corofem" "$root/build/corofem"; }
icd=$(find /usr/local/nvidia /usr/lib /usr/lib64 /usr/local/cuda* -name 'libnvidia-opencl.so.1' 2>/dev/null | head -1)
mkdir -p /tmp/icd && echo "${icd:-libnvidia-opencl.so.1}" > /tmp/icd/nvidia.icd
export OCL_ICD_VENDORS=/tmp/icd OCL_ICD_FILENAMES=${icd:-libnvidia-opencl.so.1}

if [[ $stages == *probe* ]]; then
  {
    nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.sm,clocks.mem --format=csv
    grep PRETTY /etc/os-release; ldd --version | head -1; nproc
    echo "NVIDIA OpenCL driver: ${icd:-not found}"
    ls /etc/OpenCL/vendors 2>&1
    "$g/bin/bench_opencl" --benchmark_list_tests=true 2>&1 | grep -E "dynamic_step_10k|device" || true
  } 2>&1 | tee "$OUT/probe.log"
fi

if [[ $stages == *tests* ]]; then
  pids=()
  for t in "$g"/bin/test_*; do
    n=$(basename "$t")
    (cd "$root" && timeout 400 "$t" --gtest_brief=1 > "/tmp/logs/$n.log" 2>&1; echo "$n exit $?" >> /tmp/logs/exits) &
    pids+=($!)
  done
  wait "${pids[@]}"
  sort /tmp/logs/exits
  grep -h -E '^\[  (FAILED|PASSED|SKIPPED) ' /tmp/logs/test_*.log | sort | uniq -c | sort -rn | head -60
fi

if [[ $stages == *bench* ]]; then
  B=$g/bin
  timeout 420 "$B/bench_opencl" --benchmark_filter="${BENCH_FILTER:-dev0}" \
    --benchmark_out="$OUT/bench_opencl.json" --benchmark_out_format=json > /tmp/logs/bench_opencl.txt 2>&1
  echo "bench_opencl exit $?"
  [[ $stages == *more* ]] && {
    timeout 300 "$B/bench_backends" --benchmark_repetitions=5 --benchmark_report_aggregates_only=true \
      --benchmark_out="$OUT/bench_backends.json" --benchmark_out_format=json > /tmp/logs/bench_backends.txt 2>&1
    timeout 200 "$B/bench_embed" --benchmark_filter='DeviceSurface1M|DeviceSurfaceFromDevice1M' \
      --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
      --benchmark_out="$OUT/bench_embed.json" --benchmark_out_format=json > /tmp/logs/bench_embed.txt 2>&1
    timeout 300 "$B/bench_batch" --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
      --benchmark_out="$OUT/bench_batch.json" --benchmark_out_format=json > /tmp/logs/bench_batch.txt 2>&1
  }
  grep -E 'median|copy bandwidth|ERROR' /tmp/logs/bench_*.txt | cut -c1-200 | head -150
fi
tar -C /tmp -czf "$OUT/logs.tar.gz" logs
