// The dynamics driver's per-dof passes (solve/dynamics.cpp): a body of more dofs than one chunk of
// the host's threads (16,384 dofs) has its sums (|f_ext|, the residual's norms, the loads' work,
// the kinetic energy) taken per chunk and added in chunk order (chunkSums, whose order
// HostParallel.ChunkSumsAddTheChunksInOrderWhateverOrderTheyRunIn checks), so a step gives the same bits
// whatever thread runs which chunk, in whatever order: the library's pool, the caller alone, or an
// application's task runner running the chunks backwards on two threads.
#include "beam_helpers.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <functional>
#include <thread>
#include <vector>

namespace corofem {
namespace {

using namespace corofem::test;

struct Outcome {
  std::vector<double> x, v;
  EnergyReport energy;
};

/// Three steps of a clamped 40 x 16 x 16-cell box (11,849 nodes, 35,547 dofs: three chunks) under
/// gravity and a tip load, mass-damped, Newmark with two Newton iterations, on the reference device.
Outcome threeSteps(const SimulationOptions& options) {
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
  scene.analysis.dynamics.steps = 3;
  scene.analysis.dynamics.newtonIterations = 2;
  scene.analysis.dynamics.newtonTolerance = 1e-12;
  scene.solver.linearSolver = LinearSolverKind::Pcg;
  scene.solver.tolerance = 1e-8;
  scene.solver.maxIterations = 40;
  scene.backend.kind = BackendKind::Reference;
  auto sim = Simulation::create(scene, options);
  EXPECT_TRUE(sim) << sim.message();
  Outcome r;
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
  const Outcome pool = threeSteps({});
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
    const Outcome r = threeSteps(*o);
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

}  // namespace
}  // namespace corofem
