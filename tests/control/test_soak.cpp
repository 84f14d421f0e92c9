// The soak of issue 25 in its short form (tests/control/soak.hpp): SOFA's liver and the Fig. 8 beam
// dragged by a handle with random, abrupt motions for 20 s of simulated time at 90 Hz and 60 Hz,
// with the library's defaults for an open-ended scene (no integrator given), a hard handle and a
// spring handle in turns, on the reference backend and on OpenCL in float: no step may fail and no
// position may become non-finite. bench/bench_soak.cpp runs the full hour and the integrators
// side by side.
#include "control/soak.hpp"
#include "common/test_data.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

namespace corofem::test {
namespace {

class Soak : public ::testing::TestWithParam<std::tuple<std::string, double, std::string>> {};

TEST_P(Soak, AbruptDragsNeverFailWithTheDefaults) {
  const auto& [body, hz, backend] = GetParam();
  if (body == "liver" && !std::ifstream(soakLiverMesh()))
    GTEST_SKIP() << soakLiverMesh() << " is absent (the shared data folder ../shared/data is not here)";
  Scene scene = soakScene(body);
  ASSERT_EQ(integratorOf(scene.analysis.dynamics), Integrator::BackwardEuler);
  if (backend == "opencl_float") {
    scene.backend.kind = BackendKind::OpenCL;
    scene.solver.precision = Precision::Float;
  }
  Result<Simulation> sim = Simulation::create(scene);
  if (!sim && backend != "reference" &&
      (sim.status().code() == ErrorCode::NotCompiledIn || sim.status().code() == ErrorCode::DeviceError))
    GTEST_SKIP() << "no OpenCL device here: " << sim.message();
  ASSERT_TRUE(sim) << sim.message();
  const SoakGrip grip = soakGrip(body);
  // 20 s: grabbed hard, let go at 9 s, grabbed by a spring at 10 s, let go at 19 s.
  const SoakResult r = soak(sim.value(), 20.0, hz, grip.point, grip.grab, grip.reach, 2026, grip.spring);
  EXPECT_EQ(r.failed, 0) << r.firstFailure;
  EXPECT_EQ(r.nonFinite, 0);
  EXPECT_EQ(r.steps, static_cast<long long>(20.0 * hz));
  // The drags moved the body (the handle held it: a node went at least half the reach).
  EXPECT_GT(r.largestMove, 0.5 * grip.reach);
  EXPECT_GT(r.largestSpringMove, 0.25 * grip.reach) << "the spring handle barely moved the body";
  std::printf("[info] %s %g Hz %s: largest move %.3f m, with the spring %.3f m (reach %.2f m)\n", body.c_str(), hz,
              backend.c_str(), r.largestMove, r.largestSpringMove, grip.reach);
}

INSTANTIATE_TEST_SUITE_P(Bodies, Soak,
                         ::testing::Combine(::testing::Values(std::string("liver"), std::string("beam")),
                                            ::testing::Values(90.0, 60.0),
                                            ::testing::Values(std::string("reference"), std::string("opencl_float"))),
                         [](const ::testing::TestParamInfo<std::tuple<std::string, double, std::string>>& info) {
                           return std::get<0>(info.param) + "_" +
                                  std::to_string(static_cast<int>(std::get<1>(info.param))) + "Hz_" +
                                  std::get<2>(info.param);
                         });

}  // namespace
}  // namespace corofem::test
