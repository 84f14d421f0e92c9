// The drivers are written once against the Backend interface: the same scene on the OpenCL backend
// (when built, and when a device exists) must give the reference backend's answer. Static
// co-rotational Newton (L-BFGS + line search over PCG) and a co-rotational Newmark run.
#include "beam_helpers.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

namespace corofem {
namespace {

using namespace corofem::test;

/// The Fig. 8 beam (0.8 x 0.1 x 0.1 m, 8 x 1 x 1 x 5 tets, E = 2e5 Pa) under gravity.
Scene beamScene(BackendKind backend, AnalysisDesc::Kind kind) {
  BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {0.8, 0.1, 0.1}, {8, 1, 1}), 0.0, 2e5, 0.3, 1000.0,
                                 Formulation::Corotational);
  body.loads.push_back(gravity({0, -9.81, 0}));
  body.material.rayleighMass = 4.0;
  Scene scene = staticScene(body, 4, LinearSolverKind::Pcg);
  scene.analysis.kind = kind;
  scene.analysis.dynamics.timeStep = 0.01;
  scene.analysis.dynamics.steps = 100;
  scene.analysis.dynamics.newmarkGamma = 0.6;
  scene.analysis.dynamics.newmarkBeta = 0.3025;
  scene.solver.tolerance = 1e-10;  // tight: the comparison is about the drivers, not PCG noise
  scene.solver.maxIterations = 5000;
  scene.backend.kind = backend;
  return scene;
}

/// Runs to the end; returns the positions, or an empty vector with a skip/failure recorded.
std::vector<double> finalPositions(const Scene& scene, bool* skipped) {
  *skipped = false;
  auto sim = Simulation::create(scene);
  if (!sim) {
    if (sim.status().code() == ErrorCode::NotCompiledIn || sim.status().code() == ErrorCode::DeviceError) {
      *skipped = true;
      std::cout << "  skipped: " << sim.message() << "\n";
      return {};
    }
    ADD_FAILURE() << sim.message();
    return {};
  }
  std::cout << "  " << sim->backendName() << " on " << sim->deviceName() << "\n";
  if (!runToEnd(sim.value())) return {};
  std::vector<double> x;
  EXPECT_TRUE(sim->readPositions(0, x));
  return x;
}

void compareBackends(AnalysisDesc::Kind kind, double tolerance) {
  bool skipped = false;
  const std::vector<double> reference = finalPositions(beamScene(BackendKind::Reference, kind), &skipped);
  ASSERT_FALSE(reference.empty());
  const std::vector<double> opencl = finalPositions(beamScene(BackendKind::OpenCL, kind), &skipped);
  if (skipped) GTEST_SKIP() << "no OpenCL backend or device in this build";
  ASSERT_EQ(opencl.size(), reference.size());
  double worst = 0;
  for (std::size_t i = 0; i < reference.size(); ++i) worst = std::max(worst, std::abs(opencl[i] - reference[i]));
  std::cout << "  largest position difference OpenCL - reference: " << worst << " m\n";
  EXPECT_LT(worst, tolerance);
}

TEST(BackendAgreement, StaticCorotationalNewton) {
  // Both converge to the Newton tolerance (1e-6 relative residual) on a ~0.6 m deflection; the
  // iterates differ by PCG rounding only. 1e-5 m.
  compareBackends(AnalysisDesc::Kind::Static, 1e-5);
}

TEST(BackendAgreement, DynamicCorotationalNewmark) {
  // 100 linearised steps with PCG at 1e-10: differences stay at rounding x steps. 1e-6 m.
  compareBackends(AnalysisDesc::Kind::Dynamic, 1e-6);
}

}  // namespace
}  // namespace corofem
