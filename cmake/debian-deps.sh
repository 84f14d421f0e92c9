#!/usr/bin/env bash
# Installs, with apt-get, the Debian 12 packages corofem needs that are missing (the Vulkan loader,
# headers and glslc build the Vulkan backend; mesa-vulkan-drivers is lavapipe, its CPU device; the Khronos
# validation layers check the Vulkan tests that run on an application-made device). Run as root
# (or with sudo available). Installs nothing when everything is already there. clang-14 and its
# runtime (libFuzzer, the sanitizers) build the fuzz targets (tests/fuzz/run_fuzz.sh). MinGW-w64's g++
# checks that the library compiles for Windows (tests/portability/windows_syntax.sh).
set -euo pipefail

packages=(
  cmake g++ make pkg-config
  libeigen3-dev nlohmann-json3-dev zlib1g-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  ocl-icd-opencl-dev opencl-headers pocl-opencl-icd clinfo
  libvulkan-dev glslc mesa-vulkan-drivers vulkan-validationlayers
  python3 python3-matplotlib python3-numpy python3-meshio
  clang-14 libclang-rt-14-dev
  g++-mingw-w64-x86-64-posix
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]})); then
  echo "corofem: installing missing Debian packages: ${missing[*]}"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "corofem: all Debian packages present"
fi
