// The drivers are written once against the Device interface: the same scene on each device backend
// (OpenCL, Vulkan: when built, and when a device with double exists) must give the reference
// backend's answer. Static co-rotational Newton (L-BFGS + line search over PCG), a co-rotational
// Newmark run, and SOFA's liver driving its fine render surface (paper Sec. 5).
#include "beam_helpers.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iostream>

namespace corofem {
namespace {

using namespace corofem::test;

// A build without either device backend (the sanitizer job's) skips these tests before their
// reference runs, which would compare with nothing (the multigrid's took 32 s there).
#if defined(COROFEM_WITH_OPENCL) || defined(COROFEM_WITH_VULKAN)
#define COROFEM_SKIP_WITHOUT_DEVICE_BACKENDS() (void)0
#else
#define COROFEM_SKIP_WITHOUT_DEVICE_BACKENDS() \
  GTEST_SKIP() << "no device backend in this build (COROFEM_WITH_OPENCL and COROFEM_WITH_VULKAN are off)"
#endif

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

/// The scene on every device backend (OpenCL, Vulkan; each skipped where absent) against the
/// reference backend, double precision.
void compareBackends(AnalysisDesc::Kind kind, double tolerance) {
  COROFEM_SKIP_WITHOUT_DEVICE_BACKENDS();
  bool skipped = false;
  const std::vector<double> reference = finalPositions(beamScene(BackendKind::Reference, kind), &skipped);
  ASSERT_FALSE(reference.empty());
  int compared = 0;
  for (BackendKind backend : {BackendKind::OpenCL, BackendKind::Vulkan}) {
    SCOPED_TRACE(toString(backend));
    const std::vector<double> device = finalPositions(beamScene(backend, kind), &skipped);
    if (skipped) continue;
    ASSERT_EQ(device.size(), reference.size());
    double worst = 0;
    for (std::size_t i = 0; i < reference.size(); ++i) worst = std::max(worst, std::abs(device[i] - reference[i]));
    std::cout << "  largest position difference " << toString(backend) << " - reference: " << worst << " m\n";
    EXPECT_LT(worst, tolerance);
    ++compared;
  }
  if (compared == 0) GTEST_SKIP() << "no device backend with a double-precision device in this build";
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

TEST(BackendAgreement, TheLiverAndItsSurfaceOnEveryDeviceBackend) {
  // SOFA's liver (596 tets) driving its 2,194-vertex surface, 30 backward-Euler steps under gravity
  // with its right lobe clamped, PCG at 1e-10 in double: the device's surface (computed on the
  // device, float32 output) against the reference's (double, on the host). The nodes agree to the
  // solves' rounding over 30 steps; the surface adds the float output's half ulp at |x| ~ 6.
  COROFEM_SKIP_WITHOUT_DEVICE_BACKENDS();
  const char* mesh = "../shared/data/meshes/sofa/liver.msh";
  const char* surface = "../shared/data/meshes/sofa/liver-smooth.obj";
  if (!std::ifstream(mesh) || !std::ifstream(surface)) GTEST_SKIP() << mesh << " or " << surface << " is absent";
  auto liver = [&](BackendKind backend) {
    BodyDesc body = cantileverBody(fileMesh(mesh), 0.0, 3000, 0.45, 1.0, Formulation::Corotational);
    body.fixed.clear();
    NodeSetDesc clamp;
    clamp.boxMin = {1.2, 0, -2};
    clamp.boxMax = {2, 6, 3};
    body.fixed.push_back(clamp);
    body.surface = surface;
    body.material.rayleighMass = 1.0;
    body.loads.push_back(gravity({0, -9.81, 0}));
    Scene scene = staticScene(body, 1, LinearSolverKind::Pcg);
    scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
    scene.analysis.dynamics.integrator = Integrator::BackwardEuler;
    scene.analysis.dynamics.timeStep = 0.01;
    scene.analysis.dynamics.steps = 30;
    scene.solver.tolerance = 1e-10;
    scene.solver.maxIterations = 5000;
    scene.solver.preconditioner = PreconditionerKind::Diagonal;
    scene.backend.kind = backend;
    return scene;
  };
  auto run = [&](BackendKind backend, std::vector<double>& nodes, std::vector<double>& vertices) {
    auto sim = Simulation::create(liver(backend));
    if (!sim) return sim.status();
    if (!runToEnd(sim.value())) return Status(ErrorCode::Internal, "the run failed");
    EXPECT_TRUE(sim->readPositions(0, nodes));
    EXPECT_TRUE(sim->readSurface(0, vertices));
    return Status::ok();
  };
  std::vector<double> refNodes, refSurface;
  ASSERT_TRUE(run(BackendKind::Reference, refNodes, refSurface));
  int compared = 0;
  for (BackendKind backend : {BackendKind::OpenCL, BackendKind::Vulkan}) {
    SCOPED_TRACE(toString(backend));
    std::vector<double> nodes, vertices;
    const Status st = run(backend, nodes, vertices);
    if (st.code() == ErrorCode::NotCompiledIn || st.code() == ErrorCode::DeviceError) continue;
    ASSERT_TRUE(st) << st.message();
    double worstNode = 0, worstVertex = 0;
    for (std::size_t i = 0; i < nodes.size(); ++i) worstNode = std::max(worstNode, std::abs(nodes[i] - refNodes[i]));
    for (std::size_t i = 0; i < vertices.size(); ++i)
      worstVertex = std::max(worstVertex, std::abs(vertices[i] - refSurface[i]));
    std::cout << "  liver, " << toString(backend) << " - reference: nodes " << worstNode << ", surface " << worstVertex
              << "\n";
    ASSERT_EQ(vertices.size(), refSurface.size());
    EXPECT_LT(worstNode, 1e-8);
    EXPECT_LT(worstVertex, 1e-6);  // float32 output: half an ulp at 6 is 2.4e-7
    ++compared;
  }
  if (compared == 0) GTEST_SKIP() << "no device backend with a double-precision device in this build";
}

/// A slender beam (1 x 0.1 x 0.1 m, 30 x 3 x 3 cells, 1,620 tets, E = 1e6 Pa) clamped at x = 0, 20
/// backward-Euler steps under gravity with preconditioner `pc`, PCG at 1e-10 in double, on each
/// of `backends` against the reference: the same iterations within two a step (rounding in the
/// preconditioner), the nodes to the solves' rounding; the whole run on the device asked for (a
/// failover to the reference would compare the reference with itself).
void preconditionerAgrees(PreconditionerKind pc, const std::vector<BackendKind>& backends) {
  auto beam = [pc](BackendKind backend) {
    BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {1.0, 0.1, 0.1}, {30, 3, 3}), 0.0, 1e6, 0.3, 1000.0,
                                   Formulation::Corotational);
    body.loads.push_back(gravity({0, 0, -9.81}));
    Scene scene = staticScene(body, 1, LinearSolverKind::Pcg);
    scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
    scene.analysis.dynamics.integrator = Integrator::BackwardEuler;
    scene.analysis.dynamics.timeStep = 1.0 / 60;
    scene.analysis.dynamics.steps = 20;
    scene.solver.tolerance = 1e-10;
    scene.solver.maxIterations = 500;
    scene.solver.preconditioner = pc;
    scene.backend.kind = backend;
    return scene;
  };
  auto run = [&](BackendKind backend, std::vector<double>& nodes, long long& iterations) {
    auto sim = Simulation::create(beam(backend));
    if (!sim) return sim.status();
    iterations = 0;
    while (!sim->finished()) {
      StepReport r;
      const Status st = sim->step(&r);
      if (!st) return st;
      iterations += r.linearIterations;
    }
    EXPECT_EQ(sim->backendName(), toString(backend)) << "the run left the backend it was given";
    EXPECT_TRUE(sim->readPositions(0, nodes));
    return Status::ok();
  };
  std::vector<double> refNodes;
  long long refIterations = 0;
  ASSERT_TRUE(run(BackendKind::Reference, refNodes, refIterations));
  int compared = 0;
  for (BackendKind backend : backends) {
    SCOPED_TRACE(toString(backend));
    std::vector<double> nodes;
    long long iterations = 0;
    const Status st = run(backend, nodes, iterations);
    if (st.code() == ErrorCode::NotCompiledIn || st.code() == ErrorCode::DeviceError) continue;
    ASSERT_TRUE(st) << st.message();
    ASSERT_EQ(nodes.size(), refNodes.size());
    double worst = 0;
    for (std::size_t i = 0; i < nodes.size(); ++i) worst = std::max(worst, std::abs(nodes[i] - refNodes[i]));
    std::cout << "  " << toString(pc) << " beam, " << toString(backend) << " - reference: nodes " << worst
              << " m, PCG iterations " << iterations << " (reference " << refIterations << ")\n";
    EXPECT_LT(worst, 1e-8);
    EXPECT_LE(std::abs(iterations - refIterations), 2 * 20) << "more than two iterations a step apart";
    ++compared;
  }
  if (compared == 0) GTEST_SKIP() << "no device backend with a double-precision device in this build";
}

TEST(BackendAgreement, TheMultigridOnEveryDeviceBackend) {
  // Each device's V-cycle (its own kernels over the levels device_amg.cpp lays out) against the
  // reference's ("auto" gives large slender bodies the multigrid).
  COROFEM_SKIP_WITHOUT_DEVICE_BACKENDS();
  preconditionerAgrees(PreconditionerKind::Amg, {BackendKind::OpenCL, BackendKind::Vulkan});
}

TEST(BackendAgreement, TheWarpedFactorOnOpenCl) {
  // The factor applied on the host between the OpenCL device's launches (device_warped.hpp), warped
  // by the rotations the device computed, against the reference's.
  COROFEM_SKIP_WITHOUT_DEVICE_BACKENDS();
  preconditionerAgrees(PreconditionerKind::WarpedCholesky, {BackendKind::OpenCL});
}

}  // namespace
}  // namespace corofem
