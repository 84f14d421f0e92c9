// The dynamics driver's per-dof passes (solve/dynamics.cpp): a body of more dofs than one chunk of
// the host's threads (16,384 dofs) has its sums (|f_ext|, the residual's norms, the loads' work,
// the kinetic energy) taken per chunk and added in chunk order (chunkSums, whose order
// HostParallel.ChunkSumsAddTheChunksInOrderWhateverOrderTheyRunIn checks), so a step gives the same bits
// whatever thread runs which chunk, in whatever order: the library's pool, the caller alone, or an
// application's task runner running the chunks backwards on two threads.
#include "beam_helpers.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <functional>
#include <thread>
#include <vector>

namespace corofem {
namespace {

using namespace corofem::test;

struct PassOutcome {
  std::vector<double> x, v;
  EnergyReport energy;
};

/// The clamped box of twoSteps.
Scene passesScene() {
  BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {1, 0.25, 0.25}, {40, 16, 16}), 0.0, 1e5, 0.3, 1000,
                                 Formulation::Corotational);
  body.loads.push_back(tipForce(1.0, {0, -20.0, 5.0}));
  body.loads.push_back(gravity({0, -9.81, 0}));
  body.material.rayleighMass = 2.0;
  Scene scene;
  scene.name = "passes";
  scene.bodies.push_back(body);
  scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.timeStep = 1.0 / 60.0;
  scene.analysis.dynamics.steps = 2;
  scene.analysis.dynamics.newtonIterations = 1;
  scene.solver.linearSolver = LinearSolverKind::Pcg;
  scene.solver.tolerance = 1e-8;
  scene.solver.maxIterations = 8;  // the sums' order is the point, not the answer: a cheap step (the sanitizer job runs it at -O0)
  scene.backend.kind = BackendKind::Reference;
  return scene;
}

/// Two steps of a clamped 40 x 16 x 16-cell box (11,849 nodes, 35,547 dofs: three chunks) under
/// gravity and a tip load, mass-damped, linearised Newmark with 8 PCG iterations a solve, on the
/// reference device.
PassOutcome twoSteps(const SimulationOptions& options) {
  const Scene scene = passesScene();
  auto sim = Simulation::create(scene, options);
  EXPECT_TRUE(sim) << sim.message();
  PassOutcome r;
  if (!sim) return r;
  EXPECT_EQ(sim->restMesh(0).nodes.size(), 3u * 41 * 17 * 17);
  while (!sim->finished()) {
    const Status st = sim->step();
    EXPECT_TRUE(st) << st.message();
    if (!st) return r;
  }
  EXPECT_TRUE(sim->readPositions(0, r.x));
  EXPECT_TRUE(sim->readVelocities(0, r.v));
  r.energy = sim->energies(0);
  return r;
}

TEST(DynamicsPasses, ABodyOfManyChunksGetsTheSameBitsOnAnyThreadsInAnyOrder) {
  const PassOutcome pool = twoSteps({});
  ASSERT_FALSE(pool.x.empty());
  std::atomic<long long> calls{0};
  SimulationOptions backwards;  // every task on the caller, last first
  backwards.tasks = [&](std::size_t count, const std::function<void(std::size_t)>& task) {
    ++calls;
    for (std::size_t i = count; i-- > 0;) task(i);
  };
  SimulationOptions twoThreads;  // the upper half on a thread of the application's, both halves backwards
  twoThreads.tasks = [&](std::size_t count, const std::function<void(std::size_t)>& task) {
    std::thread other([&] {
      for (std::size_t i = count; i-- > count / 2;) task(i);
    });
    for (std::size_t i = count / 2; i-- > 0;) task(i);
    other.join();
  };
  for (const SimulationOptions* o : {&backwards, &twoThreads}) {
    const PassOutcome r = twoSteps(*o);
    EXPECT_EQ(r.x, pool.x);
    EXPECT_EQ(r.v, pool.v);
    // The loads' work is one of the chunked sums.
    EXPECT_EQ(r.energy.externalWork, pool.energy.externalWork);
    EXPECT_EQ(r.energy.kinetic, pool.energy.kinetic);
  }
  EXPECT_GT(calls.load(), 0) << "the steps' passes never reached the application's tasks";
  EXPECT_GT(pool.energy.externalWork, 0.0);
  EXPECT_GT(pool.energy.kinetic, 0.0);
}

/// A cantilever (0.4 x 0.1 x 0.1 m, E = 1e5 Pa) whose tip nodes a hard handle drags `distance`
/// sideways in `steps` steps of 0.05 s / steps (the handle's centre moved on a straight line, an
/// equal part each step), with at most `maxSubsteps` substeps; the positions after the drag.
std::vector<double> dragged(double distance, int steps, int maxSubsteps) {
  BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {0.4, 0.1, 0.1}, {8, 2, 2}), 0.0, 1e5, 0.3, 1000,
                                 Formulation::Corotational);
  Scene scene;
  scene.name = "drag";
  scene.bodies.push_back(body);
  scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.timeStep = 0.05 / steps;
  scene.analysis.dynamics.steps = 0;  // open-ended
  scene.analysis.dynamics.maxSubsteps = maxSubsteps;
  scene.solver.linearSolver = LinearSolverKind::Pcg;
  scene.solver.tolerance = 1e-12;
  scene.solver.maxIterations = 2000;
  scene.backend.kind = BackendKind::Reference;
  auto sim = Simulation::create(scene);
  EXPECT_TRUE(sim) << sim.message();
  if (!sim) return {};
  HandleDesc h;
  const std::vector<double>& rest = sim->restMesh(0).nodes;
  double c[3] = {0, 0, 0};
  for (std::uint32_t n = 0; 3 * n < rest.size(); ++n)
    if (rest[3 * n] > 0.4 - 1e-9) h.nodes.push_back(n);
  for (std::uint32_t n : h.nodes)
    for (int k = 0; k < 3; ++k) c[k] += rest[3 * n + k] / static_cast<double>(h.nodes.size());
  const Result<int> id = sim->addHandle(h);
  EXPECT_TRUE(id) << id.message();
  if (!id) return {};
  for (int s = 1; s <= steps; ++s) {
    const double target[3] = {c[0], c[1] + distance * s / steps, c[2]};
    EXPECT_TRUE(sim->moveHandle(id.value(), target));
    const Status st = sim->step();
    if (!st) return {};
  }
  std::vector<double> x;
  EXPECT_TRUE(sim->readPositions(0, x));
  return x;
}

double maxDifference(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size() || a.empty()) return INFINITY;
  double m = 0;
  for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, std::abs(a[i] - b[i]));
  return m;
}

TEST(DynamicsPasses, ARetriedStepsSubstepsMoveAHeldHandleOnFromTheStepsStart) {
  // 1.5 m in 0.05 s: one step fails and so do two of 0.025 s; retried, the step takes four
  // substeps. The handle's nodes go to x0 + f (target - x0) at substep end f = 1/4 ... 1, x0 their
  // positions at the step's start, which the body holds no longer after the first substep's
  // commit: the answer of four steps of 0.0125 s with the handle moved a quarter each time.
  EXPECT_TRUE(dragged(1.5, 1, 1).empty()) << "one step of the drag was expected to fail";
  EXPECT_TRUE(dragged(1.5, 2, 1).empty()) << "two steps of the drag were expected to fail";
  const std::vector<double> retried = dragged(1.5, 1, 16), four = dragged(1.5, 4, 1);
  ASSERT_FALSE(retried.empty()) << "the retried step failed";
  ASSERT_FALSE(four.empty()) << "four steps of the drag failed";
  // Only rounding differs (substep ends t_n + h j / k against accumulated steps): 1e-9 of the drag.
  EXPECT_LT(maxDifference(retried, four), 1e-9 * 1.5);
}

}  // namespace
}  // namespace corofem
