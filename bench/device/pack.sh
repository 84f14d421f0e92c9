#!/usr/bin/env bash
# Packs what a lent GPU machine (no package registry there) needs to run corofem's tests and
# benchmarks into .gpu/pack.tar.xz (ignored by git; the device tool carries it; run_on_gpu.sh unpacks
# it there): the Release binaries built here, stripped; the libraries they link that the machine's
# CUDA image lacks, from Debian 12 (the OpenCL ICD loader, the Vulkan loader, Google Benchmark, and
# GLVND's and X11's client libraries for NVIDIA's Vulkan driver); the C API's shared library; and
# ../shared/data. Run from the repository root after `cmake --preset opencl && cmake --build build`,
# then call the device tool with carry [".gpu"] and the command `bash bench/device/run_on_gpu.sh 2>&1`.
# The carried libraries come first on LD_LIBRARY_PATH there, before the image's own copies.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
ex=$(git rev-parse --git-path info/exclude); mkdir -p "$(dirname "$ex")"
grep -qx "/.gpu/" "$ex" 2>/dev/null || echo "/.gpu/" >> "$ex"
rm -rf .gpu && mkdir -p .gpu/bin .gpu/lib
for b in build/tests/test_* build/bench/bench_* build/corofem build/renderer; do
  [[ -x $b && -f $b ]] || continue
  strip -o ".gpu/bin/$(basename "$b")" "$b"
done
# The Vulkan loader too: a CUDA image may have NVIDIA's Vulkan driver but no loader.
for lib in libOpenCL.so.1 libbenchmark.so.1debian libvulkan.so.1; do
  cp -L "$(ldconfig -p | awk -v l="$lib" '$1 == l {print $NF; exit}')" .gpu/lib/
done
# NVIDIA's Vulkan driver is libGLX_nvidia, which needs GLVND's dispatch library (and, through
# libGLX, X11's client libraries) that a compute image may lack: without them the loader finds no
# driver. Those this machine has travel.
for lib in libGLdispatch.so.0 libGLX.so.0 libEGL.so.1 libX11.so.6 libXext.so.6 libxcb.so.1 libXau.so.6 \
           libXdmcp.so.6 libbsd.so.0 libmd.so.0; do
  f=$(ldconfig -p | awk -v l="$lib" '$1 == l {print $NF; exit}')
  [[ -n $f ]] && cp -L "$f" .gpu/lib/
done
# The C API's shared library, which a test opens by its build path.
c=$(readlink -f build/libcorofem_c.so 2>/dev/null || true)
[[ -f $c ]] && strip -o ".gpu/lib/$(basename "$c")" "$c"
if [[ -d ../shared/data ]]; then
  mkdir -p .gpu/data && cp -r ../shared/data/. .gpu/data/
fi
# Compressed: the stripped binaries alone pass the device tool's 64 MiB (each links the library
# statically); run_on_gpu.sh unpacks them there.
(cd .gpu && tar -c bin lib $( [[ -d data ]] && echo data ) | xz -T0 -6 > pack.tar.xz && rm -rf bin lib data)
du -sh .gpu
