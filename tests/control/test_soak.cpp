// The soak of issue 25 in its short form (tests/control/soak.hpp): SOFA's liver and the Fig. 8 beam
// dragged by a handle with random, abrupt motions for 20 s of simulated time at 90 Hz and 60 Hz,
// with the library's defaults for an open-ended scene (no integrator given): no step may fail and
// no position may become non-finite. bench/bench_soak.cpp runs the full hour and the integrators
// side by side.
#include "control/soak.hpp"
#include "common/test_data.hpp"

#include <gtest/gtest.h>

#include <fstream>

namespace corofem::test {
namespace {

class Soak : public ::testing::TestWithParam<std::tuple<std::string, double>> {};

TEST_P(Soak, AbruptDragsNeverFailWithTheDefaults) {
  const auto& [body, hz] = GetParam();
  if (body == "liver" && !std::ifstream(soakLiverMesh()))
    GTEST_SKIP() << soakLiverMesh() << " is absent (the shared data folder ../shared/data is not here)";
  const Scene scene = soakScene(body);
  ASSERT_EQ(integratorOf(scene.analysis.dynamics), Integrator::BackwardEuler);
  Result<Simulation> sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  const SoakGrip grip = soakGrip(body);
  const SoakResult r = soak(sim.value(), 20.0, hz, grip.point, grip.grab, grip.reach, 2026);
  EXPECT_EQ(r.failed, 0) << r.firstFailure;
  EXPECT_EQ(r.nonFinite, 0);
  EXPECT_EQ(r.steps, static_cast<long long>(20.0 * hz));
  // The drags moved the body (the handle held it: a node went at least half the reach).
  EXPECT_GT(r.largestMove, 0.5 * grip.reach);
}

INSTANTIATE_TEST_SUITE_P(Bodies, Soak,
                         ::testing::Combine(::testing::Values(std::string("liver"), std::string("beam")),
                                            ::testing::Values(90.0, 60.0)),
                         [](const ::testing::TestParamInfo<std::tuple<std::string, double>>& info) {
                           return std::get<0>(info.param) + "_" +
                                  std::to_string(static_cast<int>(std::get<1>(info.param))) + "Hz";
                         });

}  // namespace
}  // namespace corofem::test
