// A small pool of host threads for the passes over large node vectors that the OpenCL backend
// makes between device work (packing, converting and checking 3N-entry vectors): on a 1M-element
// body each such pass is milliseconds of one core's memory bandwidth while the device waits.
#pragma once

#include <cstddef>
#include <functional>

namespace corofem::detail {

/// Runs fn(chunk, begin, end) for every chunk of [0, n): chunk c covers
/// [c * chunkSize, min(n, (c + 1) * chunkSize)). The chunks do not depend on the number of threads,
/// so per-chunk results combined in chunk order give the same bits with any number of threads.
/// Runs on the caller alone when there is one chunk, when the pool has one thread
/// (COROFEM_HOST_THREADS=1), or when another thread is using the pool; else on the pool's threads and
/// the caller, returning when every chunk is done. fn must not throw.
void parallelChunks(std::size_t n, std::size_t chunkSize,
                    const std::function<void(std::size_t chunk, std::size_t begin, std::size_t end)>& fn);

/// Number of chunks parallelChunks makes of n.
inline std::size_t chunkCount(std::size_t n, std::size_t chunkSize) { return (n + chunkSize - 1) / chunkSize; }

/// CPUs this process may run on at once: the CPUs of its affinity mask, fewer where a cgroup's CPU
/// quota (v2 cpu.max, v1 cpu.cfs_quota_us) allows less (rounded up); the hardware's count where
/// neither can be read. Read once.
std::size_t usableCpus();

/// A count of threads from the environment variable `name`: `fallback` where it is unset or empty;
/// where it is not a whole number of at least `least`, `fallback` too, said on stderr with the
/// variable's name and value; else the number, at most `most`.
std::size_t threadCountFromEnv(const char* name, std::size_t least, std::size_t most, std::size_t fallback,
                               const char* what);

/// Threads the pool asks for: $COROFEM_HOST_THREADS if set (1 to 64; anything else is reported on
/// stderr and ignored), else the hardware's, at most 8. The system may grant fewer.
std::size_t hostThreads();

}  // namespace corofem::detail
