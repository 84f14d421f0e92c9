// BatchGroup's rendezvous on its own (solve/batch_group.hpp): rounds hold every body's next call,
// bodies that finish, throw or fail over leave the count, and nothing deadlocks. The backends are
// small fakes whose answers are functions of their inputs, so every answer can be checked exactly.
#include "solve/batch_group.hpp"
#include "util/fiber.hpp"

#include "util/error.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <iostream>
#include <mutex>
#include <random>
#include <thread>

namespace corofem::test {
namespace {

using detail::Backend;
using detail::BatchGroup;
using detail::Error;
using detail::LinearSolveStats;
using detail::SystemCoeffs;

/// A backend whose answers are functions of the positions and the call's inputs (scaled by the
/// body's own factor k): f = k x, A p = (m + d + s k) p, solve x = b / (m + d + s k), energy =
/// k |x|^2. `failAt` > 0: the failAt-th call throws Error(DeviceError) (a device failure of this
/// body only).
class FakeBackend final : public Backend {
 public:
  FakeBackend(double k, int failAt = 0) : k_(k), failAt_(failAt) {}
  std::string name() const override { return "fake"; }
  std::string deviceName() const override { return "fake device"; }
  void setPositions(const Eigen::VectorXd& x) override {
    tick();
    x_ = x;
  }
  void internalForces(Eigen::VectorXd& f) override {
    tick();
    f = k_ * x_;
  }
  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) override {
    tick();
    y = (c.mass + c.damping + c.stiffness * k_) * p;
  }
  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    tick();
    x = b / (c.mass + c.damping + c.stiffness * k_);
    LinearSolveStats s;
    s.iterations = static_cast<int>(k_);
    s.converged = true;
    return s;
  }
  double elasticEnergy() override {
    tick();
    return k_ * x_.squaredNorm();
  }

 private:
  void tick() {
    if (failAt_ > 0 && ++calls_ == failAt_) detail::fail(ErrorCode::DeviceError, "injected device failure");
  }
  double k_;
  int failAt_;
  int calls_ = 0;
  Eigen::VectorXd x_ = Eigen::VectorXd::Zero(3);
};

/// `fiberWorkers` < 0: the group's default (fibers on a thread per usable CPU where available).
std::unique_ptr<BatchGroup> fakeGroup(std::size_t bodies, const std::vector<int>& failAt = {}, int fiberWorkers = -1) {
  std::vector<std::unique_ptr<Backend>> backends;
  for (std::size_t i = 0; i < bodies; ++i)
    backends.push_back(std::make_unique<FakeBackend>(1.0 + static_cast<double>(i), i < failAt.size() ? failAt[i] : 0));
  auto group = std::make_unique<BatchGroup>(detail::createLoopBatchDevice(std::move(backends)));
  if (fiberWorkers >= 0) group->setFiberWorkers(static_cast<std::size_t>(fiberWorkers));
  return group;
}

/// Aborts the test binary when a scope takes longer than `seconds`: a deadlock must fail, not hang
/// the suite until the CTest timeout.
class Watchdog {
 public:
  explicit Watchdog(int seconds) : thread_([this, seconds] {
    std::unique_lock<std::mutex> lk(m_);
    if (!cv_.wait_for(lk, std::chrono::seconds(seconds), [this] { return done_; })) {
      std::cerr << "Watchdog: no progress in " << seconds << " s: the rendezvous deadlocked" << std::endl;
      std::abort();
    }
  }) {}
  ~Watchdog() {
    {
      std::lock_guard<std::mutex> lk(m_);
      done_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  bool done_ = false;
  std::thread thread_;
};

std::vector<std::size_t> allBodies(std::size_t n) {
  std::vector<std::size_t> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = i;
  return v;
}

/// A view of every body of the group.
std::vector<std::unique_ptr<Backend>> allViews(BatchGroup& group) {
  std::vector<std::unique_ptr<Backend>> views;
  for (std::size_t i = 0; i < group.bodyCount(); ++i) views.push_back(group.view(i));
  return views;
}

TEST(BatchGroup, EveryRoundHoldsEveryBodysNextCall) {
  // Body i makes i + 1 calls in the step: round r holds the bodies with more than r - 1 calls, so
  // there are exactly max(i + 1) rounds, the first with every body, and sum(i + 1) requests.
  Watchdog dog(60);
  const std::size_t n = 12;
  auto group = fakeGroup(n);
  std::vector<std::unique_ptr<Backend>> views = allViews(*group);
  std::vector<double> energy(n, 0.0);
  const auto errors = group->runStep(allBodies(n), [&](std::size_t i) {
    Eigen::VectorXd x = Eigen::VectorXd::Constant(3, static_cast<double>(i));
    for (std::size_t c = 0; c <= i; ++c) {
      if (c == 0) views[i]->setPositions(x);
      else energy[i] = views[i]->elasticEnergy();
    }
  });
  ASSERT_EQ(errors.size(), n);
  for (const auto& e : errors) EXPECT_FALSE(e);
  const detail::BatchGroupStats st = group->stats();
  EXPECT_EQ(st.rounds, static_cast<long long>(n));
  EXPECT_EQ(st.requests, static_cast<long long>(n * (n + 1) / 2));
  EXPECT_EQ(st.largestRound, n);
  for (std::size_t i = 1; i < n; ++i)
    EXPECT_EQ(energy[i], (1.0 + static_cast<double>(i)) * 3.0 * static_cast<double>(i * i)) << "body " << i;
}

TEST(BatchGroup, RoundsByCallCountEachCallAndTheWaitBeforeIt) {
  // Inside a step: a round of set_positions, then (after 40 ms of every body's "host work") a
  // round of internal_forces, then a round where body 0 asks for its energy while the others
  // solve (mixed). Each round counts under its call with its requests; the wait before the second
  // round holds the 40 ms. Calls outside a step count in the totals only.
  Watchdog dog(60);
  const std::size_t n = 4;
  auto group = fakeGroup(n);
  std::vector<std::unique_ptr<Backend>> views = allViews(*group);
  Eigen::VectorXd outside = Eigen::VectorXd::Ones(3);
  views[1]->setPositions(outside);
  const auto errors = group->runStep(allBodies(n), [&](std::size_t i) {
    Eigen::VectorXd x = Eigen::VectorXd::Constant(3, 1.0 + static_cast<double>(i)), f, y = Eigen::VectorXd::Zero(3);
    views[i]->setPositions(x);
    std::this_thread::sleep_for(std::chrono::milliseconds(40));
    views[i]->internalForces(f);
    if (i == 0)
      views[i]->elasticEnergy();
    else
      views[i]->solve({1.0, 0.0, 1.0}, f, y);
  });
  for (const auto& e : errors) EXPECT_FALSE(e);
  const detail::BatchGroupStats st = group->stats();
  EXPECT_EQ(st.rounds, 4);
  const auto& set = st.byCall[static_cast<std::size_t>(detail::BatchOp::SetPositions)];
  const auto& forces = st.byCall[static_cast<std::size_t>(detail::BatchOp::InternalForces)];
  const auto& mixed = st.byCall[detail::BatchGroupStats::kMixedCalls];
  EXPECT_EQ(set.rounds, 1);
  EXPECT_EQ(set.requests, static_cast<long long>(n));
  EXPECT_EQ(forces.rounds, 1);
  EXPECT_EQ(forces.requests, static_cast<long long>(n));
  EXPECT_GE(forces.waitSeconds, 0.040) << "the bodies' host work between the two calls";
  EXPECT_EQ(mixed.rounds, 1);
  EXPECT_EQ(mixed.requests, static_cast<long long>(n));
  for (detail::BatchOp op : {detail::BatchOp::Apply, detail::BatchOp::Solve, detail::BatchOp::ElasticEnergy}) {
    const auto c = static_cast<std::size_t>(op);
    EXPECT_EQ(st.byCall[c].rounds, 0) << detail::batchCallName(c);
  }
  for (const auto& c : st.byCall) {
    EXPECT_GE(c.deviceSeconds, 0.0);
    EXPECT_GE(c.waitSeconds, 0.0);
  }
  EXPECT_STREQ(detail::batchCallName(detail::BatchGroupStats::kMixedCalls), "mixed");
  EXPECT_STREQ(detail::batchCallName(static_cast<std::size_t>(detail::BatchOp::Solve)), "solve");
}

TEST(BatchGroup, TheWaitBeforeAStepsFirstRoundStartsWithTheStep) {
  // 60 ms pass between two steps of one call each: the second step's round counts only its own
  // wait (from its startStep), not the time since the first step's round.
  Watchdog dog(60);
  const std::size_t n = 3;
  auto group = fakeGroup(n);
  std::vector<std::unique_ptr<Backend>> views = allViews(*group);
  const auto step = [&](std::size_t i) {
    Eigen::VectorXd f;
    views[i]->internalForces(f);
  };
  for (const auto& e : group->runStep(allBodies(n), step)) EXPECT_FALSE(e);
  const double first = group->stats().byCall[static_cast<std::size_t>(detail::BatchOp::InternalForces)].waitSeconds;
  std::this_thread::sleep_for(std::chrono::milliseconds(60));
  for (const auto& e : group->runStep(allBodies(n), step)) EXPECT_FALSE(e);
  const auto& forces = group->stats().byCall[static_cast<std::size_t>(detail::BatchOp::InternalForces)];
  EXPECT_EQ(forces.rounds, 2);
  EXPECT_LT(forces.waitSeconds - first, 0.060) << "the pause between the steps is no wait inside a step";
}

TEST(BatchGroup, OutsideAStepACallIsARoundOfOne) {
  auto group = fakeGroup(3);
  auto view = group->view(1);
  Eigen::VectorXd x = Eigen::VectorXd::Constant(3, 2.0), f;
  view->setPositions(x);
  view->internalForces(f);
  EXPECT_EQ(f, 2.0 * x);  // k = 2 for body 1
  Eigen::VectorXd b = Eigen::VectorXd::Constant(3, 12.0), y = Eigen::VectorXd::Zero(3);
  const LinearSolveStats s = view->solve({1.0, 1.0, 2.0}, b, y);  // 1 + 1 + 2 * 2 = 6
  EXPECT_EQ(y, Eigen::VectorXd::Constant(3, 2.0));
  EXPECT_EQ(s.iterations, 2);
  EXPECT_EQ(view->name(), "fake");
  EXPECT_EQ(group->stats().rounds, 3);
  EXPECT_EQ(group->stats().largestRound, 1u);
  EXPECT_THROW(group->view(1), Error);  // one live view per body
  EXPECT_THROW(group->view(3), Error);
}

TEST(BatchGroup, ThrowingAndFinishedBodiesLeaveTheRendezvous) {
  Watchdog dog(60);
  const std::size_t n = 6;
  auto group = fakeGroup(n);
  std::vector<std::unique_ptr<Backend>> views = allViews(*group);
  // Body 0 returns at once, body 1 throws after one call, body 2 throws before any, the others
  // make 4 calls: they must not wait for the first three.
  const auto errors = group->runStep(allBodies(n), [&](std::size_t i) {
    if (i == 0) return;
    if (i == 2) throw std::runtime_error("body 2 gave up");
    Eigen::VectorXd x = Eigen::VectorXd::Ones(3), f;
    views[i]->setPositions(x);
    if (i == 1) throw std::runtime_error("body 1 gave up");
    for (int c = 0; c < 3; ++c) views[i]->internalForces(f);
    EXPECT_EQ(f, (1.0 + static_cast<double>(i)) * x);
  });
  EXPECT_FALSE(errors[0]);
  EXPECT_TRUE(errors[1]);
  EXPECT_TRUE(errors[2]);
  for (std::size_t i = 3; i < n; ++i) EXPECT_FALSE(errors[i]);
  EXPECT_EQ(group->stats().rounds, 4);  // the first holds bodies 1, 3, 4, 5
  EXPECT_EQ(group->stats().largestRound, 4u);
  try {
    std::rethrow_exception(errors[1]);
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "body 1 gave up");
  }
  // The group works for the next step.
  const auto again = group->runStep({3, 5}, [&](std::size_t i) {
    Eigen::VectorXd f;
    views[i]->internalForces(f);
  });
  EXPECT_FALSE(again[0]);
  EXPECT_FALSE(again[1]);
  EXPECT_EQ(group->stats().rounds, 5);
}

TEST(BatchGroup, ADeviceErrorFailsOnlyThatRequestAndAReplacedViewLeaves) {
  Watchdog dog(60);
  const std::size_t n = 4;
  auto group = fakeGroup(n, {0, 2});  // body 1's second call fails like a device
  std::vector<std::unique_ptr<Backend>> backends;
  for (std::size_t i = 0; i < n; ++i) backends.push_back(group->view(i));
  std::vector<int> calls(n, 0);
  const auto errors = group->runStep(allBodies(n), [&](std::size_t i) {
    Eigen::VectorXd x = Eigen::VectorXd::Ones(3), f;
    for (int c = 0; c < 5; ++c) {
      try {
        backends[i]->internalForces(f);
      } catch (const Error& e) {
        ASSERT_EQ(e.code(), ErrorCode::DeviceError);
        // What FailoverBackend does: replace the view by the next backend and repeat the call.
        backends[i] = std::make_unique<FakeBackend>(1.0 + static_cast<double>(i));
        backends[i]->internalForces(f);
      }
      ++calls[i];
    }
  });
  for (const auto& e : errors) EXPECT_FALSE(e);
  for (int c : calls) EXPECT_EQ(c, 5);
  EXPECT_FALSE(group->attached(1));
  EXPECT_TRUE(group->attached(0));
  EXPECT_EQ(group->stats().rounds, 5);
  // Body 1 may have a view again (it would come back to the batch).
  EXPECT_NO_THROW(group->view(1));
}

TEST(BatchGroup, ADeviceThatThrowsFailsEveryRequestOfTheRound) {
  class Broken final : public detail::BatchDevice {
   public:
    std::string name() const override { return "broken"; }
    std::string deviceName() const override { return "broken"; }
    std::size_t bodyCount() const override { return 3; }
    void run(std::vector<detail::BatchRequest*>&) override { detail::fail(ErrorCode::DeviceError, "the device is lost"); }
  };
  Watchdog dog(60);
  BatchGroup group(std::make_unique<Broken>());
  std::vector<std::unique_ptr<Backend>> views = allViews(group);
  const auto errors = group.runStep(allBodies(3), [&](std::size_t i) {
    Eigen::VectorXd f;
    views[i]->internalForces(f);
  });
  for (const auto& e : errors) {
    ASSERT_TRUE(e);
    try {
      std::rethrow_exception(e);
    } catch (const Error& err) {
      EXPECT_EQ(err.code(), ErrorCode::DeviceError);
      EXPECT_NE(std::string(err.what()).find("the device is lost"), std::string::npos);
    }
  }
  EXPECT_EQ(group.stats().rounds, 1);
}

/// 100 bodies, 40 steps: each body in each step makes a random number of random calls, may return
/// early, throw, or meet an injected device failure and fail over (its view replaced by a plain
/// backend, as FailoverBackend does). Every answer is checked; the watchdog turns a deadlock into a
/// failure. Random participation: some steps leave bodies out. The bodies run as fibers on
/// `fiberWorkers` threads (0: a thread each).
void stressManyBodies(int fiberWorkers) {
  Watchdog dog(120);
  const std::size_t n = 100;
  std::mt19937 rng(12345);
  std::vector<int> failAt(n, 0);
  for (std::size_t i = 0; i < n; ++i)
    if (i % 7 == 3) failAt[i] = 5 + static_cast<int>(rng() % 200);
  auto group = fakeGroup(n, failAt, fiberWorkers);
  std::vector<std::unique_ptr<Backend>> backends;
  for (std::size_t i = 0; i < n; ++i) backends.push_back(group->view(i));
  std::vector<Eigen::VectorXd> lastX(n, Eigen::VectorXd::Zero(3));  // what a new backend is given
  std::atomic<long long> wrong{0}, failovers{0}, calls{0};
  long long thrown = 0;
  for (int step = 0; step < 40; ++step) {
    std::vector<std::size_t> bodies;
    for (std::size_t i = 0; i < n; ++i)
      if (rng() % 10 != 0) bodies.push_back(i);
    std::vector<unsigned> seeds(n);
    for (auto& s : seeds) s = static_cast<unsigned>(rng());
    const auto errors = group->runStep(bodies, [&](std::size_t i) {
      std::mt19937 r(seeds[i]);
      const double k = 1.0 + static_cast<double>(i);
      const int count = static_cast<int>(r() % 12);
      auto once = [&](auto&& fn) {
        ++calls;
        try {
          fn();
        } catch (const Error& e) {
          if (e.code() != ErrorCode::DeviceError) throw;
          ++failovers;
          backends[i] = std::make_unique<FakeBackend>(k);
          backends[i]->setPositions(lastX[i]);
          fn();
        }
      };
      for (int c = 0; c < count; ++c) {
        const unsigned what = r() % 100;
        if (what < 3) return;                                      // finishes early
        if (what < 5) throw std::runtime_error("random failure");  // the step throws
        Eigen::VectorXd x = Eigen::VectorXd::Constant(3, static_cast<double>(r() % 10)), out;
        switch (what % 4) {
          case 0: {
            lastX[i] = x;
            once([&] { backends[i]->setPositions(x); });
            once([&] { backends[i]->internalForces(out); });
            if (out != k * x) ++wrong;
            break;
          }
          case 1: {
            once([&] { backends[i]->apply({1.0, 0.5, 2.0}, x, out); });
            if (out != (1.5 + 2.0 * k) * x) ++wrong;
            break;
          }
          case 2: {
            Eigen::VectorXd y = Eigen::VectorXd::Zero(3);
            LinearSolveStats s;
            once([&] { s = backends[i]->solve({1.0, 0.0, 1.0}, x, y); });
            if (y != x / (1.0 + k) || s.iterations != static_cast<int>(k)) ++wrong;
            break;
          }
          default: {
            double e = 0;
            lastX[i] = x;
            once([&] { backends[i]->setPositions(x); });
            once([&] { e = backends[i]->elasticEnergy(); });
            if (e != k * x.squaredNorm()) ++wrong;
          }
        }
      }
    });
    ASSERT_EQ(errors.size(), bodies.size());
    for (const auto& e : errors) thrown += e ? 1 : 0;
  }
  EXPECT_EQ(wrong.load(), 0);
  EXPECT_GT(failovers.load(), 0);
  EXPECT_GT(thrown, 0);
  const detail::BatchGroupStats st = group->stats();
  EXPECT_GT(st.largestRound, 50u);  // the rounds really batch
  EXPECT_LT(st.rounds, calls.load() / 10);
  std::cout << "[ info ] " << calls.load() << " calls, " << st.rounds << " rounds, " << st.requests
            << " batched requests, " << failovers.load() << " failovers, " << thrown << " thrown steps ("
            << group->fiberWorkers() << " fiber workers)\n";
}

TEST(BatchGroup, StressManyBodiesRandomExitsThrowsAndFailovers) {
  stressManyBodies(-1);  // the default: fibers where available
}

TEST(BatchGroup, StressWithAThreadPerBody) { stressManyBodies(0); }

TEST(BatchGroup, StressWithFibersOnOneAndOnThreeThreads) {
  if (!detail::fibersAvailable()) GTEST_SKIP() << "no fibers in this build (AddressSanitizer or no ucontext)";
  stressManyBodies(1);
  stressManyBodies(3);
}

TEST(BatchGroup, FiberStacksThatCannotBeMappedFallBackToAThreadPerBody) {
  // Stacks of 2^60 bytes cannot be mapped: the step runs with a thread per body instead, with the
  // same answers, and the group stays that way.
  if (!detail::fibersAvailable()) GTEST_SKIP() << "no fibers in this build (AddressSanitizer or no ucontext)";
  Watchdog dog(60);
  const std::size_t n = 5;
  auto group = fakeGroup(n);
  group->setFiberWorkers(2, std::size_t{1} << 60);
  std::vector<std::unique_ptr<Backend>> views = allViews(*group);
  for (int step = 0; step < 2; ++step) {
    std::vector<Eigen::VectorXd> f(n);
    const auto errors = group->runStep(allBodies(n), [&](std::size_t i) {
      const Eigen::VectorXd x = Eigen::VectorXd::Constant(3, static_cast<double>(i + step));
      views[i]->setPositions(x);
      views[i]->internalForces(f[i]);
    });
    for (std::size_t i = 0; i < n; ++i) {
      EXPECT_FALSE(errors[i]);
      EXPECT_EQ(f[i], (1.0 + static_cast<double>(i)) * Eigen::VectorXd::Constant(3, static_cast<double>(i + step)));
    }
    EXPECT_EQ(group->fiberWorkers(), 0u);
  }
  EXPECT_EQ(group->stats().rounds, 4);
}

TEST(BatchGroup, ABodyThatLeftTheGroupStepsBesideTheFibers) {
  // Body 0's view was replaced (it failed over): its calls never wait for a round, so it steps on a
  // thread of its own. Here it waits until the other three, fibers of the one fiber thread, have
  // made their calls: as a fiber of that thread it would keep them from running until its deadline.
  if (!detail::fibersAvailable()) GTEST_SKIP() << "no fibers in this build (AddressSanitizer or no ucontext)";
  Watchdog dog(60);
  const std::size_t n = 4;
  auto group = fakeGroup(n, {}, 1);
  std::vector<std::unique_ptr<Backend>> views = allViews(*group);
  views[0] = std::make_unique<FakeBackend>(1.0);  // as FailoverBackend replaces a view: body 0 leaves
  std::atomic<int> done{0};
  bool sawOthers = false;
  const auto errors = group->runStep(allBodies(n), [&](std::size_t i) {
    Eigen::VectorXd x = Eigen::VectorXd::Constant(3, static_cast<double>(i)), f;
    if (i == 0) {
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
      while (done.load() < 3 && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      sawOthers = done.load() == 3;
      views[0]->setPositions(x);
      return;
    }
    views[i]->setPositions(x);
    views[i]->internalForces(f);
    ++done;
  });
  for (const auto& e : errors) EXPECT_FALSE(e);
  EXPECT_TRUE(sawOthers) << "the other bodies did not step while body 0 stepped";
  EXPECT_EQ(group->stats().rounds, 2);
}

TEST(BatchGroup, FibersKeepTheirOwnCaughtExceptions) {
  // Eight bodies as fibers on one thread. Each throws its own exception and, inside the catch
  // block, calls its view (the fiber suspends there and the others run, throwing and catching
  // theirs), then rethrows with `throw;`: each must get its own exception back, and no exception
  // may count as uncaught. Each context keeps its own C++ exception globals (util/fiber.cpp); with
  // one set per thread, the rethrows take the wrong exceptions or terminate.
  if (!detail::fibersAvailable()) GTEST_SKIP() << "no fibers in this build (AddressSanitizer or no ucontext)";
  Watchdog dog(60);
  const std::size_t n = 8;
  auto group = fakeGroup(n, {}, 1);
  std::vector<std::unique_ptr<Backend>> views = allViews(*group);
  std::vector<int> rethrown(n, -1), uncaught(n, -1), rounds(n, 0);
  const auto errors = group->runStep(allBodies(n), [&](std::size_t i) {
    try {
      throw static_cast<int>(i);
    } catch (int) {
      for (std::size_t c = 0; c <= i % 3; ++c) {  // suspends, while the others throw and catch
        Eigen::VectorXd x = Eigen::VectorXd::Constant(3, static_cast<double>(i)), f;
        views[i]->setPositions(x);
        views[i]->internalForces(f);
        ++rounds[i];
      }
      uncaught[i] = std::uncaught_exceptions();
      try {
        throw;
      } catch (int k) {
        rethrown[i] = k;
      }
    }
    if (i % 2 == 1) throw std::runtime_error("body " + std::to_string(i));  // after the catch: a normal throw
  });
  ASSERT_EQ(errors.size(), n);
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(rethrown[i], static_cast<int>(i)) << "body " << i;
    EXPECT_EQ(uncaught[i], 0) << "body " << i;
    EXPECT_EQ(rounds[i], static_cast<int>(i % 3) + 1);
    EXPECT_EQ(static_cast<bool>(errors[i]), i % 2 == 1) << "body " << i;
  }
  EXPECT_EQ(std::uncaught_exceptions(), 0);
}

}  // namespace
}  // namespace corofem::test
