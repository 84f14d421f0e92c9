#include "util/parallel.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <system_error>
#include <mutex>
#include <thread>
#include <vector>

#ifdef __linux__
#include <sched.h>
#endif
#if defined(__unix__) || defined(__APPLE__)
#include <pthread.h>
#endif

namespace corofem::detail {

namespace {

/// Workers sleep on a condition variable between jobs (no spinning: on a CPU OpenCL device they
/// share the cores with its threads). One job at a time; the caller works on it too.
class Pool {
 public:
  explicit Pool(std::size_t threads) {
    // A thread the system refuses (a pids limit, RLIMIT_NPROC) leaves the pool with those it got;
    // with none, parallelChunks runs on the caller.
    try {
      for (std::size_t i = 1; i < threads; ++i) workers_.emplace_back([this] { work(); });
    } catch (const std::system_error&) {
    }
  }
  ~Pool() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    for (std::thread& t : workers_) t.join();
  }
  std::size_t threads() const { return workers_.size() + 1; }

  /// false (nothing run) when another thread holds the pool.
  bool run(std::size_t chunks, std::size_t n, std::size_t chunkSize,
           const std::function<void(std::size_t, std::size_t, std::size_t)>& fn) {
    std::unique_lock<std::mutex> busy(busy_, std::try_to_lock);
    if (!busy.owns_lock()) return false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      fn_ = &fn;
      n_ = n;
      chunkSize_ = chunkSize;
      chunks_ = chunks;
      next_.store(0);
      done_ = 0;
      ++generation_;
    }
    wake_.notify_all();
    const std::size_t mine = drain();
    std::unique_lock<std::mutex> lock(mutex_);
    done_ += mine;
    // Every chunk done and every worker that took this job out of it: none can touch the next.
    finished_.wait(lock, [&] { return done_ == chunks_ && active_ == 0; });
    fn_ = nullptr;  // a worker waking from now on finds no job to take
    return true;
  }

 private:
  std::size_t drain() {  // chunks taken by this thread until none is left
    std::size_t count = 0;
    for (std::size_t c = next_.fetch_add(1); c < chunks_; c = next_.fetch_add(1), ++count)
      (*fn_)(c, c * chunkSize_, std::min(n_, (c + 1) * chunkSize_));
    return count;
  }
  void work() {
    std::size_t seen = 0;
    for (;;) {
      {
        std::unique_lock<std::mutex> lock(mutex_);
        wake_.wait(lock, [&] { return stop_ || (generation_ != seen && fn_ != nullptr); });
        if (stop_) return;
        seen = generation_;
        ++active_;  // taken under the lock that ends the job: taken before its end, or not at all
      }
      const std::size_t mine = drain();
      std::lock_guard<std::mutex> lock(mutex_);
      done_ += mine;
      --active_;
      if (done_ == chunks_ && active_ == 0) finished_.notify_one();
    }
  }

  std::vector<std::thread> workers_;
  std::mutex busy_;   ///< held by the caller of the job in progress
  std::mutex mutex_;  ///< guards the job's description and done_
  std::condition_variable wake_, finished_;
  const std::function<void(std::size_t, std::size_t, std::size_t)>* fn_ = nullptr;
  std::size_t n_ = 0, chunkSize_ = 1, chunks_ = 0, done_ = 0, generation_ = 0;
  std::size_t active_ = 0;  ///< workers inside the current job
  std::atomic<std::size_t> next_{0};
  bool stop_ = false;
};

/// Set in a child made by fork() after the pool existed. The child has none of the pool's workers,
/// and the pool's mutex may have been held by one of them at the fork (a worker going back to
/// sleep), so the child never touches the pool: its passes run on the caller, chunk by chunk in
/// order, which gives the same bits.
std::atomic<bool> forkedChild{false};

Pool& pool() {
  // Never destroyed: its workers sleep until the process ends. Destroying it at exit would hang a
  // forked child in pthread_cond_destroy (the parent's sleeping workers count as waiters there), and
  // a static destructor elsewhere could still call parallelChunks.
  static Pool* p = [] {
#if defined(__unix__) || defined(__APPLE__)
    pthread_atfork(nullptr, nullptr, [] { forkedChild.store(true, std::memory_order_relaxed); });
#endif
    return new Pool(hostThreads());
  }();
  return *p;
}

}  // namespace

namespace {
/// The CPUs a Linux cgroup quota grants (quota / period, rounded up), 0 where there is none or none
/// can be read (and on every other system).
std::size_t cgroupCpus() {
#ifndef __linux__
  return 0;
#else
  double quota = -1, period = -1;
  if (std::FILE* f = std::fopen("/sys/fs/cgroup/cpu.max", "r")) {  // v2: "max 100000" or "200000 100000"
    char q[32] = {0};
    if (std::fscanf(f, "%31s %lf", q, &period) == 2 && std::string(q) != "max") quota = std::atof(q);
    std::fclose(f);
  } else if (std::FILE* fq = std::fopen("/sys/fs/cgroup/cpu/cpu.cfs_quota_us", "r")) {  // v1
    if (std::fscanf(fq, "%lf", &quota) != 1) quota = -1;
    std::fclose(fq);
    if (std::FILE* fp = std::fopen("/sys/fs/cgroup/cpu/cpu.cfs_period_us", "r")) {
      if (std::fscanf(fp, "%lf", &period) != 1) period = -1;
      std::fclose(fp);
    }
  }
  if (quota <= 0 || period <= 0) return 0;
  return static_cast<std::size_t>(std::ceil(quota / period));
#endif
}
}  // namespace

std::size_t usableCpus() {
  static const std::size_t n = [] {
    std::size_t cpus = std::max(1u, std::thread::hardware_concurrency());
#ifdef __linux__
    cpu_set_t set;
    CPU_ZERO(&set);
    if (sched_getaffinity(0, sizeof(set), &set) == 0) cpus = std::max(1, CPU_COUNT(&set));
#endif
    if (const std::size_t quota = cgroupCpus(); quota > 0) cpus = std::min(cpus, std::max<std::size_t>(1, quota));
    return cpus;
  }();
  return n;
}

namespace {

thread_local const TaskRunnerFn* currentRunner = nullptr;
/// Chunks of a parallelChunks call this thread is running for the pool or a runner (> 0: a nested
/// call runs its chunks here, in order: it neither takes the pool this thread's caller holds nor
/// calls the application's runner from inside one of its tasks).
thread_local int chunkDepth = 0;

/// $COROFEM_HOST_THREADS as a count, 0 where it is unset, empty or not a whole number from 1.
std::size_t hostThreadsFromEnv() {
  const char* env = std::getenv("COROFEM_HOST_THREADS");
  if (!env || !*env) return 0;
  char* end = nullptr;
  const long asked = std::strtol(env, &end, 10);
  if (*end != '\0' || asked < 1) return 0;
  return std::min<std::size_t>(static_cast<std::size_t>(asked), 64);  // more gains nothing here
}

}  // namespace

TaskScope::TaskScope(const TaskRunnerFn& runner) : previous_(currentRunner), installed_(static_cast<bool>(runner)) {
  if (installed_) currentRunner = &runner;
}

TaskScope::~TaskScope() {
  if (installed_) currentRunner = previous_;
}

std::size_t hostThreads() {
  static const std::size_t n = [] {
    const std::size_t asked = hostThreadsFromEnv();
    return asked ? asked : std::clamp<std::size_t>(usableCpus(), 1, 8);
  }();
  return n;
}

std::string hostThreadsProblem() {
  const char* env = std::getenv("COROFEM_HOST_THREADS");
  if (!env || !*env || hostThreadsFromEnv() != 0) return "";
  return std::string("COROFEM_HOST_THREADS='") + std::string(env).substr(0, 40) +
         "' is not a whole number from 1 to 64; it is ignored, and the host uses " + std::to_string(hostThreads()) +
         " threads";
}

void parallelChunks(std::size_t n, std::size_t chunkSize,
                    const std::function<void(std::size_t chunk, std::size_t begin, std::size_t end)>& fn) {
  chunkSize = std::max<std::size_t>(chunkSize, 1);
  const std::size_t chunks = chunkCount(n, chunkSize);
  if (chunks > 1 && chunkDepth == 0) {
    const std::function<void(std::size_t, std::size_t, std::size_t)> marked = [&](std::size_t c, std::size_t begin,
                                                                                  std::size_t end) {
      ++chunkDepth;
      fn(c, begin, end);
      --chunkDepth;
    };
    if (currentRunner) {
      (*currentRunner)(chunks, [&](std::size_t c) { marked(c, c * chunkSize, std::min(n, (c + 1) * chunkSize)); });
      return;
    }
    if (hostThreads() > 1 && !forkedChild.load(std::memory_order_relaxed) && pool().run(chunks, n, chunkSize, marked))
      return;
  }
  for (std::size_t c = 0; c < chunks; ++c) fn(c, c * chunkSize, std::min(n, (c + 1) * chunkSize));
}

}  // namespace corofem::detail
