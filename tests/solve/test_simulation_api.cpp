// The public Simulation API: step bookkeeping, reports, energies, read-back, and failures that
// keep the last good state (SolveFailed) or are refused at create() (BadInput, NotCompiledIn).
#include "beam_helpers.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

namespace corofem {
namespace {

using namespace corofem::test;

/// A small cantilever 1 x 0.1 x 0.1 m, 10 x 1 x 1 cells.
BodyDesc smallBeam(Formulation formulation, double tipLoad, const std::string& name = "beam") {
  BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {1, 0.1, 0.1}, {10, 1, 1}), 0.0, 1e6, 0.3, 1000, formulation);
  body.name = name;
  if (tipLoad != 0) body.loads.push_back(tipForce(1.0, {0, -tipLoad, 0}));
  return body;
}

TEST(SimulationApi, StaticBookkeepingReportAndWork) {
  Scene scene = staticScene(smallBeam(Formulation::Linear, 1.0), 4);
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  EXPECT_EQ(sim->backendName(), "reference");
  EXPECT_FALSE(sim->deviceName().empty());
  EXPECT_EQ(sim->bodyCount(), 1);
  EXPECT_EQ(sim->stepCount(), 4);
  EXPECT_EQ(sim->stepsTaken(), 0);
  EXPECT_DOUBLE_EQ(sim->time(), 0.0);
  EXPECT_FALSE(sim->finished());
  for (int k = 1; k <= 4; ++k) {
    StepReport r;
    ASSERT_TRUE(sim->step(&r));
    EXPECT_EQ(r.step, k);
    EXPECT_DOUBLE_EQ(r.time, k / 4.0);  // statics: the load factor
    EXPECT_TRUE(r.converged);
    EXPECT_LE(r.residual, scene.analysis.statics.residualTolerance);
    EXPECT_GE(r.wallSeconds, 0.0);
  }
  EXPECT_TRUE(sim->finished());
  // A linear problem loaded proportionally: the trapezoidal external work 1/2 f.u equals the strain
  // energy 1/2 u.K.u (1e-9 relative: Cholesky rounding).
  const EnergyReport e = sim->energies(0);
  EXPECT_GT(e.elastic, 0.0);
  EXPECT_NEAR(e.externalWork, e.elastic, 1e-9 * e.elastic);
  EXPECT_EQ(e.kinetic, 0.0);
  // Statics has no velocities: zeros.
  std::vector<double> v;
  ASSERT_TRUE(sim->readVelocities(0, v));
  ASSERT_EQ(v.size(), sim->restMesh(0).nodes.size());
  for (double c : v) EXPECT_EQ(c, 0.0);
  // Past the end: refused, nothing changes.
  std::vector<double> before, after;
  ASSERT_TRUE(sim->readPositions(0, before));
  const Status st = sim->step();
  EXPECT_EQ(st.code(), ErrorCode::BadInput);
  EXPECT_NE(st.message().find("finished"), std::string::npos) << st.message();
  ASSERT_TRUE(sim->readPositions(0, after));
  EXPECT_EQ(before, after);
}

TEST(SimulationApi, DynamicBookkeepingAndKineticEnergy) {
  BodyDesc body = smallBeam(Formulation::Corotational, 0.0);
  body.fixed.clear();
  body.initialVelocity = {0.0, 0.0, 2.0};
  Scene scene;
  scene.bodies.push_back(body);
  scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.timeStep = 0.01;
  scene.analysis.dynamics.steps = 5;
  scene.backend.kind = BackendKind::Auto;  // the reference backend until the scheduler exists
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  EXPECT_EQ(sim->backendName(), "reference");
  EXPECT_EQ(sim->stepCount(), 5);
  // Mass 1000 kg/m^3 x 0.01 m^3 = 10 kg: KE = 1/2 10 2^2 = 20 J (1e-12: summation rounding).
  EXPECT_NEAR(sim->energies(0).kinetic, 20.0, 1e-12);
  EXPECT_NEAR(sim->energies(0).elastic, 0.0, 1e-12);
  while (!sim->finished()) {
    StepReport r;
    ASSERT_TRUE(sim->step(&r));
    EXPECT_NEAR(r.time, 0.01 * r.step, 1e-15);
  }
  EXPECT_NEAR(sim->time(), 0.05, 1e-15);
  // Free flight without loads: uniform motion, 2 m/s x 0.05 s = 0.1 m in z (1e-9 m: PCG tolerance).
  const Vec3 mean = meanDisplacement(sim.value(), planeX(1.0));
  EXPECT_NEAR(mean[2], 0.1, 1e-9);
  EXPECT_NEAR(sim->energies(0).kinetic, 20.0, 1e-6);
}

TEST(SimulationApi, PrescribedStretchIsUniaxialAndExact) {
  // A 1 x 0.1 x 0.1 m bar, nu = 0, clamped at x = 0 and pulled by a prescribed displacement
  // delta = 1 cm of the x = 1 face, in 2 increments. With nu = 0 the clamp adds no lateral
  // constraint, so the strain delta / L is uniform and linear tets represent it exactly:
  // u_x = delta x / L at every node, U = E A delta^2 / (2 L) = 0.5 J.
  for (Formulation f : {Formulation::Linear, Formulation::Corotational}) {
    BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {1, 0.1, 0.1}, {10, 1, 1}), 0.0, 1e6, 0.0, 1000, f);
    LoadDesc pull;
    pull.kind = LoadDesc::Kind::Displacement;
    pull.vector = {0.01, 0, 0};
    pull.nodes = planeX(1.0);
    body.loads.push_back(pull);
    auto sim = Simulation::create(staticScene(body, 2));
    ASSERT_TRUE(sim) << sim.message();
    ASSERT_TRUE(runToEnd(sim.value()));
    std::vector<double> x;
    ASSERT_TRUE(sim->readPositions(0, x));
    const std::vector<double>& x0 = sim->restMesh(0).nodes;
    double worst = 0;
    for (std::size_t n = 0; n < x0.size() / 3; ++n) {
      worst = std::max(worst, std::abs(x[3 * n] - x0[3 * n] - 0.01 * x0[3 * n]));
      worst = std::max({worst, std::abs(x[3 * n + 1] - x0[3 * n + 1]), std::abs(x[3 * n + 2] - x0[3 * n + 2])});
    }
    // 1e-9 m: the Newton tolerances (residual 1e-6 relative) on a 1 cm displacement, Cholesky.
    EXPECT_LT(worst, 1e-9) << toString(f);
    // 1e-6 relative: same reason (a pure stretch has R = I, so both formulations coincide).
    EXPECT_NEAR(sim->energies(0).elastic, 0.5, 0.5 * 1e-6) << toString(f);
    EXPECT_EQ(sim->energies(0).externalWork, 0.0);  // no applied loads: the supports did the work
  }
}

TEST(SimulationApi, StaticFailureKeepsLastConvergedIncrement) {
  // A co-rotational cantilever under a load of alpha ~ 40 with a single Newton iteration allowed
  // and a tight tolerance cannot converge.
  Scene scene = staticScene(smallBeam(Formulation::Corotational, 2000.0), 2);
  scene.analysis.statics.maxNewtonIterations = 1;
  scene.analysis.statics.residualTolerance = 1e-10;
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  StepReport report;
  const Status st = sim->step(&report);
  ASSERT_FALSE(st);
  EXPECT_EQ(st.code(), ErrorCode::SolveFailed);
  EXPECT_NE(st.message().find("body 'beam'"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("increment 1/2"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("did not converge in 1 Newton iterations"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("analysis.increments"), std::string::npos) << st.message();
  EXPECT_FALSE(report.converged);
  EXPECT_EQ(sim->stepsTaken(), 0);
  EXPECT_FALSE(sim->finished());
  std::vector<double> x;
  ASSERT_TRUE(sim->readPositions(0, x));
  EXPECT_EQ(x, sim->restMesh(0).nodes);  // the last converged state is the rest state
}

TEST(SimulationApi, OneFailingBodyRollsTheOthersBack) {
  // Body "easy" (linear, converges at once) is stepped first; body "hard" then fails: "easy" must go
  // back too, so that every body stays at the same (last completed) increment.
  Scene scene = staticScene(smallBeam(Formulation::Linear, 1.0, "easy"), 1);
  BodyDesc hard = smallBeam(Formulation::Corotational, 2000.0, "hard");
  hard.mesh.translate = {0, 0, 5};
  scene.bodies.push_back(hard);
  scene.analysis.statics.maxNewtonIterations = 2;
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  const Status st = sim->step();
  ASSERT_FALSE(st);
  EXPECT_NE(st.message().find("body 'hard'"), std::string::npos) << st.message();
  std::vector<double> x;
  ASSERT_TRUE(sim->readPositions(0, x));
  EXPECT_EQ(x, sim->restMesh(0).nodes);
  EXPECT_DOUBLE_EQ(sim->energies(0).externalWork, 0.0);
}

TEST(SimulationApi, BadBodyIndexIsAStatus) {
  auto sim = Simulation::create(staticScene(smallBeam(Formulation::Linear, 1.0), 1));
  ASSERT_TRUE(sim) << sim.message();
  std::vector<double> x;
  const Status st = sim->readPositions(3, x);
  EXPECT_EQ(st.code(), ErrorCode::BadInput);
  EXPECT_NE(st.message().find("out of range"), std::string::npos) << st.message();
  EXPECT_EQ(sim->readVelocities(-1, x).code(), ErrorCode::BadInput);
}

TEST(SimulationApi, HyperelasticOnOpenCLIsRefusedWithTheFix) {
#ifndef COROFEM_WITH_OPENCL
  GTEST_SKIP() << "built without the OpenCL backend (OpenCLWithoutTheBackendSaysNotCompiledIn covers it)";
#endif
  for (Formulation f : {Formulation::StVenantKirchhoff, Formulation::NeoHookean}) {
    Scene scene = staticScene(smallBeam(f, 1.0, "soft part"), 1);
    scene.backend.kind = BackendKind::OpenCL;
    auto sim = Simulation::create(scene);
    ASSERT_FALSE(sim);
    EXPECT_EQ(sim.status().code(), ErrorCode::BadInput);
    EXPECT_NE(sim.message().find("body 'soft part'"), std::string::npos) << sim.message();
    EXPECT_NE(sim.message().find(toString(f)), std::string::npos) << sim.message();
    EXPECT_NE(sim.message().find("\"backend\": \"reference\""), std::string::npos) << sim.message();
  }
}

TEST(SimulationApi, OpenCLWithoutTheBackendSaysNotCompiledIn) {
#ifdef COROFEM_WITH_OPENCL
  GTEST_SKIP() << "this build has the OpenCL backend";
#else
  Scene scene = staticScene(smallBeam(Formulation::Corotational, 1.0), 1);
  scene.backend.kind = BackendKind::OpenCL;
  auto sim = Simulation::create(scene);
  ASSERT_FALSE(sim);
  EXPECT_EQ(sim.status().code(), ErrorCode::NotCompiledIn);
  EXPECT_NE(sim.message().find("COROFEM_WITH_OPENCL"), std::string::npos) << sim.message();
#endif
}

TEST(SimulationApi, MeshErrorsReachTheCaller) {
  Scene scene = staticScene(cantileverBody(fileMesh("no/such/mesh.msh"), 0.0, 1e6, 0.3, 1000, Formulation::Linear), 1);
  auto sim = Simulation::create(scene);
  ASSERT_FALSE(sim);
  EXPECT_NE(sim.status().code(), ErrorCode::Ok);
  EXPECT_NE(sim.message().find("no/such/mesh.msh"), std::string::npos) << sim.message();
}

TEST(SimulationApi, AMeshInMemoryRunsAsTheBoxItCameFrom) {
  // MeshSourceDesc::mesh: the application's mesh, here the very mesh of the scene's box; the same
  // steps, bit for bit.
  Scene boxScene = staticScene(smallBeam(Formulation::Corotational, 20.0), 2);
  Result<TetMesh> mesh = loadBodyMesh(boxScene.bodies[0], "");
  ASSERT_TRUE(mesh) << mesh.message();
  Scene held = boxScene;
  held.bodies[0].mesh = MeshSourceDesc{};
  held.bodies[0].mesh.mesh = std::make_shared<const TetMesh>(mesh.value());
  auto a = Simulation::create(boxScene), b = Simulation::create(held);
  ASSERT_TRUE(a) << a.message();
  ASSERT_TRUE(b) << b.message();
  EXPECT_EQ(b->meshReport(0).format, "in memory");
  while (!a->finished()) {
    ASSERT_TRUE(a->step());
    ASSERT_TRUE(b->step());
  }
  std::vector<double> xa, xb;
  ASSERT_TRUE(a->readPositions(0, xa));
  ASSERT_TRUE(b->readPositions(0, xb));
  EXPECT_EQ(xa, xb);
}

TEST(SimulationApi, ABadHostThreadCountIsAWarningInTheLog) {
  // COROFEM_HOST_THREADS that is not a count is ignored and said in the application's log (the
  // library writes nothing to stderr).
  setenv("COROFEM_HOST_THREADS", "lots", 1);
  std::vector<std::string> warnings;
  SimulationOptions o;
  o.log.callback = [&](LogLevel level, const std::string& message) {
    if (level == LogLevel::Warning) warnings.push_back(message);
  };
  auto sim = Simulation::create(staticScene(smallBeam(Formulation::Linear, 1.0), 1), o);
  unsetenv("COROFEM_HOST_THREADS");
  ASSERT_TRUE(sim) << sim.message();
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("COROFEM_HOST_THREADS='lots'"), std::string::npos) << warnings[0];
  warnings.clear();
  ASSERT_TRUE(Simulation::create(staticScene(smallBeam(Formulation::Linear, 1.0), 1), o));
  EXPECT_TRUE(warnings.empty()) << warnings.front();
}

}  // namespace
}  // namespace corofem
