// Failure policy (DynamicDesc::maxSubsteps, JSON "analysis.max_substeps"): a dynamic step that
// fails is retried from its start as 2, 4, ... substeps of h / k. The case: a cantilever (0.4 x 0.1
// x 0.1 m, 160 tets, E = 1e5 Pa) whose free end is dragged 0.3 m sideways within 0.05 s, integrated
// with the paper's linearised average-acceleration Newmark at h = 0.05 s. One linearised step of
// that violent drag feeds energy in (the runaway guard fires: KE + U > 1.25 x the work done);
// halving the step removes it.
#include "extremes_support.hpp"

namespace corofem::test {
namespace {

class FailurePolicy : public testing::TestWithParam<BackendCase> {};

Scene dragScene(const BackendCase& c, double h, int steps, int maxSubsteps) {
  BodyDesc body = makeBody(box({0, 0, 0}, {0.4, 0.1, 0.1}, {8, 2, 2}), 1e5, 0.3);
  body.fixed.push_back(planeSet(0, 0.0));
  LoadDesc drag;
  drag.kind = LoadDesc::Kind::Displacement;
  drag.vector = {0, 0.3, 0};
  drag.nodes = planeSet(0, 0.4);
  drag.rampTime = 0.05;
  body.loads.push_back(drag);
  Scene scene = dynamicScene(c, body, h, steps);
  scene.analysis.dynamics.maxSubsteps = maxSubsteps;
  return scene;
}

TEST_P(FailurePolicy, FailedStepIsRetriedInSubstepsAndMatchesTheSmallStep) {
  const BackendCase& c = GetParam();
  COROFEM_SKIP_ABSENT(c);
  constexpr double h = 0.05;
  constexpr int steps = 2;

  // 1. Without the policy the first step fails, cleanly: SolveFailed, the body stays at rest, and
  //    the message offers the policy.
  {
    COROFEM_CREATE_SIM(sim, dragScene(c, h, steps, 1));
    const Status st = sim->step();
    ASSERT_FALSE(st) << "the h = 0.05 s linearised drag step was expected to fail on " << c.describe();
    EXPECT_EQ(st.code(), ErrorCode::SolveFailed);
    EXPECT_NE(st.message().find("max_substeps"), std::string::npos) << st.message();
    EXPECT_EQ(sim->stepsTaken(), 0);
    std::vector<double> x;
    ASSERT_TRUE(sim->readPositions(0, x));
    EXPECT_EQ(x, sim->restMesh(0).nodes);
    std::cout << "  without substeps: " << st.message().substr(0, 160) << "...\n";
  }

  // 2. With max_substeps = 8 both steps pass, each by a retry (the driver reports the substeps).
  COROFEM_DIRECT_BODY(retried, dragScene(c, h, steps, 8));
  std::vector<int> used;
  detail::BodyStepStats first;
  for (int s = 1; s <= steps; ++s) {
    detail::BodyStepStats stats;
    try {
      stats = retried.solver->step(s, steps);
    } catch (const detail::Error& e) {
      FAIL() << "step " << s << " failed even with substeps: " << e.what();
    }
    used.push_back(stats.substeps);
    if (s == 1) first = stats;
  }
  std::cout << "  substeps used: " << used[0] << ", " << used[1] << "\n";
  ASSERT_GT(used[0], 1) << "step 1 should have needed a retry";
  ASSERT_EQ(used[0], used[1]) << "the comparison below assumes the same subdivision in both steps";

  // 3. The same through the Simulation API: every step succeeds.
  {
    COROFEM_CREATE_SIM(sim, dragScene(c, h, steps, 8));
    while (!sim->finished()) ASSERT_TRUE(sim->step()) << "Simulation with max_substeps = 8 failed";
  }

  // 4. The answer equals a run with h / k throughout: a retried step with k substeps is k full
  //    steps of the same scheme, so only rounding differs (substep end times are computed as
  //    t_n + h j / k instead of by accumulation). Bound: 1e-9 of the 0.3 m drag in double;
  //    float: 1e-4 of it (PCG to 1e-5 in float, two runs with different rounding).
  const int k = used[0];
  COROFEM_DIRECT_BODY(small, dragScene(c, h / k, steps * k, 1));
  int smallLinear = 0, smallNewton = 0;  // the first k small steps: the retried step's last attempt
  for (int s = 1; s <= steps * k; ++s) {
    detail::BodyStepStats st;
    ASSERT_NO_THROW(st = small.solver->step(s, steps * k));
    if (s <= k) smallLinear += st.linearIterations, smallNewton += st.newtonIterations;
  }
  // The retried step reports every attempt's iterations, the failed ones too (the cost paid).
  std::cout << "  step 1: " << first.newtonIterations << " Newton, " << first.linearIterations
            << " PCG iterations over every attempt; its last attempt alone about " << smallNewton << ", "
            << smallLinear << "\n";
  EXPECT_GT(first.linearIterations, smallLinear) << "the failed attempts' iterations are not counted";
  const double dx = (retried.solver->positions() - small.solver->positions()).cwiseAbs().maxCoeff();
  const double dv = (retried.solver->velocities() - small.solver->velocities()).cwiseAbs().maxCoeff();
  const double vScale = small.solver->velocities().cwiseAbs().maxCoeff();
  std::cout << "  retried vs h/" << k << " throughout: max |dx| " << dx << " m, max |dv| " << dv << " m/s (|v| up to "
            << vScale << " m/s)\n";
  const double rel = c.isFloat() ? 1e-4 : 1e-9;
  EXPECT_LT(dx, rel * 0.3);
  EXPECT_LT(dv, rel * std::max(vScale, 1.0));
}

TEST_P(FailurePolicy, HopelessStepFailsAfterEveryRetryAndKeepsState) {
  // A NaN time step cannot be cured by substeps: every subdivision fails, the message lists them,
  // the body keeps its (rest) state and nothing non-finite reaches the user's buffers.
  const BackendCase& c = GetParam();
  COROFEM_SKIP_ABSENT(c);
  // A Scene built in code can carry any double (the parser rejects a non-finite time_step).
  Scene nanScene = dragScene(c, std::nan(""), 3, 4);
  COROFEM_CREATE_SIM(nanSim, nanScene);
  const Status st = nanSim->step();
  ASSERT_FALSE(st);
  EXPECT_EQ(st.code(), ErrorCode::SolveFailed);
  EXPECT_NE(st.message().find("failed with 1, 2, 4 substeps"), std::string::npos) << st.message();
  std::vector<double> x, v;
  ASSERT_TRUE(nanSim->readPositions(0, x));
  ASSERT_TRUE(nanSim->readVelocities(0, v));
  EXPECT_TRUE(allFinite(x) && allFinite(v));
  EXPECT_EQ(x, nanSim->restMesh(0).nodes);
  std::cout << "  " << st.message().substr(0, 200) << "...\n";
}

INSTANTIATE_TEST_SUITE_P(Backends, FailurePolicy, testing::ValuesIn(backendCases()), caseName);

TEST(FailurePolicyScene, MaxSubstepsKeyIsParsedAndValidated) {
  const std::string text = R"({
    "bodies": [{"mesh": {"box": {"min": [0, 0, 0], "max": [1, 0.1, 0.1], "cells": [4, 1, 1]}}}],
    "analysis": {"type": "dynamic", "time_step": 0.01, "steps": 2, "max_substeps": 8}
  })";
  Result<Scene> scene = parseScene(text, ".");
  ASSERT_TRUE(scene) << scene.message();
  EXPECT_EQ(scene->analysis.dynamics.maxSubsteps, 8);
  Result<Scene> byDefault = parseScene(text, ".", {"analysis.max_substeps=1"});
  ASSERT_TRUE(byDefault) << byDefault.message();
  EXPECT_EQ(byDefault->analysis.dynamics.maxSubsteps, 1);
  EXPECT_EQ(DynamicDesc{}.maxSubsteps, 1);  // off unless asked for
  Result<Scene> zero = parseScene(text, ".", {"analysis.max_substeps=0"});
  ASSERT_FALSE(zero);
  EXPECT_EQ(zero.status().code(), ErrorCode::BadInput);
  EXPECT_NE(zero.message().find("max_substeps"), std::string::npos) << zero.message();
}

}  // namespace
}  // namespace corofem::test
