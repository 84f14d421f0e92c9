// Nothing non-finite reaches the user's buffers. Non-finite input is refused where it enters
// (scene parser, Simulation::create); absurd but finite input that makes the solve overflow must
// end in a SolveFailed step with the last good (finite) state in readPositions / readVelocities.
#include "extremes_support.hpp"

#include <cstdio>
#include <functional>
#include <limits>

namespace corofem::test {
namespace {

const char* kSceneWithGravity = R"({
  "bodies": [{"mesh": {"box": {"min": [0, 0, 0], "max": [0.4, 0.1, 0.1], "cells": [4, 1, 1]}},
              "fixed": [{"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}}],
              "loads": [{"type": "gravity", "vector": GRAVITY}]}],
  "analysis": {"type": "dynamic", "time_step": 0.01, "steps": 2}
})";

std::string withGravity(const std::string& vector) {
  std::string text = kSceneWithGravity;
  text.replace(text.find("GRAVITY"), 7, vector);
  return text;
}

TEST(NonFiniteInput, SceneParserRejectsNaNAndInfiniteGravity) {
  // The control case parses, so the refusals below are about the numbers.
  Result<Scene> ok = parseScene(withGravity("[0, -9.81, 0]"), ".");
  ASSERT_TRUE(ok) << ok.message();
  // JSON has no NaN or Infinity literal: the parser must refuse them with a position, not read 0.
  for (const std::string& bad : {"[NaN, -9.81, 0]", "[0, Infinity, 0]", "[0, -1e999, 0]", "[0, nan, 0]"}) {
    Result<Scene> scene = parseScene(withGravity(bad), ".");
    ASSERT_FALSE(scene) << bad << " was accepted";
    EXPECT_EQ(scene.status().code(), ErrorCode::BadInput);
    EXPECT_NE(scene.message().find("line"), std::string::npos) << scene.message();
    std::printf("  %s -> %s\n", bad.c_str(), scene.message().c_str());
  }
  // --set overrides go through the same number check.
  Result<Scene> overridden = parseScene(withGravity("[0, -9.81, 0]"), ".", {"bodies.0.loads.0.vector=[0,1e999,0]"});
  EXPECT_FALSE(overridden);
  if (!overridden) std::printf("  --set 1e999 -> %s\n", overridden.message().c_str());
}

TEST(NonFiniteInput, SimulationCreateRejectsNonFiniteSceneValues) {
  // A Scene filled in code bypasses the parser: Simulation::create must refuse non-finite values
  // of the loads, material and initial velocity (BadInput naming the body).
  Result<Scene> parsed = parseScene(withGravity("[0, -9.81, 0]"), ".");
  ASSERT_TRUE(parsed);
  const double nan = std::nan(""), inf = std::numeric_limits<double>::infinity();
  const std::vector<std::pair<std::string, std::function<void(Scene&)>>> cases = {
      {"NaN gravity", [&](Scene& s) { s.bodies[0].loads[0].vector = {0, nan, 0}; }},
      {"infinite gravity", [&](Scene& s) { s.bodies[0].loads[0].vector = {0, -inf, 0}; }},
      {"NaN Young's modulus", [&](Scene& s) { s.bodies[0].material.youngsModulus = nan; }},
      {"NaN density", [&](Scene& s) { s.bodies[0].material.density = nan; }},
      {"infinite initial velocity", [&](Scene& s) { s.bodies[0].initialVelocity = {inf, 0, 0}; }},
      {"NaN angular velocity", [&](Scene& s) { s.bodies[0].initialAngularVelocity = {0, 0, nan}; }},
  };
  for (const auto& [what, mutate] : cases) {
    Scene scene = parsed.value();
    scene.backend.kind = BackendKind::Reference;
    mutate(scene);
    Result<Simulation> sim = Simulation::create(scene);
    EXPECT_FALSE(sim) << what << " was accepted";
    if (!sim) {
      EXPECT_EQ(sim.status().code(), ErrorCode::BadInput) << what;
      std::printf("  %s -> %s\n", what.c_str(), sim.message().c_str());
    }
  }
}

class NonFiniteSolve : public testing::TestWithParam<BackendCase> {};

TEST_P(NonFiniteSolve, AbsurdParametersFailCleanlyWithFiniteBuffers) {
  // Finite but absurd values that overflow somewhere inside the solve (in float on OpenCL the
  // overflow comes earlier, at 3.4e38). Each runs up to 3 steps; every step must be ok or
  // SolveFailed, the buffers finite after every step, and a failed step must keep the last good
  // state. The cases marked "must fail" overflow in double too (1e300 squared), so they must end in
  // SolveFailed rather than silently produce a "result".
  const BackendCase& c = GetParam();
  COROFEM_SKIP_ABSENT(c);
  struct Case {
    std::string what;
    std::function<void(Scene&)> mutate;
    bool mustFail;
  };
  const std::vector<Case> cases = {
      {"gravity 1e300 m/s^2", [](Scene& s) { s.bodies[0].loads[0].vector = {0, -1e300, 0}; }, true},
      {"initial velocity 1e300 m/s", [](Scene& s) { s.bodies[0].initialVelocity = {0, 1e300, 0}; }, true},
      {"time step 1e300 s", [](Scene& s) { s.analysis.dynamics.timeStep = 1e300; }, true},
      {"E = 1e300 Pa", [](Scene& s) { s.bodies[0].material.youngsModulus = 1e300; }, false},
      {"density 1e-300 kg/m^3", [](Scene& s) { s.bodies[0].material.density = 1e-300; }, false},
      {"time step 1e-300 s", [](Scene& s) { s.analysis.dynamics.timeStep = 1e-300; }, false},
      {"Rayleigh mass damping 1e300 1/s", [](Scene& s) { s.bodies[0].material.rayleighMass = 1e300; }, false},
      {"NaN time step", [](Scene& s) { s.analysis.dynamics.timeStep = std::nan(""); }, true},
  };
  Result<Scene> parsed = parseScene(withGravity("[0, -9.81, 0]"), ".");
  ASSERT_TRUE(parsed);
  for (const Case& k : cases) {
    Scene scene = parsed.value();
    scene.backend.kind = c.kind;
    scene.backend.device = c.device;
    scene.solver.precision = c.precision;
    scene.analysis.dynamics.steps = 3;
    k.mutate(scene);
    std::string skip;
    auto sim = createSim(scene, &skip);
    if (!skip.empty()) GTEST_SKIP() << skip;
    if (!sim) {
      ADD_FAILURE() << k.what << ": create failed";
      continue;
    }
    std::string outcome = "all steps ok";
    bool failed = false;
    while (!sim->finished()) {
      std::vector<double> before;
      ASSERT_TRUE(sim->readPositions(0, before));
      const Status st = sim->step();
      std::vector<double> x, v;
      ASSERT_TRUE(sim->readPositions(0, x));
      ASSERT_TRUE(sim->readVelocities(0, v));
      EXPECT_TRUE(allFinite(x) && allFinite(v)) << k.what << ": non-finite buffer after step " << sim->stepsTaken() + 1;
      if (!st) {
        EXPECT_EQ(st.code(), ErrorCode::SolveFailed) << k.what << ": " << st.message();
        EXPECT_EQ(x, before) << k.what << ": a failed step must keep the last good state";
        outcome = "step " + std::to_string(sim->stepsTaken() + 1) + " SolveFailed: " + st.message().substr(0, 150);
        failed = true;
        break;
      }
    }
    std::printf("  %s, %s: %s (max |x| %.3e m)\n", c.describe().c_str(), k.what.c_str(), outcome.c_str(), [&] {
      std::vector<double> x;
      sim->readPositions(0, x);
      return maxAbs(x);
    }());
    if (k.mustFail) EXPECT_TRUE(failed) << k.what << " produced a 'result'";
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, NonFiniteSolve, testing::ValuesIn(backendCases()), caseName);

}  // namespace
}  // namespace corofem::test
