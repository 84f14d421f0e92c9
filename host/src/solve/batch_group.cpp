// BatchGroup, its views and its worker pool, and LoopBatchDevice (see batch_group.hpp, batch.hpp).
#include "solve/batch_group.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <utility>

namespace corofem::detail {

namespace {

// ------------------------------------------------------------------ LoopBatchDevice
/// A round as a loop over one Backend per body, in body order: bit-identical to separate runs.
class LoopBatchDevice final : public BatchDevice {
 public:
  explicit LoopBatchDevice(std::vector<std::unique_ptr<Backend>> backends) : backends_(std::move(backends)) {
    for (std::size_t i = 0; i < backends_.size(); ++i)
      if (!backends_[i]) fail(ErrorCode::Internal, "createLoopBatchDevice: backend ", i, " is null");
  }
  std::string name() const override { return backends_.empty() ? "loop" : backends_.front()->name(); }
  std::string deviceName() const override {
    return backends_.empty() ? "none" : backends_.front()->deviceName() + " (one backend per body)";
  }
  std::size_t bodyCount() const override { return backends_.size(); }

  void run(std::vector<BatchRequest*>& round) override {
    std::vector<BatchRequest*> ordered = round;
    std::stable_sort(ordered.begin(), ordered.end(), [](auto* a, auto* b) { return a->body < b->body; });
    for (BatchRequest* r : ordered) {
      try {
        if (r->body >= backends_.size())
          fail(ErrorCode::Internal, "batch request for body ", r->body, " of a batch of ", backends_.size());
        Backend& b = *backends_[r->body];
        switch (r->op) {
          case BatchOp::SetPositions: b.setPositions(*r->in); break;
          case BatchOp::InternalForces: b.internalForces(*r->out); break;
          case BatchOp::Apply: b.apply(r->coeffs, *r->in, *r->out); break;
          case BatchOp::Solve: r->stats = b.solve(r->coeffs, *r->in, *r->out); break;
          case BatchOp::ElasticEnergy: r->energy = b.elasticEnergy(); break;
        }
      } catch (...) {
        r->error = std::current_exception();
      }
    }
  }

 private:
  std::vector<std::unique_ptr<Backend>> backends_;
};

BatchDeviceFactory& testFactory() {
  static BatchDeviceFactory f;
  return f;
}

}  // namespace

std::unique_ptr<BatchDevice> createLoopBatchDevice(std::vector<std::unique_ptr<Backend>> backends) {
  return std::make_unique<LoopBatchDevice>(std::move(backends));
}

const char* batchCallName(std::size_t i) {
  static const char* const names[] = {"set_positions", "internal_forces", "apply", "solve", "elastic_energy", "mixed"};
  static_assert(static_cast<std::size_t>(BatchOp::ElasticEnergy) + 1 == BatchGroupStats::kMixedCalls,
                "one name per BatchOp, then mixed");
  return i <= BatchGroupStats::kMixedCalls ? names[i] : "unknown";
}

// ------------------------------------------------------------------ rendezvous
struct BatchGroup::Shared {
  enum class Phase { Out, Running, Waiting };
  struct Slot {
    bool attached = false;
    Phase phase = Phase::Out;
    BatchRequest* request = nullptr;  ///< posted, not yet taken by a round
    bool answered = false;            ///< the round that took the request has finished
  };

  std::unique_ptr<BatchDevice> device;
  mutable std::mutex m;
  std::condition_variable cv;
  std::vector<Slot> slots;
  std::size_t running = 0;  ///< Running bodies
  std::size_t waiting = 0;  ///< Waiting bodies whose request no round has taken yet
  bool roundBusy = false;   ///< a round is on the device
  BatchGroupStats stats;
  /// The end of the last round inside the step (the step's start before its first round).
  std::chrono::steady_clock::time_point lastRoundEnd;

  /// The device work of one round, outside the lock. A throw from run() fails every request.
  /// Returns the seconds spent in it.
  double execute(std::vector<BatchRequest*>& round) {
    const auto t0 = std::chrono::steady_clock::now();
    try {
      device->run(round);
    } catch (...) {
      const std::exception_ptr e = std::current_exception();
      for (BatchRequest* r : round) r->error = e;
    }
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }

  /// The byCall index of a round: its requests' call, or kMixedCalls.
  static std::size_t callIndex(const std::vector<BatchRequest*>& round) {
    const BatchOp op = round.front()->op;
    for (const BatchRequest* r : round)
      if (r->op != op) return BatchGroupStats::kMixedCalls;
    return static_cast<std::size_t>(op);
  }

  void count(std::size_t requests, double seconds) {
    stats.deviceSeconds += seconds;
    ++stats.rounds;
    stats.requests += static_cast<long long>(requests);
    stats.largestRound = std::max(stats.largestRound, requests);
  }

  /// A body stops taking part in the step (finished, threw, or its view went away).
  void leave(Slot& s) {
    if (s.phase != Phase::Running) return;
    s.phase = Phase::Out;
    --running;
    if (running == 0 && waiting > 0) cv.notify_all();
  }

  /// One Backend call of body `body`. Rethrows the request's error in the caller's thread.
  void call(std::size_t body, BatchRequest& req) {
    req.body = body;
    std::unique_lock<std::mutex> lk(m);
    Slot& s = slots[body];
    if (s.phase == Phase::Out) {
      // Outside a batched step: a round of one, after any round in progress.
      cv.wait(lk, [&] { return !roundBusy; });
      roundBusy = true;
      lk.unlock();
      std::vector<BatchRequest*> round{&req};
      const double seconds = execute(round);
      lk.lock();
      count(1, seconds);
      roundBusy = false;
      cv.notify_all();
    } else {
      // Inside the step: post, then wait for the round that answers it, or run it.
      s.request = &req;
      s.answered = false;
      s.phase = Phase::Waiting;
      --running;
      ++waiting;
      while (!s.answered) {
        if (running == 0 && !roundBusy && s.request) {
          // Every body still inside the step is Waiting: this thread runs the round for all.
          std::vector<std::size_t> taken;
          std::vector<BatchRequest*> round;
          for (std::size_t i = 0; i < slots.size(); ++i)
            if (slots[i].phase == Phase::Waiting && slots[i].request) {
              taken.push_back(i);
              round.push_back(slots[i].request);
              slots[i].request = nullptr;
            }
          waiting -= taken.size();
          roundBusy = true;
          lk.unlock();
          const auto start = std::chrono::steady_clock::now();
          const double seconds = execute(round);
          lk.lock();
          count(round.size(), seconds);
          BatchCallStats& call = stats.byCall[callIndex(round)];
          ++call.rounds;
          call.requests += static_cast<long long>(round.size());
          call.deviceSeconds += seconds;
          call.waitSeconds += std::chrono::duration<double>(start - lastRoundEnd).count();
          lastRoundEnd = std::chrono::steady_clock::now();
          // Answered bodies are Running again before anyone can start the next round, so that
          // round waits for their next calls.
          for (std::size_t i : taken) {
            slots[i].answered = true;
            slots[i].phase = Phase::Running;
            ++running;
          }
          roundBusy = false;
          // Woken after the unlock, the answered threads do not queue on the mutex at once (a
          // batch of 100 bodies on 2 cores spent 4 % of its samples in that contention).
          lk.unlock();
          cv.notify_all();
          lk.lock();
        } else {
          cv.wait(lk);
        }
      }
    }
    lk.unlock();
    if (req.error) std::rethrow_exception(req.error);
  }
};

namespace {

/// The Backend of one body of a group.
class BatchView final : public Backend {
 public:
  BatchView(std::shared_ptr<BatchGroup::Shared> shared, std::size_t body) : shared_(std::move(shared)), body_(body) {}
  ~BatchView() override {
    std::lock_guard<std::mutex> lk(shared_->m);
    BatchGroup::Shared::Slot& s = shared_->slots[body_];
    s.attached = false;
    shared_->leave(s);
  }
  std::string name() const override { return shared_->device->name(); }
  std::string deviceName() const override { return shared_->device->deviceName(); }

  void setPositions(const Eigen::VectorXd& x) override {
    BatchRequest r;
    r.op = BatchOp::SetPositions;
    r.in = &x;
    shared_->call(body_, r);
  }
  void internalForces(Eigen::VectorXd& f) override {
    BatchRequest r;
    r.op = BatchOp::InternalForces;
    r.out = &f;
    shared_->call(body_, r);
  }
  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) override {
    BatchRequest r;
    r.op = BatchOp::Apply;
    r.coeffs = c;
    r.in = &p;
    r.out = &y;
    shared_->call(body_, r);
  }
  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    BatchRequest r;
    r.op = BatchOp::Solve;
    r.coeffs = c;
    r.in = &b;
    r.out = &x;
    shared_->call(body_, r);
    return r.stats;
  }
  double elasticEnergy() override {
    BatchRequest r;
    r.op = BatchOp::ElasticEnergy;
    shared_->call(body_, r);
    return r.energy;
  }
  bool devicePositions(DevicePositions& out) const override { return shared_->device->devicePositions(body_, out); }

 private:
  std::shared_ptr<BatchGroup::Shared> shared_;
  std::size_t body_;
};

}  // namespace

// ------------------------------------------------------------------ worker pool
/// Persistent threads; a step hands out one task per body, each claimed by a different idle
/// thread. The pool grows to the largest step first seen, so every task of a step gets its own
/// thread (the tasks wait for each other in the rendezvous: two on one thread would deadlock).
struct BatchGroup::Pool {
  std::mutex m;
  std::condition_variable work, done;
  std::vector<std::thread> threads;
  std::size_t idle = 0;
  bool stop = false;
  std::function<void(std::size_t)> task;
  std::size_t tasks = 0, next = 0, remaining = 0;
  bool inStep = false;
  std::vector<std::exception_ptr> errors;  ///< per task of the step

  ~Pool() {
    {
      std::lock_guard<std::mutex> lk(m);
      stop = true;
    }
    work.notify_all();
    for (std::thread& t : threads) t.join();
  }

  void loop() {
    std::unique_lock<std::mutex> lk(m);
    for (;;) {
      ++idle;
      work.wait(lk, [&] { return stop || next < tasks; });
      --idle;
      if (stop) return;
      const std::size_t k = next++;
      lk.unlock();
      task(k);  // never throws: startStep wraps the body's step
      lk.lock();
      if (--remaining == 0) done.notify_all();
    }
  }
};

BatchGroup::BatchGroup(std::unique_ptr<BatchDevice> device)
    : shared_(std::make_shared<Shared>()), pool_(std::make_unique<Pool>()) {
  if (!device) fail(ErrorCode::Internal, "BatchGroup: no device");
  shared_->slots.resize(device->bodyCount());
  shared_->device = std::move(device);
}

BatchGroup::~BatchGroup() {
  if (pool_->inStep) finishStep();
}

std::size_t BatchGroup::bodyCount() const { return shared_->slots.size(); }
std::string BatchGroup::name() const { return shared_->device->name(); }
std::string BatchGroup::deviceName() const { return shared_->device->deviceName(); }
std::size_t BatchGroup::allocatedBytes() const { return shared_->device->allocatedBytes(); }
std::vector<DeviceBuffer> BatchGroup::deviceBuffers() const { return shared_->device->deviceBuffers(); }
BatchGroupStats BatchGroup::stats() const {
  std::lock_guard<std::mutex> lk(shared_->m);
  return shared_->stats;
}

std::unique_ptr<Backend> BatchGroup::view(std::size_t body) {
  std::lock_guard<std::mutex> lk(shared_->m);
  if (body >= shared_->slots.size())
    fail(ErrorCode::Internal, "BatchGroup::view: body ", body, " of a batch of ", shared_->slots.size());
  if (shared_->slots[body].attached) fail(ErrorCode::Internal, "BatchGroup::view: body ", body, " already has a view");
  shared_->slots[body].attached = true;
  return std::make_unique<BatchView>(shared_, body);
}

bool BatchGroup::devicePositions(std::size_t body, DevicePositions& out) const {
  return shared_->device->devicePositions(body, out);
}

bool BatchGroup::attached(std::size_t body) const {
  std::lock_guard<std::mutex> lk(shared_->m);
  return body < shared_->slots.size() && shared_->slots[body].attached;
}

void BatchGroup::startStep(const std::vector<std::size_t>& bodies, std::function<void(std::size_t)> step) {
  Pool& p = *pool_;
  if (p.inStep) fail(ErrorCode::Internal, "BatchGroup::startStep: the previous step was not finished");
  std::vector<char> seen(bodyCount(), 0);
  for (std::size_t b : bodies) {
    if (b >= bodyCount() || seen[b])
      fail(ErrorCode::Internal, "BatchGroup::startStep: body ", b, " is out of range or listed twice");
    seen[b] = 1;
  }
  std::unique_lock<std::mutex> lk(p.m);
  // Threads first: a failure to create one leaves no body marked as inside the step.
  while (p.threads.size() < bodies.size()) p.threads.emplace_back([&p] { p.loop(); });
  {
    // Every body enters before any runs: no round may start while one has yet to enter.
    std::lock_guard<std::mutex> g(shared_->m);
    shared_->lastRoundEnd = std::chrono::steady_clock::now();
    for (std::size_t b : bodies) {
      Shared::Slot& s = shared_->slots[b];
      if (s.attached && s.phase == Shared::Phase::Out) {
        s.phase = Shared::Phase::Running;
        ++shared_->running;
      }
    }
  }
  p.inStep = true;
  p.errors.assign(bodies.size(), nullptr);
  p.task = [&p, shared = shared_, bodies, step = std::move(step)](std::size_t k) {
    try {
      step(bodies[k]);
    } catch (...) {
      p.errors[k] = std::current_exception();
    }
    std::lock_guard<std::mutex> g(shared->m);
    shared->leave(shared->slots[bodies[k]]);
  };
  p.tasks = bodies.size();
  p.next = 0;
  p.remaining = bodies.size();
  // Woken after the unlock, the workers do not all queue on the pool's mutex at once: with 100
  // bodies on 2 cores a step of one call took 1.55-1.71 ms against 0.49-0.50 ms after
  // (bench_batch's BM_Rendezvous, a device that answers at once).
  lk.unlock();
  p.work.notify_all();
}

std::vector<std::exception_ptr> BatchGroup::finishStep() {
  Pool& p = *pool_;
  std::unique_lock<std::mutex> lk(p.m);
  if (!p.inStep) return {};
  p.done.wait(lk, [&] { return p.remaining == 0; });
  p.inStep = false;
  p.tasks = p.next = 0;
  p.task = nullptr;
  return std::move(p.errors);
}

std::vector<std::exception_ptr> BatchGroup::runStep(const std::vector<std::size_t>& bodies,
                                                    std::function<void(std::size_t)> step) {
  startStep(bodies, std::move(step));
  return finishStep();
}

// ------------------------------------------------------------------ factory
std::unique_ptr<BatchDevice> createBatchDeviceFor(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                                  const std::string& deviceSelector) {
  if (testFactory()) return testFactory()(problems, solver, deviceSelector);
  return createOpenCLBatchDevice(problems, solver, deviceSelector);
}

void setBatchDeviceFactoryForTesting(BatchDeviceFactory factory) { testFactory() = std::move(factory); }
bool batchDeviceFactoryForTesting() { return static_cast<bool>(testFactory()); }

}  // namespace corofem::detail
