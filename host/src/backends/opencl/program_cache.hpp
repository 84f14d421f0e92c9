// OpenCL programs built from the embedded kernel sources (kernels/opencl/*.cl after
// kernels/shared/*.h) with -D switches, cached in memory per context and on disk as device binaries.
// Disk cache: the kernels/ folder of the cache folder (util/cache_dir.hpp: $COROFEM_CACHE_DIR, whose
// value "off" disables it, else %LOCALAPPDATA%\corofem on Windows, $XDG_CACHE_HOME/corofem or
// ~/.cache/corofem); one file per (device
// name, driver version, options, source hash). A cache file that does not load is rebuilt from source and overwritten, never fatal.
// PoCL's devices get no file here (cachesBinaries): PoCL keeps its own cache of what it compiled.
#pragma once

#include "backends/opencl/cl_context.hpp"
#include "util/hash.hpp"

#include <cstdint>
#include <string>

namespace corofem::detail::cl {

enum class ProgramOrigin {
  Memory,    ///< already built on this context
  Disk,      ///< loaded from a cached device binary
  Compiled,  ///< compiled from source (and written to the disk cache when possible)
};

struct ProgramBuild {
  cl_program program = nullptr;  ///< owned by the context's cache: do not release
  ProgramOrigin origin = ProgramOrigin::Compiled;
  std::string cacheFile;         ///< the disk cache file for this program ("" when disabled)
};

/// Whether corofem keeps the device's program binaries on disk. Not on PoCL ("Portable Computing
/// Language"): asking PoCL for a program's binary makes it compile every kernel of the program for
/// any work-group size, while a launch compiles only the kernel launched, for its size; and PoCL
/// caches both the program and those kernels itself ($POCL_CACHE_DIR, else ~/.cache/pocl). A
/// 200-tet beam's first `corofem run` on empty caches took 16 s with the binaries, 2.8-3.4 s
/// without (docs/performance.md, "PoCL's cold start").
bool cachesBinaries(const DeviceInfo& device);

/// Where buildProgram looks for and keeps the program's binary: Auto follows cachesBinaries;
/// Always uses the disk cache on every device (the tests of the disk cache, on PoCL).
enum class BinaryCache { Auto, Always };

/// The on-disk cache directory, "" when disabled or no home directory is known.
std::string kernelCacheDirectory();

/// The corofem kernel program: the embedded shared headers, then the .cl files in dependency
/// order, each preceded by a #line directive naming it (so build logs name the real file).
std::string corofemProgramSource();

/// 64-bit FNV-1a hash (cache keys).
std::uint64_t fnv1a64(const std::string& text, std::uint64_t seed = kFnv1aOffset);

/// Returns the program built from `source` with `options` on ctx: from the context's memory cache,
/// else from the disk cache (where `cache` and cachesBinaries allow it), else compiled. Throws
/// Error(DeviceError) with the compiler's build log naming `label` when compilation fails.
ProgramBuild buildProgram(Context& ctx, const std::string& label, const std::string& source,
                          const std::string& options, BinaryCache cache = BinaryCache::Auto);

}  // namespace corofem::detail::cl
