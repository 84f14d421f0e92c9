#!/usr/bin/env bash
# The library and the corofem command compile for Windows: every source of host/src is checked by
# MinGW-w64's g++ (Debian's g++-mingw-w64-x86-64-posix) with -fsyntax-only, against Windows' own
# headers. It catches what only POSIX offers (unistd.h, fstat, O_NONBLOCK, getpid ...); and a search
# refuses GCC's __builtin_ functions, which MSVC lacks (MinGW's g++, a GCC, would take them). It is
# not a build with MSVC, and nothing is linked or run on Windows.
# Usage: windows_syntax.sh SOURCE_DIR BUILD_DIR [JOBS]   (run by CTest: tests/CMakeLists.txt)
# Exit: 0 all compile; 1 some do not (each named with its first errors); 77 no cross compiler.
set -euo pipefail
src=$1 build=$2 jobs=${3:-2}
cxx=$(command -v x86_64-w64-mingw32-g++-posix || command -v x86_64-w64-mingw32-g++ || true)
if [[ -z "$cxx" ]]; then
  echo "SKIP: no MinGW-w64 C++ compiler (install g++-mingw-w64-x86-64-posix; cmake/debian-deps.sh does)"
  exit 77
fi
# The host's header-only dependencies, seen through a folder of their own (the host's /usr/include
# itself would mix Linux's C headers into Windows').
deps=$(mktemp -d)
trap 'rm -rf "$deps"' EXIT
for d in CL vulkan vk_video nlohmann; do
  [[ -e /usr/include/$d ]] && ln -s "/usr/include/$d" "$deps/$d"
done
flags=(-std=c++17 -fsyntax-only -Wall -Wextra -Wpedantic
       -I"$src/host/include" -I"$build/generated/include" -I"$src/host/src" -I"$build/generated/spirv"
       -isystem /usr/include/eigen3 -isystem "$deps"
       -DCOROFEM_VERSION=\"check\" -DCOROFEM_WITH_OPENCL=1 -DCL_TARGET_OPENCL_VERSION=120 -DCOROFEM_WITH_VULKAN=1)
failed=0
if grep -rn '__builtin_' "$src/host/src" "$src/host/include"; then
  echo "windows_syntax.sh: GCC builtins (above) do not compile with MSVC; write them in standard C++"
  failed=1
fi
export cxx
log=$(mktemp -d)
find "$src/host/src" -name '*.cpp' | sort > "$log/files"
echo "windows_syntax.sh: $(wc -l < "$log/files") sources, $cxx"
# shellcheck disable=SC2016
xargs -P "$jobs" -I{} bash -c 'f={}; out=$("$cxx" "$@" "$f" 2>&1) || { echo "FAILED: $f"; echo "$out" | grep -m5 "error"; exit 1; }' _ "${flags[@]}" < "$log/files" || failed=1
rm -rf "$log"
if ((failed)); then
  echo "windows_syntax.sh: some sources do not compile for Windows (above); keep POSIX calls behind #ifndef _WIN32 with a standard C++ or Windows branch"
  exit 1
fi
echo "windows_syntax.sh: all compile"
