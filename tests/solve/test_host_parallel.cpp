// The host's chunked passes (util/parallel.hpp) that the OpenCL backend runs over large node
// vectors: every index once in its fixed chunk, per-chunk results combinable in chunk order, and
// two callers at once (the second runs on its own thread). CI's 2-core machine runs the pool with
// one worker beside the caller, so the threaded path runs here.
#include "util/parallel.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <thread>
#include <vector>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

namespace corofem {
namespace {

using detail::chunkCount;
using detail::parallelChunks;

TEST(HostParallel, EveryIndexOnceInItsFixedChunk) {
  EXPECT_GE(detail::hostThreads(), 1u);
  for (std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{7}, std::size_t{4096}, std::size_t{4097},
                        std::size_t{1000003}}) {
    for (std::size_t chunk : {std::size_t{1}, std::size_t{7}, std::size_t{4096}}) {
      if (n > 100000 && chunk == 1) continue;  // a million jobs of one index: slow, nothing new
      std::vector<std::atomic<int>> hits(n), seen(chunkCount(n, chunk));
      std::atomic<int> misplaced{0};
      parallelChunks(n, chunk, [&](std::size_t c, std::size_t begin, std::size_t end) {
        if (begin != c * chunk || end != std::min(n, begin + chunk) || begin >= end) ++misplaced;
        ++seen[c];
        for (std::size_t i = begin; i < end; ++i) ++hits[i];
      });
      EXPECT_EQ(misplaced.load(), 0) << "n " << n << " chunk " << chunk;
      EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](const std::atomic<int>& h) { return h.load() == 1; }))
          << "n " << n << " chunk " << chunk;
      EXPECT_TRUE(std::all_of(hits.begin(), hits.end(), [](const std::atomic<int>& h) { return h.load() == 1; }))
          << "n " << n << " chunk " << chunk;
    }
  }
}

/// Sum of v over fixed chunks, the chunks added in order (chunkSums): what the backend does for
/// b . b and the centroid, and the dynamics driver for its norms and work.
double chunkedSum(const std::vector<double>& v, std::size_t chunk) {
  return detail::chunkSums<1>(v.size(), chunk, [&](std::size_t begin, std::size_t end, std::array<double, 1>& s) {
    for (std::size_t i = begin; i < end; ++i) s[0] += v[i];
  })[0];
}

TEST(HostParallel, ChunkedSumsHaveTheBitsOfTheSameChunksAddedInOrderOnOneThread) {
  std::vector<double> v(300001);
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = std::sin(0.37 * static_cast<double>(i)) * (1.0 + 1e-3 * i);
  for (std::size_t chunk : {std::size_t{1000}, std::size_t{65536}}) {
    double serial = 0.0;
    for (std::size_t begin = 0; begin < v.size(); begin += chunk) {
      double s = 0.0;
      for (std::size_t i = begin; i < std::min(v.size(), begin + chunk); ++i) s += v[i];
      serial += s;
    }
    for (int repeat = 0; repeat < 5; ++repeat) EXPECT_EQ(chunkedSum(v, chunk), serial) << "chunk " << chunk;
  }
}

TEST(HostParallel, ChunkSumsAddTheChunksInOrderWhateverOrderTheyRunIn) {
  // Chunks whose sums are 1e16, -1e16 and 1: added in order 1, last first 0 (1 - 1e16 rounds to
  // -1e16).
  std::vector<double> v(3000, 0.0);
  v[10] = 1e16;
  v[1500] = -1e16;
  v[2999] = 1.0;
  constexpr std::size_t chunk = 1000;
  double serial = 0.0;
  for (std::size_t begin = 0; begin < v.size(); begin += chunk) {
    double s = 0.0;
    for (std::size_t i = begin; i < begin + chunk; ++i) s += v[i];
    serial += s;
  }
  const detail::TaskRunnerFn backwards = [](std::size_t count, const std::function<void(std::size_t)>& task) {
    for (std::size_t i = count; i-- > 0;) task(i);
  };
  const detail::TaskScope scope(backwards);
  const std::array<double, 2> sums =
      detail::chunkSums<2>(v.size(), chunk, [&](std::size_t begin, std::size_t end, std::array<double, 2>& s) {
        for (std::size_t i = begin; i < end; ++i) {
          s[0] += v[i];
          s[1] += 2.0 * v[i];
        }
      });
  EXPECT_EQ(sums[0], serial);
  EXPECT_EQ(sums[1], 2.0 * serial);
  EXPECT_EQ(serial, 1.0);
}

TEST(HostParallel, TwoCallersAtOnceBothFinishWithTheirOwnAnswers) {
  std::vector<double> a(100000, 1.0), b(100000, 2.0);
  std::atomic<int> wrong{0};
  auto caller = [&](const std::vector<double>& v, double expected) {
    for (int job = 0; job < 300; ++job)
      if (chunkedSum(v, 1000) != expected) ++wrong;
  };
  std::thread first(caller, std::cref(a), 100000.0), second(caller, std::cref(b), 200000.0);
  first.join();
  second.join();
  EXPECT_EQ(wrong.load(), 0);
}

TEST(HostParallel, AForkedChildUsesItAndExitsNormally) {
  // After fork the child has none of the pool's workers, and the pool's mutex may be held by one
  // that was going back to sleep at the fork. The child must still run chunked passes (on the
  // caller alone, never touching the pool) and exit through the static destructors without
  // waiting for the parent's workers (a destroyed pool hung there in pthread_cond_destroy).
  std::vector<double> v(100000, 1.0);
  ASSERT_EQ(chunkedSum(v, 1000), 100000.0);  // the pool exists
  // Its workers are running, not starting: a thread starting under AddressSanitizer allocates, and
  // the allocator's lock held at the fork would hang the child's leak check at exit (GCC 12's
  // libasan takes no lock around fork), which is not what this test is about. One chunk per thread,
  // each waiting (up to 10 s: a thread the system refused never comes) until all are taken: a
  // thread holds one waiting chunk at a time, so every worker has taken one.
  const int threads = static_cast<int>(detail::hostThreads());
  if (threads > 1) {
    std::atomic<int> entered{0};
    parallelChunks(static_cast<std::size_t>(threads), 1, [&](std::size_t, std::size_t, std::size_t) {
      ++entered;
      for (int i = 0; i < 10000 && entered.load() < threads; ++i) usleep(1000);
    });
  }
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) std::exit(chunkedSum(v, 1000) == 100000.0 ? 0 : 1);
  int status = 0;
  pid_t done = 0;
  for (int i = 0; i < 200 && (done = waitpid(child, &status, WNOHANG)) == 0; ++i) usleep(50000);
  if (done == 0) {
    kill(child, SIGKILL);
    waitpid(child, &status, 0);
    FAIL() << "the forked child did not exit within 10 s";
  }
  ASSERT_EQ(done, child);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "child status " << status;
}

}  // namespace
}  // namespace corofem
