#!/usr/bin/env bash
# The library and the corofem command compile for Windows. Two checks over host/src:
# - MinGW-w64's g++ (Debian's g++-mingw-w64-x86-64-posix) compiles every source with -fsyntax-only
#   against Windows' own headers, warnings as errors (eight at a time in the library's unity
#   batches where the build has them; an error still names its source file, but a header that a
#   source's Windows branch needs and does not include passes where an earlier source of its batch
#   includes it). It catches a POSIX call or flag Windows lacks (O_NONBLOCK, S_ISSOCK,
#   sched_getaffinity ...).
# - A search: POSIX headers (unistd.h, fcntl.h, sys/*.h, pthread.h, dlfcn.h, sched.h) only inside
#   `#ifndef _WIN32`, `#ifdef __linux__` or the `#else` of `#ifdef _WIN32`; no GCC __builtin_. MinGW
#   ships unistd.h and getpid and takes GCC's builtins, and MSVC has none of them.
# It is not a build with MSVC, and nothing is linked or run on Windows.
# Usage (CTest, tests/CMakeLists.txt): windows_syntax.sh SOURCE_DIR BUILD_DIR JOBS WITH_OPENCL
#   WITH_VULKAN EIGEN_INCLUDE JSON_INCLUDE OPENCL_INCLUDE VULKAN_INCLUDE  (ON/OFF; folders)
# Exit: 0 all pass; 1 some do not (each named with its first errors); 77 no MinGW-w64 compiler.
set -euo pipefail
src=$1 build=$2 jobs=$3 opencl=$4 vulkan=$5 eigen=$6 json=$7 clinc=${8:-} vkinc=${9:-}
# The posix-threads variant: the win32 one has no std::thread or std::mutex in GCC 12.
cxx=$(command -v x86_64-w64-mingw32-g++-posix || true)
if [[ -z "$cxx" ]]; then
  echo "SKIP: no MinGW-w64 C++ compiler with POSIX threads (install g++-mingw-w64-x86-64-posix; cmake/debian-deps.sh does)"
  exit 77
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
failed=0

# 1. The search. A conditional's state per nesting level: "ok" where a POSIX header may appear.
posix='^[[:space:]]*#[[:space:]]*include[[:space:]]*<(unistd|fcntl|pthread|dlfcn|sched|sys/[a-z_]+)[.]h>'
while IFS= read -r -d '' f; do
  awk -v file="$f" -v posix="$posix" '
    # "ok": a POSIX branch (a condition that names a POSIX system and negates nothing, or
    # #ifndef _WIN32); "win": #ifdef _WIN32 or #if defined(_WIN32) alone, whose #else is one.
    function posixOnly(line) {
      return line !~ /!/ && line ~ /(__linux__|__unix__|__APPLE__)([^A-Za-z0-9_]|$)/
    }
    /^[[:space:]]*#[[:space:]]*if/ {
      ok = ($0 ~ /#[[:space:]]*ifndef[[:space:]]+_WIN32([^A-Za-z0-9_]|$)/ || posixOnly($0))
      win = ($0 ~ /#[[:space:]]*ifdef[[:space:]]+_WIN32[[:space:]]*$/ || $0 ~ /#[[:space:]]*if[[:space:]]+defined\(_WIN32\)[[:space:]]*$/)
      depth++; state[depth] = ok; winif[depth] = win; next
    }
    /^[[:space:]]*#[[:space:]]*elif/ { if (depth) { state[depth] = posixOnly($0); winif[depth] = 0 } next }
    /^[[:space:]]*#[[:space:]]*else/ { if (depth) state[depth] = winif[depth]; next }
    /^[[:space:]]*#[[:space:]]*endif/ { if (depth) depth--; next }
    $0 ~ posix {
      allowed = 0
      for (i = 1; i <= depth; i++) if (state[i]) allowed = 1
      if (!allowed) { printf "%s:%d: %s: a POSIX header outside #ifndef _WIN32\n", file, NR, $0; bad = 1 }
    }
    /__builtin_/ { printf "%s:%d: a GCC builtin (MSVC has none): %s\n", file, NR, $0; bad = 1 }
    END { exit bad }' "$f" || failed=1
done < <(find "$src/host/src" "$src/host/include" \( -name '*.cpp' -o -name '*.hpp' -o -name '*.h' \) -print0)

# 2. The compile. The header-only dependencies through a folder of their own: the host's
# /usr/include itself would mix Linux's C headers into Windows'.
mkdir "$work/deps"
link() { [[ -n "$1" && -e "$1/$2" ]] && ln -s "$1/$2" "$work/deps/$2"; return 0; }
link "$json" nlohmann
flags=(-std=c++17 -fsyntax-only -Wall -Wextra -Wpedantic -Werror
       -I"$src/host/include" -I"$build/generated/include" -I"$src/host/src"
       -isystem "$eigen" -isystem "$work/deps" -DCOROFEM_VERSION=\"windows-syntax\")
skip='/host/src/backends/(opencl|vulkan)/'
if [[ "$opencl" == ON ]]; then
  link "$clinc" CL
  flags+=(-DCOROFEM_WITH_OPENCL=1 -DCL_TARGET_OPENCL_VERSION=120)
  skip='/host/src/backends/vulkan/'
fi
if [[ "$vulkan" == ON ]]; then
  link "$vkinc" vulkan
  link "$vkinc" vk_video
  flags+=(-DCOROFEM_WITH_VULKAN=1 -I"$build/generated/spirv")
  [[ "$opencl" == ON ]] && skip='^$' || skip='/host/src/backends/opencl/'
fi
printf '%s\n' "${flags[@]}" > "$work/flags"
find "$src/host/src" -name '*.cpp' | { grep -Ev "$skip" || true; } | sort > "$work/sources"
# The library's unity batches (COROFEM_UNITY_BUILD: CMake's Unity/unity_N_cxx.cxx, which include
# the sources by absolute path) are compiled as they are, each a compiler run that parses the
# Windows and Eigen headers once for its eight sources: the check took 77 s of both cores source by
# source. A batch is taken only when the build's generator lists it (CMake leaves the batch files of
# an earlier configuration behind) and every source it includes is one of this check's; the sources
# no batch holds (the C API's, the command's, those the library keeps out of its batches, or all of
# them in a build without batches) are compiled one by one.
: > "$work/batched"
: > "$work/files"
for batch in "$build"/CMakeFiles/corofem.dir/Unity/unity_*_cxx.cxx; do
  [[ -f "$batch" ]] || continue
  grep -qsF "corofem.dir/Unity/${batch##*/}" "$build"/CMakeFiles/corofem.dir/build.make "$build"/build.ninja || continue
  sed -n 's/^#include "\(.*\)"$/\1/p' "$batch" | sort > "$work/members"
  if [[ -s "$work/members" ]] && [[ -z "$(comm -23 "$work/members" "$work/sources")" ]]; then
    cat "$work/members" >> "$work/batched"
    echo "$batch" >> "$work/files"
  fi
done
sort -o "$work/batched" "$work/batched"
comm -23 "$work/sources" "$work/batched" >> "$work/files"
echo "windows_syntax.sh: $(wc -l < "$work/sources") sources in $(wc -l < "$work/files") compiler runs," \
     "$cxx (OpenCL $opencl, Vulkan $vulkan)"
export cxx FLAGS="$work/flags"
# shellcheck disable=SC2016
xargs -r -d '\n' -n 1 -P "$jobs" bash -c '
  mapfile -t flags < "$FLAGS"
  if ! out=$("$cxx" "${flags[@]}" "$1" 2>&1); then
    printf "FAILED: %s\n%s\n" "$1" "$(grep -m5 -E "error|warning" <<< "$out")"
    exit 1
  fi' _ < "$work/files" || failed=1

if ((failed)); then
  echo "windows_syntax.sh: some sources are not portable (above); keep POSIX calls behind #ifndef _WIN32 with a standard C++ or Windows branch"
  exit 1
fi
echo "windows_syntax.sh: all pass"
