// The host's parallel work between device calls: the passes over large node vectors (packing,
// converting and checking 3N-entry vectors: on a 1M-element body each is milliseconds of one core's
// memory bandwidth while the device waits) and the per-body work of a batch's drivers. It runs on
// an application's task system where one is installed (TaskScope), else on a small pool of the
// library's own.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

namespace corofem::detail {

/// Where the host's parallel work runs: an application's task system (SimulationOptions::tasks),
/// the same type as corofem::TaskRunner. Empty: the library's own pool.
using TaskRunnerFn = std::function<void(std::size_t count, const std::function<void(std::size_t)>& task)>;

/// Installs `runner` for the calling thread's parallelChunks calls until destroyed (the previous
/// one back then); an empty runner installs nothing.
class TaskScope {
 public:
  explicit TaskScope(const TaskRunnerFn& runner);
  ~TaskScope();
  TaskScope(const TaskScope&) = delete;
  TaskScope& operator=(const TaskScope&) = delete;

 private:
  const TaskRunnerFn* previous_ = nullptr;
  bool installed_ = false;
};

/// Runs fn(chunk, begin, end) for every chunk of [0, n): chunk c covers
/// [c * chunkSize, min(n, (c + 1) * chunkSize)). The chunks do not depend on the number of threads,
/// so per-chunk results combined in chunk order give the same bits with any number of threads.
/// Runs on the caller alone when there is one chunk; else on the calling thread's TaskScope runner
/// where one is installed, else on the pool's threads and the caller (on the caller alone when
/// the pool has one thread, COROFEM_HOST_THREADS=1, or another thread is using it), returning when
/// every chunk is done. Called from inside a chunk of another call that the pool or a runner runs
/// (a body's passes inside a pass over bodies), it runs its chunks on the calling thread, in order.
/// fn must not throw.
void parallelChunks(std::size_t n, std::size_t chunkSize,
                    const std::function<void(std::size_t chunk, std::size_t begin, std::size_t end)>& fn);

/// Number of chunks parallelChunks makes of n.
inline std::size_t chunkCount(std::size_t n, std::size_t chunkSize) { return (n + chunkSize - 1) / chunkSize; }

/// K sums over [0, n) by parallelChunks: fn(begin, end, sums) adds chunk [begin, end)'s terms to
/// its own K sums (from 0), and the chunks' sums are added in chunk order, so the totals have the
/// same bits with any number of threads running the chunks in any order; with one chunk, the bits
/// of one pass in index order. fn must not throw.
template <std::size_t K, class Fn>
std::array<double, K> chunkSums(std::size_t n, std::size_t chunkSize, Fn&& fn) {
  if (n <= chunkSize) {  // one chunk: on the caller, no allocation (the many small bodies of a batch)
    std::array<double, K> total;
    total.fill(0.0);
    fn(std::size_t{0}, n, total);
    return total;
  }
  std::vector<std::array<double, K>> part(std::max<std::size_t>(1, chunkCount(n, chunkSize)));
  for (std::array<double, K>& p : part) p.fill(0.0);
  parallelChunks(n, chunkSize, [&](std::size_t c, std::size_t begin, std::size_t end) { fn(begin, end, part[c]); });
  std::array<double, K> total = part[0];
  for (std::size_t c = 1; c < part.size(); ++c)
    for (std::size_t k = 0; k < K; ++k) total[k] += part[c][k];
  return total;
}

/// CPUs this process may run on at once: the CPUs of its affinity mask, fewer where a cgroup's CPU
/// quota (v2 cpu.max, v1 cpu.cfs_quota_us) allows less (rounded up); the hardware's count where
/// neither can be read. Read once.
std::size_t usableCpus();

/// Threads the pool asks for: $COROFEM_HOST_THREADS if it is a whole number from 1 (at most 64),
/// else the usable CPUs, at most 8. The system may grant fewer.
std::size_t hostThreads();
/// Why $COROFEM_HOST_THREADS is ignored ("" when it is unset or valid), for the application's log.
std::string hostThreadsProblem();

}  // namespace corofem::detail
