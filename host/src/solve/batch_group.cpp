// BatchGroup, its views and its worker pool, and LoopBatchDevice (see batch_group.hpp, batch.hpp).
#include "solve/batch_group.hpp"

#include "util/error.hpp"
#include "util/fiber.hpp"
#include "util/parallel.hpp"

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
  /// The fiber workers (Pool) wait here for one of their fibers to be able to go on: notified with
  /// cv wherever a round ends or the running count drops to 0.
  std::condition_variable workers;
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
    if (running == 0 && waiting > 0) {
      cv.notify_all();
      workers.notify_all();
    }
  }

  /// Whether the body of `slot`, driven by a fiber that is not running, can go on (under m): it is
  /// not waiting for a round, or it is and may run that round (every body inside the step waits).
  bool canGoOn(std::size_t slot) const {
    const Slot& s = slots[slot];
    return s.phase != Phase::Waiting || s.answered || (running == 0 && !roundBusy && s.request);
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
      workers.notify_all();
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
          workers.notify_all();
          lk.lock();
        } else if (Fiber::inFiber()) {
          // Its worker thread runs its other bodies meanwhile (Pool::runFibers).
          lk.unlock();
          Fiber::suspend();
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
/// Persistent threads. With fibers (fiberWorkers > 0, the default where they are available) a step
/// hands each of up to fiberWorkers threads a share of the bodies, each body's step a fiber that
/// the thread resumes whenever it can go on (runFibers): a body waiting for a round gives the
/// thread to the next instead of sleeping in the kernel. Without, a step hands out one task per
/// body, each claimed by a different idle thread; the pool grows to the largest step first seen, so
/// every task of a step gets its own thread (the tasks wait for each other in the rendezvous: two
/// on one thread would deadlock).
struct BatchGroup::Pool {
  /// A fiber's stack: reserved, and committed only as far as it is used (a thread's default).
  static constexpr std::size_t kFiberStack = std::size_t{8} << 20;
  std::size_t fiberWorkers = 0;                ///< threads of a step's fibers; 0: a thread per body
  std::size_t fiberStack = kFiberStack;        ///< each fiber's stack
  std::vector<std::unique_ptr<Fiber>> fibers;  ///< fibers[k] drives the step's body k (kept between steps)

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

  /// Worker w of `workers`: the fibers of the step's bodies k = w, w + workers, ..., each resumed
  /// in turn whenever it can go on (Shared::canGoOn), until all have finished; the thread waits on
  /// shared.workers while none can.
  void runFibers(Shared& shared, std::size_t w, std::size_t workers, const std::vector<std::size_t>& bodies,
                 const std::vector<std::size_t>& tasks, const std::function<void(std::size_t)>& bodyTask) {
    // Tasks k = tasks[w], tasks[w + workers], ...: the bodies' indices in the step.
    std::vector<std::size_t> mine;
    for (std::size_t i = w; i < tasks.size(); i += workers) mine.push_back(tasks[i]);
    for (std::size_t k : mine) fibers[k]->start([&bodyTask, k] { bodyTask(k); });
    std::size_t left = mine.size(), at = 0;
    std::unique_lock<std::mutex> lk(shared.m);
    while (left > 0) {
      std::size_t pick = mine.size();
      for (std::size_t i = 0; i < mine.size() && pick == mine.size(); ++i) {
        const std::size_t j = (at + i) % mine.size();
        if (!fibers[mine[j]]->finished() && shared.canGoOn(bodies[mine[j]])) pick = j;
      }
      if (pick == mine.size()) {
        shared.workers.wait(lk);
        continue;
      }
      at = pick + 1;  // the others first next time: every body gets its turn
      Fiber& f = *fibers[mine[pick]];
      lk.unlock();
      try {
        f.resume();
      } catch (...) {
        // Its context could not be made (it never ran): the body's step fails and it leaves.
        errors[mine[pick]] = std::current_exception();
        std::lock_guard<std::mutex> g(shared.m);
        shared.leave(shared.slots[bodies[mine[pick]]]);
      }
      lk.lock();
      if (f.finished()) --left;
    }
  }
};

BatchGroup::BatchGroup(std::unique_ptr<BatchDevice> device)
    : shared_(std::make_shared<Shared>()), pool_(std::make_unique<Pool>()) {
  if (!device) fail(ErrorCode::Internal, "BatchGroup: no device");
  shared_->slots.resize(device->bodyCount());
  shared_->device = std::move(device);
  // A fiber worker per usable CPU; COROFEM_BATCH_FIBERS=0 gives each body a thread, =N N workers
  // (read once: a bad value is said once).
  static const std::size_t workers = threadCountFromEnv("COROFEM_BATCH_FIBERS", 0, 256, usableCpus(), "fiber threads");
  setFiberWorkers(workers);
}

void BatchGroup::setFiberWorkers(std::size_t workers, std::size_t stackBytes) {
  if (pool_->inStep) fail(ErrorCode::Internal, "BatchGroup::setFiberWorkers: inside a step");
  pool_->fiberWorkers = fibersAvailable() ? workers : 0;
  const std::size_t stack = stackBytes ? stackBytes : Pool::kFiberStack;
  if (stack != pool_->fiberStack) pool_->fibers.clear();  // made again with the new size
  pool_->fiberStack = stack;
}

std::size_t BatchGroup::fiberWorkers() const { return pool_->fiberWorkers; }

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
  // The bodies in the rendezvous (their view alive) run as fibers. A body whose view is gone (it
  // failed over) runs its step on a thread of its own: its calls never wait for a round, so as a
  // fiber it would keep its thread's other bodies, and every round, waiting for its whole step.
  std::vector<std::size_t> fiberTasks, threadTasks;
  {
    std::lock_guard<std::mutex> g(shared_->m);
    for (std::size_t k = 0; k < bodies.size(); ++k)
      (shared_->slots[bodies[k]].attached ? fiberTasks : threadTasks).push_back(k);
  }
  std::size_t workers = std::min(p.fiberWorkers, fiberTasks.size());
  std::unique_lock<std::mutex> lk(p.m);
  // Fiber stacks and threads first: a failure to create one leaves no body marked as inside the
  // step. Where the stacks cannot be mapped (a strict overcommit policy, an address-space limit),
  // the group gives each body a thread from then on, as without fibers.
  if (workers > 0) {
    try {
      while (p.fibers.size() < bodies.size()) p.fibers.push_back(std::make_unique<Fiber>(p.fiberStack));
    } catch (const Error&) {
      p.fibers.clear();
      p.fiberWorkers = workers = 0;
    }
  }
  if (workers == 0) {
    threadTasks.resize(bodies.size());
    for (std::size_t k = 0; k < bodies.size(); ++k) threadTasks[k] = k;
    fiberTasks.clear();
  }
  while (p.threads.size() < workers + threadTasks.size()) p.threads.emplace_back([&p] { p.loop(); });
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
  std::function<void(std::size_t)> bodyTask = [&p, shared = shared_, bodies, step = std::move(step)](std::size_t k) {
    try {
      step(bodies[k]);
    } catch (...) {
      p.errors[k] = std::current_exception();
    }
    std::lock_guard<std::mutex> g(shared->m);
    shared->leave(shared->slots[bodies[k]]);
  };
  // Tasks [0, workers): fiber threads; then a task per body on a thread of its own.
  p.task = [&p, shared = shared_, bodies, workers, fiberTasks, threadTasks,
            bodyTask = std::move(bodyTask)](std::size_t t) {
    if (t < workers) p.runFibers(*shared, t, workers, bodies, fiberTasks, bodyTask);
    else bodyTask(threadTasks[t - workers]);
  };
  p.tasks = workers + threadTasks.size();
  p.next = 0;
  p.remaining = p.tasks;
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
                                                  const std::string& deviceSelector, const OpenCLTuning& tuning) {
  if (testFactory()) return testFactory()(problems, solver, deviceSelector);
  return createOpenCLBatchDevice(problems, solver, deviceSelector, tuning);
}

void setBatchDeviceFactoryForTesting(BatchDeviceFactory factory) { testFactory() = std::move(factory); }
bool batchDeviceFactoryForTesting() { return static_cast<bool>(testFactory()); }

}  // namespace corofem::detail
