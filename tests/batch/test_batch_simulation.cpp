// Batching inside the Simulation: bodies scheduled on one device share its calls (one call per
// operation for the whole set, solve/driver.hpp), and nothing a user sees changes. On a fake
// batching backend of reference devices the answer must be bit-identical to the unbatched scene,
// step by step, with bodies of different sizes and materials, one whose step fails (the whole
// scene goes back), one that sleeps, and device failures that move the whole batch to the next
// candidate. With OpenCL the batched scene is compared with the same scene run with "batch": false.
#include "schedule/schedule_support.hpp"

#include "backends/reference/reference_device.hpp"
#include "output/run_outputs.hpp"
#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/segment_engine.hpp"
#endif
#include "util/error.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <mutex>
#include <thread>

namespace corofem::test {
namespace {

using nlohmann::json;

/// The number after `prefix` in a body name ("flaky12" -> 12), or 0 when the name lacks it.
int suffix(const std::string& name, const std::string& prefix) {
  if (name.rfind(prefix, 0) != 0 || name.size() == prefix.size()) return 0;
  return std::atoi(name.c_str() + prefix.size());
}

/// The solve at which a body's step fails: body "flaky" its 7th, "flakyN" its N-th; 0: never.
int flakyAt(const std::string& name) { return name == "flaky" ? 7 : suffix(name, "flaky"); }

/// Solves per body name over every device of one run (a body keeps its count when its device
/// fails over, as it would on one device).
struct SolveCounts {
  std::mutex m;
  std::map<std::string, int> n;
};

/// Returns NaN for a flaky body's solution at its failing solve: that body's step fails exactly as
/// a non-finite PCG would, whatever else shares the call.
class FlakyDevice final : public ForwardingDevice {
 public:
  FlakyDevice(std::unique_ptr<detail::Device> inner, std::shared_ptr<SolveCounts> counts)
      : ForwardingDevice(std::move(inner)), counts_(std::move(counts)) {}
  std::vector<detail::PcgStart> pcgBegin(const detail::BodySet& bodies, const std::vector<detail::SystemCoeffs>& c,
                                         const detail::ConstVectors& b, const detail::ConstVectors& x,
                                         double tolerance, int maxIterations) override {
    std::vector<detail::PcgStart> out = ForwardingDevice::pcgBegin(bodies, c, b, x, tolerance, maxIterations);
    poisoned_.assign(bodies.size(), 0);
    std::lock_guard<std::mutex> lock(counts_->m);
    for (std::size_t k = 0; k < bodies.size(); ++k) {
      const std::string& name = problem(bodies[k]).name;
      if (const int at = flakyAt(name); at > 0 && ++counts_->n[name] == at) poisoned_[k] = 1;
    }
    return out;
  }
  void pcgEnd(const std::vector<int>& it, const detail::Vectors& x, std::vector<detail::PcgScalars>& r) override {
    ForwardingDevice::pcgEnd(it, x, r);
    for (std::size_t k = 0; k < poisoned_.size(); ++k)
      if (poisoned_[k] && x[k]) x[k]->setConstant(std::numeric_limits<double>::quiet_NaN());
  }

 private:
  std::shared_ptr<SolveCounts> counts_;
  std::vector<char> poisoned_;
};

/// What a run's devices do: the batch device `lost` (a device fault of the whole set, from
/// common/device_fakes.hpp; none by default), and how many batch devices were made.
struct BatchFaults {
  FaultSpec lost{};
  std::atomic<int>* made = nullptr;
};

const detail::Candidate& batchCandidate() {
  static const detail::Candidate c = fakeCandidate("batchdev", "batchdev", "7");
  return c;
}

/// The backends of a run: "batchdev", a batching backend of reference devices (flaky bodies
/// flaky; a device of several bodies with `faults.lost` injected), and the reference backend with
/// the same flaky bodies, both counting solves in `counts`.
std::vector<detail::BackendEntry> backends(const BatchFaults& faults = {},
                                           std::shared_ptr<SolveCounts> counts = std::make_shared<SolveCounts>()) {
  auto make = [faults, counts](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                               const detail::Candidate& c) -> std::unique_ptr<detail::Device> {
    std::unique_ptr<detail::Device> d = std::make_unique<FlakyDevice>(detail::createReferenceDevice(problems, s), counts);
    if (c.backend != "batchdev" || problems.size() < 2) return d;
    EXPECT_EQ(c.selector, "7");
    if (faults.made) ++*faults.made;
    return faults.lost.kind == FaultKind::None ? std::move(d) : injectFaults(std::move(d), faults.lost);
  };
  detail::BackendEntry reference = *detail::findBackend("reference");
  reference.create = [make](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                            const detail::Candidate& c, const detail::DeviceOptions&) { return make(problems, s, c); };
  return {fakeBackend("batchdev", {batchCandidate()}, make, /*batches=*/true), reference};
}

/// Every body on "batchdev" first (no calibration), the reference backend next.
SimulationOptions onBatchDevice() {
  SimulationOptions o;
  o.devices = {"batchdev"};
  return o;
}

/// Five bodies of different sizes, materials and formulations; "flaky" fails one step, "quiet"
/// (clamped, unloaded) falls asleep, "damped" needs the damping product.
Scene fiveBodies(int steps, bool withFlaky = true) {
  Scene s = dynamicScene(boxBeam({10, 2, 2}), steps);
  s.bodies[0].name = "a";
  BodyDesc damped = boxBeam({6, 3, 2});
  damped.name = "damped";
  damped.material.youngsModulus = 3e6;
  damped.material.density = 800;
  damped.material.rayleighMass = 2.0;
  damped.material.rayleighStiffness = 1e-3;
  BodyDesc flaky = boxBeam({8, 2, 2});
  flaky.name = withFlaky ? "flaky" : "steady";
  flaky.material.youngsModulus = 2e6;
  BodyDesc quiet = boxBeam({5, 2, 2});
  quiet.name = "quiet";
  quiet.loads.clear();
  BodyDesc linear = boxBeam({12, 2, 2});
  linear.name = "linear";
  linear.formulation = Formulation::Linear;
  linear.material.poissonRatio = 0.45;
  for (BodyDesc* b : {&damped, &flaky, &quiet, &linear}) s.bodies.push_back(*b);
  s.analysis.dynamics.sleep.enabled = true;
  s.analysis.dynamics.sleep.steps = 3;
  return s;
}

struct Trace {
  std::vector<std::string> statuses;         ///< per step() call: "" or the message
  std::vector<StepReport> reports;
  std::vector<std::vector<double>> states;   ///< per call: every body's x and v, then energies
  json scheduler;
};

/// Calls step() until the analysis is finished (at most 2 x steps calls), recording everything.
Trace run(const Scene& scene, const SimulationOptions& options = {}) {
  Trace t;
  auto sim = Simulation::create(scene, options);
  EXPECT_TRUE(sim) << sim.message();
  if (!sim) return t;
  for (int call = 0; call < 2 * sim->stepCount() && !sim->finished(); ++call) {
    StepReport r;
    const Status st = sim->step(&r);
    // The message names the device the solve failed on: the same but for a fault injected in it.
    std::string message = st ? "" : st.message();
    for (std::size_t at; (at = message.find(" [faulty]")) != std::string::npos;) message.erase(at, 9);
    t.statuses.push_back(message);
    r.wallSeconds = 0;
    t.reports.push_back(r);
    std::vector<double> all;
    for (int b = 0; b < sim->bodyCount(); ++b) {
      std::vector<double> x, v;
      EXPECT_TRUE(sim->readPositions(b, x));
      EXPECT_TRUE(sim->readVelocities(b, v));
      all.insert(all.end(), x.begin(), x.end());
      all.insert(all.end(), v.begin(), v.end());
      const EnergyReport e = sim->energies(b);  // outside a step: a round of one on the batch
      all.insert(all.end(), {e.elastic, e.kinetic, e.externalWork});
    }
    t.states.push_back(std::move(all));
  }
  EXPECT_TRUE(sim->finished());
  t.scheduler = json::parse(sim->schedulerReport());
  return t;
}

void expectSameRun(const Trace& batched, const Trace& alone) {
  ASSERT_EQ(batched.statuses, alone.statuses);
  ASSERT_EQ(batched.states.size(), alone.states.size());
  for (std::size_t k = 0; k < alone.states.size(); ++k) {
    SCOPED_TRACE("step() call " + std::to_string(k + 1));
    const StepReport &a = batched.reports[k], &b = alone.reports[k];
    EXPECT_EQ(a.step, b.step);
    EXPECT_EQ(a.time, b.time);
    EXPECT_EQ(a.newtonIterations, b.newtonIterations);
    EXPECT_EQ(a.linearIterations, b.linearIterations);
    EXPECT_EQ(a.residual, b.residual);
    EXPECT_EQ(a.linearResidual, b.linearResidual);
    EXPECT_EQ(a.converged, b.converged);
    // Bit-identical: every body's call sequence is the same and each is answered by a reference
    // backend of its own in both runs.
    EXPECT_TRUE(batched.states[k] == alone.states[k]) << "positions, velocities or energies differ";
  }
}

Trace unbatched(Scene scene) {
  HookScope scope(backends());
  scene.backend.batch = false;
  return run(scene, onBatchDevice());
}

TEST(BatchSimulation, BatchIsBitIdenticalWithAFailingAndASleepingBody) {
  const Scene scene = fiveBodies(16);
  const Trace alone = unbatched(scene);
  std::atomic<int> made{0};
  HookScope scope(backends({{}, &made}));
  const Trace batched = run(scene, onBatchDevice());
  EXPECT_EQ(made.load(), 1);
  expectSameRun(batched, alone);

  // The flaky body failed one step: the scene repeated it, and the message names that body.
  int failures = 0;
  for (const std::string& s : batched.statuses)
    if (!s.empty()) {
      ++failures;
      EXPECT_NE(s.find("body 'flaky'"), std::string::npos) << s;
    }
  EXPECT_EQ(failures, 1);
  // The summary: one batch of all five bodies, calls that held all of them, the quiet body asleep.
  const json& sched = batched.scheduler;
  ASSERT_EQ(sched["batches"].size(), 1u) << sched.dump(1);
  EXPECT_EQ(sched["batches"][0]["bodies"], json({"a", "damped", "flaky", "quiet", "linear"}));
  EXPECT_EQ(sched["batches"][0]["largest_round"], 5);
  EXPECT_GT(sched["batches"][0]["rounds"].get<long long>(), 0);
  for (const json& b : sched["bodies"]) {
    EXPECT_EQ(b["batch"]["group"], 0) << b.dump();
    EXPECT_EQ(b["batch"]["active"], true) << b.dump();
  }
  EXPECT_TRUE(sched["bodies"][3]["sleep"]["asleep"].get<bool>()) << sched["bodies"][3].dump();
  EXPECT_GT(sched["bodies"][3]["sleep"]["slept_steps"].get<long long>(), 0);
  EXPECT_TRUE(alone.scheduler["batches"].empty());
  EXPECT_TRUE(alone.scheduler["bodies"][0]["batch"].is_null());
}

TEST(BatchSimulation, TheReferenceBackendBatchesItsBodiesBitForBitAndLeavesHyperelasticOnesAlone) {
  // The reference backend batches: one call per operation for the set, its bodies across the
  // host's threads. The same bits as every body alone; a Neo-Hookean body (whose inverted element
  // would fail its whole call) runs alone.
  Scene scene = fiveBodies(10, /*withFlaky=*/false);
  BodyDesc rubber = boxBeam({6, 2, 2});
  rubber.name = "rubber";
  rubber.formulation = Formulation::NeoHookean;
  scene.bodies.push_back(rubber);
  scene.backend.kind = BackendKind::Reference;
  const Trace batched = run(scene);
  Scene apart = scene;
  apart.backend.batch = false;
  const Trace alone = run(apart);
  expectSameRun(batched, alone);
  ASSERT_EQ(batched.scheduler["batches"].size(), 1u) << batched.scheduler.dump(1);
  const json& batch = batched.scheduler["batches"][0];
  EXPECT_EQ(batch["backend"], "reference");
  EXPECT_EQ(batch["bodies"], json({"a", "damped", "steady", "quiet", "linear"}));
  EXPECT_TRUE(alone.scheduler["batches"].empty());
}

/// Refuses body "refuser"'s state in the forces' call (Error(SolveFailed) naming it, whatever else
/// the call holds) at its 4th and 5th calls: a device that fails one body's call, as the reference
/// device does for an inverted Neo-Hookean element.
class RefusingDevice final : public ForwardingDevice {
 public:
  explicit RefusingDevice(std::unique_ptr<detail::Device> inner) : ForwardingDevice(std::move(inner)) {}
  void internalForces(const detail::BodySet& bodies, const detail::Vectors& f) override {
    for (std::size_t b : bodies)
      if (problem(b).name == "refuser" && ++calls_ >= 4 && calls_ <= 5)
        detail::fail(ErrorCode::SolveFailed, "body 'refuser': its state is refused");
    ForwardingDevice::internalForces(bodies, f);
  }

 private:
  int calls_ = 0;
};

TEST(BatchSimulation, ABodyWhoseCallFailsInItsBatchFailsAloneAndTheStatusNamesIt) {
  // The call fails for the whole batch; the driver repeats it body by body to find whose failure it
  // is. Before, every body of the call failed with the refuser's error, and the status named the
  // first of them in scene order ("a").
  Scene scene = fiveBodies(8, /*withFlaky=*/false);
  BodyDesc refuser = boxBeam({7, 2, 2});
  refuser.name = "refuser";
  scene.bodies.push_back(refuser);
  auto make = [](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                 const detail::Candidate&) -> std::unique_ptr<detail::Device> {
    return std::make_unique<RefusingDevice>(detail::createReferenceDevice(problems, s));
  };
  HookScope scope({fakeBackend("batchdev", {batchCandidate()}, make, /*batches=*/true), *detail::findBackend("reference")});
  auto sim = Simulation::create(scene, onBatchDevice());
  ASSERT_TRUE(sim) << sim.message();
  ASSERT_EQ(json::parse(sim->schedulerReport())["batches"][0]["bodies"].size(), 6u);
  std::string failure;
  for (int k = 0; k < 8 && failure.empty(); ++k)
    if (const Status st = sim->step(); !st) failure = st.message();
  ASSERT_FALSE(failure.empty()) << "the refused step did not fail";
  EXPECT_EQ(failure.rfind("body 'refuser'", 0), 0u) << failure;
  EXPECT_NE(failure.find("its state is refused"), std::string::npos) << failure;
  // The scene goes on from the last step every body completed.
  const Status next = sim->step();
  EXPECT_TRUE(next) << next.message();
}

TEST(BatchSimulation, DeviceCallsPerStepDoNotGrowWithTheBodies) {
  // Copies of one beam (same mesh, material and loads, side by side) take the same iterations, so
  // a batch of any number of them makes the same device calls per step, each holding all of them:
  // what batching is for. A loop over the bodies would make n times as many.
  std::vector<long long> rounds;
  for (int n : {2, 3, 6}) {
    SCOPED_TRACE(std::to_string(n) + " bodies");
    Scene scene = dynamicScene(boxBeam({8, 2, 2}), 4);
    scene.bodies.clear();
    for (int i = 0; i < n; ++i) {
      BodyDesc b = boxBeam({8, 2, 2});
      b.name = "copy" + std::to_string(i);
      b.mesh.translate = {0.0, 0.0, 0.3 * i};
      scene.bodies.push_back(b);
    }
    HookScope scope(backends());
    auto sim = Simulation::create(scene, onBatchDevice());
    ASSERT_TRUE(sim) << sim.message();
    while (!sim->finished()) ASSERT_TRUE(sim->step());
    const json batch = json::parse(sim->schedulerReport())["batches"].at(0);
    EXPECT_EQ(batch["largest_round"], n);
    EXPECT_EQ(batch["requests"].get<long long>(), n * batch["rounds"].get<long long>()) << batch.dump(1);
    for (const auto& c : batch["rounds_by_call"].items())
      EXPECT_EQ(c.value()["requests"].get<long long>(), n * c.value()["rounds"].get<long long>()) << c.key();
    rounds.push_back(batch["rounds"].get<long long>());
  }
  EXPECT_EQ(rounds[0], rounds[1]);
  EXPECT_EQ(rounds[0], rounds[2]);
}

/// Depth of the test runner's tasks on the calling thread.
int& taskDepth() {
  thread_local int depth = 0;
  return depth;
}

/// A body of 35,547 dofs (40 x 16 x 16 cells: its per-dof passes in three chunks of the host's
/// threads) and a small one, 3 dynamic steps.
Scene largeAndSmall() {
  BodyDesc big = boxBeam({40, 16, 16});
  big.mesh.box->max = {1.0, 0.25, 0.25};
  Scene scene = dynamicScene(big, 3);
  BodyDesc small = boxBeam({6, 2, 2});
  small.name = "small";
  scene.bodies.push_back(small);
  return scene;
}

TEST(BatchSimulation, ALargeBodysChunkedPassesRunInsideTheBatchsTasksWithTheirBits) {
  // A body of 35,547 dofs (its per-dof passes in three chunks of the host's threads) batched with
  // a small one: the driver's pass over the batch's bodies runs each body's chunked passes inside
  // one of its tasks. They run on that task's thread, never calling the application's runner from
  // inside one of its tasks (nor taking the library's pool, which the pass's caller holds), with
  // the bits of the unbatched scene, on the library's pool and on the application's runner.
  Scene scene = largeAndSmall();
  scene.solver.linearSolver = LinearSolverKind::Pcg;
  scene.solver.tolerance = 1e-8;
  scene.solver.maxIterations = 40;
  const Trace alone = unbatched(scene);
  std::atomic<long long> calls{0}, reentrant{0};
  SimulationOptions withTasks = onBatchDevice();
  withTasks.tasks = [&](std::size_t count, const std::function<void(std::size_t)>& task) {
    ++calls;
    if (taskDepth() > 0) ++reentrant;
    auto one = [&](std::size_t i) {
      ++taskDepth();
      task(i);
      --taskDepth();
    };
    std::thread other([&] {
      for (std::size_t i = count; i-- > count / 2;) one(i);
    });
    for (std::size_t i = count / 2; i-- > 0;) one(i);
    other.join();
  };
  std::atomic<int> made{0};
  HookScope scope(backends({{}, &made}));
  expectSameRun(run(scene, onBatchDevice()), alone);
  expectSameRun(run(scene, withTasks), alone);
  EXPECT_EQ(made.load(), 2) << "the two bodies were not batched";
  EXPECT_GT(calls.load(), 0);
  EXPECT_EQ(reentrant.load(), 0) << "the runner was called from inside one of its own tasks";
}

TEST(BatchSimulation, RemovingABodyFromABatchRunsTheNewDevicesSetUpOnTheApplicationsTasks) {
  // Removing the small body of a batch makes the batch's device again for the large one (the test
  // device cannot remove a body in place): the positions it is given (its rotations) run in chunks
  // of the host's threads, on the application's runner as every other call's do, then the large
  // body steps on.
  Scene scene = largeAndSmall();
  std::atomic<long long> calls{0};
  SimulationOptions o = onBatchDevice();
  o.tasks = [&](std::size_t count, const std::function<void(std::size_t)>& task) {
    ++calls;
    for (std::size_t i = 0; i < count; ++i) task(i);
  };
  std::atomic<int> made{0};
  HookScope scope(backends({{}, &made}));
  auto sim = Simulation::create(scene, o);
  ASSERT_TRUE(sim) << sim.message();
  EXPECT_EQ(made.load(), 1) << "the two bodies were not batched";
  ASSERT_TRUE(sim->step());  // the slot now gives a new device the positions it knows
  calls = 0;
  ASSERT_TRUE(sim->removeBody(1));
  EXPECT_GT(calls.load(), 0) << "the new device's set-up did not run on the application's tasks";
  ASSERT_EQ(sim->bodyCount(), 1);
  EXPECT_TRUE(sim->step());
}

TEST(BatchSimulation, AnApplicationsTaskRunnerRunsTheHostWork) {
  // SimulationOptions::tasks: the per-body host work of the batch runs on the application's tasks
  // (here half on the calling thread, backwards, half on a thread of the application's), with the
  // answer of the library's own pool bit for bit.
  const Scene scene = fiveBodies(8);
  Trace plain, withTasks;
  {
    HookScope scope(backends());
    plain = run(scene, onBatchDevice());
  }
  std::atomic<long long> calls{0}, tasks{0};
  SimulationOptions o = onBatchDevice();
  o.tasks = [&](std::size_t count, const std::function<void(std::size_t)>& task) {
    ++calls;
    tasks += static_cast<long long>(count);
    std::thread other([&] {
      for (std::size_t i = count / 2; i < count; ++i) task(i);
    });
    for (std::size_t i = count / 2; i-- > 0;) task(i);
    other.join();
  };
  {
    HookScope scope(backends());
    withTasks = run(scene, o);
  }
  expectSameRun(withTasks, plain);
  EXPECT_GT(calls.load(), 0) << "the batch's host work did not reach the application's tasks";
  EXPECT_GE(tasks.load(), 2 * calls.load()) << "a call of one task runs on the caller, without the runner";
}

TEST(BatchSimulation, StaticFailureRollsEveryBatchedBodyBack) {
  // Statics: body "hard" cannot converge in 2 Newton iterations; every batched body stays at the
  // rest state and the status names "hard", as without batching.
  Scene scene = staticScene(boxBeam({10, 2, 2}), 2);
  scene.bodies[0].name = "easy";
  scene.bodies[0].formulation = Formulation::Linear;  // linear bodies converge in one iteration
  BodyDesc hard = boxBeam({10, 2, 2});
  hard.name = "hard";
  hard.loads.back().vector = {0, 0, -400.0};
  scene.bodies.push_back(hard);
  BodyDesc other = boxBeam({6, 2, 2});
  other.name = "other";
  other.formulation = Formulation::Linear;
  scene.bodies.push_back(other);
  scene.analysis.statics.maxNewtonIterations = 2;
  scene.analysis.statics.residualTolerance = 1e-10;
  std::string aloneMessage;
  {
    HookScope scope(backends());
    Scene off = scene;
    off.backend.batch = false;
    auto sim = Simulation::create(off, onBatchDevice());
    ASSERT_TRUE(sim) << sim.message();
    const Status st = sim->step();
    ASSERT_FALSE(st) << "the scene was meant to fail its first increment";
    aloneMessage = st.message();
  }
  std::atomic<int> made{0};
  HookScope scope(backends({{}, &made}));
  auto sim = Simulation::create(scene, onBatchDevice());
  ASSERT_TRUE(sim) << sim.message();
  EXPECT_EQ(made.load(), 1);
  const Status st = sim->step();
  ASSERT_FALSE(st);
  EXPECT_EQ(st.code(), ErrorCode::SolveFailed);
  EXPECT_EQ(st.message(), aloneMessage);
  EXPECT_NE(st.message().find("body 'hard'"), std::string::npos) << st.message();
  EXPECT_EQ(sim->stepsTaken(), 0);
  for (int b = 0; b < sim->bodyCount(); ++b) {
    std::vector<double> x;
    ASSERT_TRUE(sim->readPositions(b, x));
    EXPECT_EQ(x, sim->restMesh(b).nodes) << "body " << b << " was not rolled back";
  }
}

TEST(BatchSimulation, AFailingDeviceMovesTheWholeBatchToItsNextCandidate) {
  // The batch's device fails (a launch in its 5th solve, an allocation at its 30th call, a
  // read-back of forces at its 12th): every body of the batch carries on on the reference backend
  // from where it was, bit-identical to the run that never failed (reference devices both; the
  // flaky body keeps its solve count across the move, so it fails the same step).
  const Scene scene = fiveBodies(10);
  const Trace alone = unbatched(scene);
  for (const FaultSpec lost : {FaultSpec{FaultKind::Launch, 5}, FaultSpec{FaultKind::Allocation, 30},
                               FaultSpec{FaultKind::ReadBack, 12}}) {
    SCOPED_TRACE(toString(lost.kind));
    HookScope scope(backends({lost}));
    const Trace batched = run(scene, onBatchDevice());
    expectSameRun(batched, alone);
    const json& sched = batched.scheduler;
    ASSERT_EQ(sched["fallbacks"].size(), 5u) << sched.dump(1);
    for (const json& e : sched["fallbacks"]) {
      EXPECT_EQ(e["from"], batchCandidate().label());
      EXPECT_EQ(e["to"], "reference");
      EXPECT_NE(e["error"].get<std::string>().find("injected"), std::string::npos) << e.dump();
    }
    EXPECT_TRUE(sched["batches"][0]["active_bodies"].empty()) << sched.dump(1);
    for (const json& b : sched["bodies"]) {
      EXPECT_EQ(b["batch"]["active"], false) << b.dump();
      EXPECT_EQ(b["current"], "reference") << b.dump();
    }
  }
}

TEST(BatchSimulation, BatchOffAndSingleBodiesStayUnbatchedSurfacesJoin) {
  std::atomic<int> made{0};
  HookScope scope(backends({{}, &made}));
  {
    Scene one = dynamicScene(boxBeam(), 2);  // a single body: nothing to share
    auto sim = Simulation::create(one, onBatchDevice());
    ASSERT_TRUE(sim) << sim.message();
    EXPECT_TRUE(json::parse(sim->schedulerReport())["batches"].empty());
  }
  {
    Scene off = fiveBodies(2);
    off.backend.batch = false;
    auto sim = Simulation::create(off, onBatchDevice());
    ASSERT_TRUE(sim) << sim.message();
    EXPECT_TRUE(json::parse(sim->schedulerReport())["batches"].empty());
    const json plan = json::parse(sim->planReport());
    EXPECT_EQ(plan["bodies"][0]["features"]["shared_launches"], false);
  }
  EXPECT_EQ(made.load(), 0);
  {
    // A body with a render surface joins the batch like any other (on an OpenCL batch its surface
    // reads its nodes in the shared position buffer; these reference devices keep positions on
    // the host, so the surface is computed there, and the plan says so).
    const std::string obj = (tempDir() / "batch_surface.obj").string();
    std::ofstream(obj) << "v 0.5 0.05 0.05\nv 0.6 0.05 0.05\nv 0.5 0.06 0.05\nf 1 2 3\n";
    Scene withSurface = fiveBodies(2);
    withSurface.bodies[0].surface = obj;
    auto sim = Simulation::create(withSurface, onBatchDevice());
    ASSERT_TRUE(sim) << sim.message();
    const json sched = json::parse(sim->schedulerReport());
    ASSERT_EQ(sched["batches"].size(), 1u);
    EXPECT_EQ(sched["batches"][0]["bodies"], json({"a", "damped", "flaky", "quiet", "linear"}));
    EXPECT_FALSE(sched["bodies"][0]["batch"].is_null());
    EXPECT_EQ(made.load(), 1);
    EXPECT_FALSE(sim->surfaceBuffer(0));
    EXPECT_EQ(json::parse(sim->planReport())["bodies"][0]["surface"]["where"], "host");
    ASSERT_TRUE(sim->step());
    std::vector<double> positions;
    EXPECT_TRUE(sim->readSurface(0, positions));
    EXPECT_EQ(positions.size(), 9u);
  }
  {
    // Plan of a batched scene: every body says which bodies share its launches.
    auto sim = Simulation::create(fiveBodies(2), onBatchDevice());
    ASSERT_TRUE(sim) << sim.message();
    const json plan = json::parse(sim->planReport());
    ASSERT_EQ(plan["batches"].size(), 1u);
    for (const json& b : plan["bodies"]) {
      EXPECT_EQ(b["shared_launches"], json({"a", "damped", "flaky", "quiet", "linear"})) << b.dump();
      EXPECT_NE(b["features"]["shared_launches"].get<std::string>().find("5 bodies"), std::string::npos);
    }
  }
}

TEST(BatchSimulation, SummaryJsonListsTheBatch) {
  HookScope scope(backends());
  Scene scene = fiveBodies(3);
  auto sim = Simulation::create(scene, onBatchDevice());
  ASSERT_TRUE(sim) << sim.message();
  const std::string dir = (tempDir() / "batch_summary").string();
  detail::RunOutputs out(sim.value(), dir);
  while (!sim->finished()) {
    StepReport r;
    const Status st = sim->step(&r);
    out.record(sim.value(), r);
  }
  out.finish(sim.value(), Status(), 0.0);
  std::ifstream in(dir + "/summary.json");
  ASSERT_TRUE(in);
  const json summary = json::parse(in);
  ASSERT_EQ(summary["scheduler"]["batches"].size(), 1u) << summary["scheduler"].dump(1);
  EXPECT_EQ(summary["scheduler"]["batches"][0]["bodies"].size(), 5u);
  // The device calls inside the steps by operation ("rounds": calls; "requests": bodies in them).
  const json& byCall = summary.at("scheduler").at("batches").at(0).at("rounds_by_call");
  ASSERT_FALSE(byCall.empty()) << summary["scheduler"].dump(1);
  const std::vector<std::string> names{"set_positions", "internal_forces", "apply", "solve", "elastic_energy"};
  for (const auto& c : byCall.items()) {
    EXPECT_NE(std::find(names.begin(), names.end(), c.key()), names.end()) << c.key();
    EXPECT_GT(c.value()["rounds"].get<long long>(), 0) << c.key();
    EXPECT_GE(c.value()["requests"].get<long long>(), c.value()["rounds"].get<long long>()) << c.key();
    EXPECT_GE(c.value()["wait_seconds"].get<double>(), 0.0) << c.key();
    EXPECT_GE(c.value()["device_seconds"].get<double>(), 0.0) << c.key();
  }
  long long inSteps = 0;
  for (const auto& c : byCall.items()) inSteps += c.value()["rounds"].get<long long>();
  EXPECT_LE(inSteps, summary["scheduler"]["batches"][0]["rounds"].get<long long>());
}

TEST(BatchSimulation, SceneKeyBackendBatch) {
  // "backend": {"batch": false} switches batching off; the default is on; a non-boolean is refused.
  const std::string base = R"({"bodies": [{"mesh": {"box": {}}}], "backend": )";
  Result<Scene> on = parseScene(base + R"({"kind": "opencl"}})", ".");
  ASSERT_TRUE(on) << on.message();
  EXPECT_TRUE(on->backend.batch);
  Result<Scene> off = parseScene(base + R"({"kind": "opencl", "batch": false}})", ".");
  ASSERT_TRUE(off) << off.message();
  EXPECT_FALSE(off->backend.batch);
  Result<Scene> set = parseScene(base + R"("opencl"})", ".", {"backend.batch=false"});
  ASSERT_TRUE(set) << set.message();
  EXPECT_FALSE(set->backend.batch);
  Result<Scene> bad = parseScene(base + R"({"batch": "no"}})", ".");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("backend.batch"), std::string::npos) << bad.message();
}

TEST(BatchSimulation, StressManyBodiesFailingSleepingAndFailingOver) {
  // 40 small bodies of 8 sizes and 40 materials, 30 steps, sleep on: every fifth fails one step
  // (at a different solve each), three are unloaded and fall asleep, and the batch's device fails
  // at its 60th solve, moving all 40 to the reference backend mid-run. Step by step bit-identical
  // to the same scene unbatched; the failed steps are repeated by the loop in run().
  Scene scene = dynamicScene(boxBeam({4, 1, 1}), 30);
  scene.bodies.clear();
  for (int i = 0; i < 40; ++i) {
    BodyDesc b = boxBeam({3 + i % 8, 1 + i % 2, 1});
    b.name = i % 5 == 1 ? "flaky" + std::to_string(3 + 2 * i) : "b" + std::to_string(i);
    b.material.youngsModulus = 5e5 * (1 + i % 9);
    b.material.density = 700 + 17 * i;
    b.material.rayleighMass = i % 4 == 0 ? 1.5 : 0.0;
    b.mesh.translate = {0, 0, 0.3 * i};
    if (i % 13 == 3) b.loads.clear();  // at rest: falls asleep
    scene.bodies.push_back(b);
  }
  scene.analysis.dynamics.sleep.enabled = true;
  scene.analysis.dynamics.sleep.steps = 2;
  const Trace alone = unbatched(scene);
  HookScope scope(backends({{FaultKind::Launch, 60}}));
  const Trace batched = run(scene, onBatchDevice());
  expectSameRun(batched, alone);
  int failures = 0;
  for (const std::string& st : batched.statuses) failures += st.empty() ? 0 : 1;
  EXPECT_GE(failures, 4) << "the flaky bodies were meant to fail steps";
  EXPECT_EQ(batched.scheduler["fallbacks"].size(), 40u) << batched.scheduler["fallbacks"].dump(1);
  EXPECT_TRUE(batched.scheduler["batches"][0]["active_bodies"].empty());
  EXPECT_EQ(batched.scheduler["batches"][0]["largest_round"], 40);
}

// ------------------------------------------------------------------ OpenCL
bool haveOpenCLDevice() {
  for (const detail::Candidate& c : detail::listCandidates())
    if (c.backend == "opencl") return true;
  return false;
}

/// Four bodies of different sizes and materials on the OpenCL device, explicitly.
Scene openclScene(Precision precision, int steps) {
  Scene s = dynamicScene(boxBeam({10, 2, 2}), steps);
  s.bodies[0].name = "b0";
  for (int i = 1; i < 4; ++i) {
    BodyDesc b = boxBeam({6 + 3 * i, 2 + i % 2, 2});
    b.name = "b" + std::to_string(i);
    b.material.youngsModulus = 1e6 * (1 + i);
    b.material.rayleighMass = i == 2 ? 1.0 : 0.0;
    s.bodies.push_back(b);
  }
  s.backend.kind = BackendKind::OpenCL;
  s.solver.precision = precision;
  s.solver.tolerance = precision == Precision::Float ? 1e-5 : 1e-10;
  return s;
}

TEST(BatchSimulation, OpenCLBatchAgreesWithUnbatchedBodies) {
#ifndef COROFEM_WITH_OPENCL
  GTEST_SKIP() << "built without COROFEM_WITH_OPENCL";
#else
  if (!haveOpenCLDevice()) GTEST_SKIP() << "no OpenCL device on this machine";
  for (Precision precision : {Precision::Double, Precision::Float}) {
    SCOPED_TRACE(toString(precision));
    HookScope scope;
    const int steps = 12;
    Scene scene = openclScene(precision, steps);
    auto batched = Simulation::create(scene);
    ASSERT_TRUE(batched) << batched.message();
    const json sched = json::parse(batched->schedulerReport());
    if (sched["batches"].empty()) {
      // The device could not batch these bodies (e.g. no fp64 for double): the reason is reported.
      ASSERT_FALSE(sched["unbatched"].empty()) << sched.dump(1);
      std::cout << "[ note ] " << toString(precision) << ": unbatched: " << sched["unbatched"][0]["reason"] << "\n";
      continue;
    }
    EXPECT_EQ(sched["batches"][0]["bodies"], json({"b0", "b1", "b2", "b3"})) << sched.dump(1);
    EXPECT_EQ(sched["batches"][0]["backend"], "opencl");
    EXPECT_GT(sched["batches"][0]["allocated_bytes"].get<long long>(), 0);
    scene.backend.batch = false;
    auto alone = Simulation::create(scene);
    ASSERT_TRUE(alone) << alone.message();
    EXPECT_TRUE(json::parse(alone->schedulerReport())["batches"].empty());
    EXPECT_EQ(alone->backendName(), "opencl");
    double worst = 0;  // largest difference relative to the displacement, for the log
    for (int k = 0; k < steps; ++k) {
      StepReport rb, ra;
      ASSERT_TRUE(batched->step(&rb)) << "step " << k + 1;
      ASSERT_TRUE(alone->step(&ra)) << "step " << k + 1;
      for (int b = 0; b < 4; ++b) {
        std::vector<double> xb, xa, x0 = batched->restMesh(b).nodes;
        ASSERT_TRUE(batched->readPositions(b, xb));
        ASSERT_TRUE(alone->readPositions(b, xa));
        double diff = 0, disp = 0;
        for (std::size_t i = 0; i < xa.size(); ++i) {
          diff = std::max(diff, std::abs(xb[i] - xa[i]));
          disp = std::max(disp, std::abs(xa[i] - x0[i]));
        }
        // Same kernels on the same data, each body its own segment (measured: bit-identical, the
        // single backend being the one-segment case of the same engine); the bounds allow for a
        // device that orders a body's partial sums differently in a batch. Double: 1e-9 of
        // the displacement (PCG stops at 1e-10 relative, so a reordered sum can change the last
        // iteration's x by about that). Float: PCG to 1e-5 in float arithmetic; a reordered
        // reduction moves the iterate by up to ~tolerance, and 12 steps accumulate it: 1e-3 of
        // the displacement.
        const double tol = (precision == Precision::Double ? 1e-9 : 1e-3) * disp + 1e-12;
        EXPECT_LE(diff, tol) << "body " << b << " step " << k + 1 << " (largest displacement " << disp << " m)";
        worst = std::max(worst, diff / (disp + 1e-300));
      }
    }
    std::cout << "[ info ] " << toString(precision) << ": batched vs unbatched, largest difference / displacement = "
              << worst << "\n";
    const json after = json::parse(batched->schedulerReport());
    EXPECT_EQ(after["batches"][0]["largest_round"], 4);
    EXPECT_TRUE(after["fallbacks"].empty()) << after.dump(1);
  }
#endif
}

/// A counter of the devices a run used, from its scheduler report ("device_counters"; 0 when absent).
long long counter(const Trace& t, const char* name) { return t.scheduler["device_counters"].value(name, 0LL); }

TEST(BatchSimulation, OneLaunchPcgGivesTheLaunchedRunBitForBit) {
#ifndef COROFEM_WITH_OPENCL
  GTEST_SKIP() << "built without COROFEM_WITH_OPENCL";
#else
  if (!haveOpenCLDevice()) GTEST_SKIP() << "no OpenCL device on this machine";
  // The bodies batched (on a CPU device each solve round's PCG iterations run in one launch,
  // pcg_iterate_group) and each alone (one launch too: with teams on and teamPcgMinElements 1 every
  // body alone gets a team of work-groups, pcg_iterate_team, small as these bodies are), against the
  // same runs without teams and with every PCG iteration launched (groupPcg 0; OpenCLTuning through
  // SimulationOptions): the same statuses, reports, positions, velocities and energies, bit for bit.
  // On a GPU all three launch every iteration.
  const auto oneLaunches = [](const Trace& t) {
    return counter(t, "pcg_group_launches") + counter(t, "pcg_team_launches");
  };
  for (Precision precision : {Precision::Float, Precision::Double}) {
    SCOPED_TRACE(toString(precision));
    Scene scene = openclScene(precision, 6);
    if (!Simulation::create(scene)) {
      std::cout << "[ note ] " << toString(precision) << ": the device cannot run this precision\n";
      continue;
    }
    for (bool batch : {true, false}) {
      SCOPED_TRACE(batch ? "batched" : "each body alone");
      scene.backend.batch = batch;
      Trace grouped, noTeams, launched;
      {
        SimulationOptions o;
        o.opencl.groupPcg = 1;
        o.opencl.teamPcg = 1;
        o.opencl.teamPcgMinElements = 1;
        grouped = run(scene, o);
      }
      const detail::cl::DeviceInfo& info = detail::cl::Context::shared("")->info();
      if (!batch && info.cpu && info.computeUnits > 1)
        EXPECT_GT(counter(grouped, "pcg_team_launches"), 0) << "each body alone took teams on this CPU device";
      {
        SimulationOptions o;
        o.opencl.groupPcg = 1;
        o.opencl.teamPcg = 0;
        noTeams = run(scene, o);
      }
      EXPECT_EQ(counter(noTeams, "pcg_team_launches"), 0) << "teamPcg 0 launched no team";
      {
        SimulationOptions o;
        o.opencl.groupPcg = 0;
        launched = run(scene, o);
      }
      EXPECT_EQ(oneLaunches(launched), 0) << "groupPcg 0 launched no group";
      if (!info.gpu) EXPECT_GT(oneLaunches(grouped), 0) << "a CPU device runs these small bodies' iterations in one launch";
      ASSERT_EQ(noTeams.states.size(), 6u);
      expectSameRun(noTeams, launched);
      ASSERT_EQ(grouped.states.size(), 6u);
      expectSameRun(grouped, launched);
    }
  }
#endif
}

TEST(BatchSimulation, PacksOfOneMeshGiveTheOneWorkGroupRunBitForBit) {
#ifndef COROFEM_WITH_OPENCL
  GTEST_SKIP() << "built without COROFEM_WITH_OPENCL";
#else
  if (!haveOpenCLDevice()) GTEST_SKIP() << "no OpenCL device on this machine";
  // Ten copies of one beam (each its own material, density and damping; one linear, one unloaded
  // that falls asleep, one of another cross-section) and a body of another mesh, batched: on a
  // CPU device the copies' PCG iterations run in packs, a body per vector lane (pcg_iterate_pack),
  // and must give the run of one work-group per body (packPcg 0) bit for bit:
  // statuses, reports, positions, velocities and energies. A GPU runs neither (it launches every
  // iteration) and both runs agree trivially.
  for (Precision precision : {Precision::Float, Precision::Double}) {
    SCOPED_TRACE(toString(precision));
    Scene scene = dynamicScene(boxBeam({8, 2, 2}), 5);
    scene.bodies.clear();
    for (int i = 0; i < 10; ++i) {
      BodyDesc b = boxBeam({8, 2, 2});
      b.name = "copy" + std::to_string(i);
      b.mesh.translate = {0.0, 0.0, 0.3 * i};
      b.material.youngsModulus = 5e5 * (1 + i);
      b.material.poissonRatio = 0.25 + 0.02 * i;
      b.material.density = 900 + 40 * i;
      b.material.rayleighMass = i % 3 == 0 ? 0.5 : 0.0;
      if (i == 4) b.formulation = Formulation::Linear;
      if (i == 7) b.loads.clear();  // falls asleep
      if (i == 8) b.mesh.box->max = {1.0, 0.15, 0.12};  // the same corners, another rest shape
      scene.bodies.push_back(b);
    }
    BodyDesc other = boxBeam({5, 3, 2});
    other.name = "other";
    scene.bodies.push_back(other);
    scene.backend.kind = BackendKind::OpenCL;
    scene.solver.precision = precision;
    scene.solver.tolerance = precision == Precision::Float ? 1e-5 : 1e-10;
    scene.analysis.dynamics.sleep.enabled = true;
    scene.analysis.dynamics.sleep.steps = 2;
    if (!Simulation::create(scene)) {
      std::cout << "[ note ] " << toString(precision) << ": the device cannot run this precision\n";
      continue;
    }
    Trace packed, grouped;
    {
      SimulationOptions o;
      o.opencl.packPcg = 1;
      packed = run(scene, o);
    }
    {
      SimulationOptions o;
      o.opencl.packPcg = 0;
      grouped = run(scene, o);
    }
    EXPECT_EQ(counter(grouped, "pcg_pack_launches"), 0) << "packPcg 0 ran no pack";
    if (!detail::cl::Context::shared("")->info().gpu) {
      EXPECT_GT(counter(packed, "pcg_pack_launches"), 0) << "a CPU device runs the copies' iterations in packs";
      EXPECT_GE(counter(packed, "pcg_pack_lanes"), counter(packed, "pcg_pack_launches"));
    }
    ASSERT_EQ(packed.states.size(), 5u);
    expectSameRun(packed, grouped);
  }
#endif
}

}  // namespace
}  // namespace corofem::test
