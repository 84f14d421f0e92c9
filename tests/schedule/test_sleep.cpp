// Sleeping bodies (analysis.sleep): a damped body that has come to rest stops being solved, and the
// answer moves by no more than the sleep thresholds allow.
#include "schedule_support.hpp"

#include <nlohmann/json.hpp>

#include <cmath>

namespace corofem::test {
namespace {

using nlohmann::json;

/// The cantilever under gravity and a tip force, damped near critically (first bending mode about
/// 10 rad/s, alpha = 20 1/s) so that it settles within the run.
Scene settlingScene(int steps) {
  BodyDesc body = boxBeam({10, 2, 2});
  body.material.youngsModulus = 1e7;
  body.material.rayleighMass = 20.0;
  Scene s = dynamicScene(body, steps);
  s.backend.kind = BackendKind::Reference;
  s.analysis.dynamics.timeStep = 0.01;
  // Backward Euler damps the high-frequency modes that Rayleigh mass damping leaves ringing.
  s.analysis.dynamics.integrator = Integrator::BackwardEuler;
  return s;
}

json sleepInfo(const Simulation& sim) {
  return json::parse(sim.schedulerReport())["bodies"][0]["sleep"];
}

TEST(Sleep, RestingBodySleepsAndTheAnswerMovesLessThanTheThresholdAllows) {
  HookScope scope;
  const int steps = 300;
  Scene awake = settlingScene(steps);
  auto ref = Simulation::create(awake);
  ASSERT_TRUE(ref) << ref.message();
  const std::vector<double> expected = runToEnd(ref.value());

  Scene sleepy = awake;
  sleepy.analysis.dynamics.sleep.enabled = true;
  sleepy.analysis.dynamics.sleep.velocity = 1e-4;
  sleepy.analysis.dynamics.sleep.steps = 5;
  auto sim = Simulation::create(sleepy);
  ASSERT_TRUE(sim) << sim.message();
  int idle = 0;
  while (!sim->finished()) {
    StepReport r;
    ASSERT_TRUE(sim->step(&r));
    if (r.newtonIterations == 0) ++idle;
  }
  const json info = sleepInfo(sim.value());
  ASSERT_TRUE(info.is_object());
  EXPECT_TRUE(info["asleep"].get<bool>()) << info;
  const long long slept = info["slept_steps"].get<long long>();
  EXPECT_GT(slept, 0) << info;
  EXPECT_EQ(slept, idle);
  std::vector<double> x;
  ASSERT_TRUE(sim->readPositions(0, x));
  double worst = 0;
  for (std::size_t i = 0; i < x.size(); ++i) worst = std::max(worst, std::abs(x[i] - expected[i]));
  // Bound: asleep, the body misses motion slower than the threshold, at most velocity x time asleep.
  const double bound = sleepy.analysis.dynamics.sleep.velocity * slept * sleepy.analysis.dynamics.timeStep;
  EXPECT_LE(worst, bound) << "slept " << slept << " steps";
  std::cout << "[ measured ] slept " << slept << " of " << steps << " steps; largest position change " << worst
            << " m (bound " << bound << " m)\n";
  std::vector<double> v;
  ASSERT_TRUE(sim->readVelocities(0, v));
  for (double c : v) EXPECT_EQ(c, 0.0);  // a sleeping body is at rest
}

TEST(Sleep, ARampingLoadKeepsTheBodyAwake) {
  HookScope scope;
  Scene s = settlingScene(120);
  s.analysis.dynamics.sleep.enabled = true;
  s.analysis.dynamics.sleep.steps = 3;
  s.analysis.dynamics.sleep.velocity = 1.0;  // every step is slow enough: only the load keeps it awake
  for (LoadDesc& l : s.bodies[0].loads) l.rampTime = 100.0;  // grows by h / t >= 8e-3 of itself per step (t <= 1.2 s)
  auto sim = Simulation::create(s);
  ASSERT_TRUE(sim) << sim.message();
  runToEnd(sim.value());
  EXPECT_EQ(sleepInfo(sim.value())["slept_steps"], 0);
}

TEST(Sleep, ALoadChangeWakesTheBody) {
  // The body falls asleep under a slow ramp (the per-step change is below load_change), and wakes
  // once the load has drifted from the one it fell asleep under by more than load_change.
  HookScope scope;
  Scene s = settlingScene(100);
  s.analysis.dynamics.sleep.enabled = true;
  s.analysis.dynamics.sleep.steps = 3;
  s.analysis.dynamics.sleep.velocity = 1.0;
  s.analysis.dynamics.sleep.loadChange = 5e-3;  // per step at t: h / t = 0.01 / t < 5e-3 beyond t = 2 s
  for (LoadDesc& l : s.bodies[0].loads) l.rampTime = 1e9;  // f grows linearly the whole run
  s.analysis.dynamics.steps = 400;
  auto sim = Simulation::create(s);
  ASSERT_TRUE(sim) << sim.message();
  runToEnd(sim.value());
  const json info = sleepInfo(sim.value());
  EXPECT_GT(info["slept_steps"].get<long long>(), 0) << info;
  EXPECT_GT(info["wakes"].get<long long>(), 0) << info;
  std::cout << "[ measured ] " << info << "\n";
}

TEST(Sleep, SceneKey) {
  const std::string base = R"({"bodies": [{"mesh": {"box": {}}}], "analysis": {"type": "dynamic", "sleep": )";
  auto on = parseScene(base + "true}}", "");
  ASSERT_TRUE(on) << on.message();
  EXPECT_TRUE(on->analysis.dynamics.sleep.enabled);
  EXPECT_EQ(on->analysis.dynamics.sleep.steps, 10);
  auto set = parseScene(base + R"({"velocity": 1e-3, "load_change": 1e-4, "steps": 4}}})", "");
  ASSERT_TRUE(set) << set.message();
  EXPECT_TRUE(set->analysis.dynamics.sleep.enabled);
  EXPECT_EQ(set->analysis.dynamics.sleep.velocity, 1e-3);
  EXPECT_EQ(set->analysis.dynamics.sleep.loadChange, 1e-4);
  EXPECT_EQ(set->analysis.dynamics.sleep.steps, 4);
  auto off = parseScene(base + "false}}", "");
  ASSERT_TRUE(off);
  EXPECT_FALSE(off->analysis.dynamics.sleep.enabled);
  auto bad = parseScene(base + R"({"speed": 1}}})", "");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("analysis.sleep"), std::string::npos) << bad.message();
  auto neg = parseScene(base + R"({"velocity": -1}}})", "");
  ASSERT_FALSE(neg);
  EXPECT_NE(neg.message().find("velocity"), std::string::npos) << neg.message();
  auto stat = parseScene(R"({"bodies": [{"mesh": {"box": {}}}], "analysis": {"type": "static", "sleep": true}})", "");
  ASSERT_FALSE(stat);
  EXPECT_NE(stat.message().find("dynamic"), std::string::npos) << stat.message();
}

}  // namespace
}  // namespace corofem::test
