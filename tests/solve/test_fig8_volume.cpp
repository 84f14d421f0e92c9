// The paper's Fig. 8: a soft beam of 8 x 1 x 1 cells x 5 tets, clamped at one end, under gravity.
// The linear formulation cannot follow the large rotations of the elements near the free end and
// "artificially enlarges" the volume; the co-rotational one keeps it.
//
// Beam 0.8 x 0.1 x 0.1 m (as samples/fig8_beam), E = 2e5 Pa, nu = 0.3, rho = 1000 kg/m^3, gravity
// -9.81 m/s^2 in y. Euler-Bernoulli would give q L^4 / (8 E I) = 3.0 m of tip deflection (far beyond
// small deflections); the coarse locked mesh gives 1.07 m linearly, i.e. more than the length, so
// the tip rotates a lot (the co-rotational tip ends ~0.6 m down and ~0.3 m back).
#include "beam_helpers.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

namespace corofem {
namespace {

using namespace corofem::test;

constexpr double kFig8Length = 0.8;

BodyDesc fig8Beam(Formulation formulation) {
  BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {kFig8Length, 0.1, 0.1}, {8, 1, 1}), 0.0, 2e5, 0.3, 1000.0,
                                 formulation);
  body.loads.push_back(gravity({0, -9.81, 0}));
  return body;
}

struct Fig8Outcome {
  double volume = NAN;  // deformed / rest
  Vec3 tip{NAN, NAN, NAN};
};

Fig8Outcome staticOutcome(Formulation formulation, int increments = 10) {
  Scene scene = staticScene(fig8Beam(formulation), increments);  // default Newton settings
  Fig8Outcome o;
  auto sim = Simulation::create(scene);
  if (!sim) {
    ADD_FAILURE() << sim.message();
    return o;
  }
  if (!runToEnd(sim.value())) return o;
  o.volume = volumeRatio(sim.value());
  o.tip = meanDisplacement(sim.value(), planeX(kFig8Length));
  return o;
}

TEST(Fig8, LinearGrowsTheVolumeCorotationalKeepsIt) {
  const Fig8Outcome linear = staticOutcome(Formulation::Linear);
  const Fig8Outcome corot = staticOutcome(Formulation::Corotational);
  std::cout << "  Fig. 8 beam (static, gravity): linear formulation volume change " << 100 * (linear.volume - 1)
            << " %, tip (" << linear.tip[0] << ", " << linear.tip[1] << ") m\n"
            << "                                 co-rotational volume change " << 100 * (corot.volume - 1)
            << " %, tip (" << corot.tip[0] << ", " << corot.tip[1] << ") m\n";
  // Measured: linear +199 %, co-rotational -0.22 %.
  EXPECT_GT(linear.volume - 1, 0.5);  // "visibly" larger: the linear solution at least 1.5x the volume
  EXPECT_GT(std::abs(linear.volume - 1), 10 * std::abs(corot.volume - 1));
  // "Within a few per cent": the co-rotational elements keep their small-strain volume change
  // (nu = 0.3, strains of a few per cent at most); 3 %.
  EXPECT_LT(std::abs(corot.volume - 1), 0.03);
  // The deflection is large: the tip falls by most of the length and moves back towards the clamp.
  EXPECT_LT(corot.tip[1], -0.5 * kFig8Length);
  EXPECT_LT(corot.tip[0], -0.2 * kFig8Length);
  // The linear solution moves the tip straight down, by more than the length.
  EXPECT_LT(linear.tip[1], -kFig8Length);
  EXPECT_NEAR(linear.tip[0], 0.0, 1e-9);
}

/// The sample's interactive set-up: Newmark, h = 0.01 s, one linearised Newton step per frame, PCG,
/// mass-proportional damping.
Scene fig8Dynamic(double gamma, int steps) {
  BodyDesc body = fig8Beam(Formulation::Corotational);
  body.material.rayleighMass = 4.0;
  Scene scene;
  scene.bodies.push_back(body);
  scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.timeStep = 0.01;
  scene.analysis.dynamics.steps = steps;
  scene.analysis.dynamics.newmarkGamma = gamma;
  scene.analysis.dynamics.newmarkBeta = (gamma + 0.5) * (gamma + 0.5) / 4;  // the matching beta
  scene.solver.tolerance = 1e-8;
  scene.backend.kind = BackendKind::Reference;
  return scene;
}

TEST(Fig8, FullLoadInOneIncrementGivesTheSameAnswer) {
  // The paper (Sec. 4): the co-rotational formulation "allows ... even the application of full load
  // in one step". With the default 30 Newton iterations the full load from rest needs 31 here, so
  // the automatic cut-back halves it once; the answer is the 10-increment one.
  const Fig8Outcome one = staticOutcome(Formulation::Corotational, 1);
  const Fig8Outcome ten = staticOutcome(Formulation::Corotational, 10);
  // 1e-6 m: both converged to residual 1e-6 relative on a tip displacement of ~0.6 m.
  EXPECT_NEAR(one.tip[0], ten.tip[0], 1e-6);
  EXPECT_NEAR(one.tip[1], ten.tip[1], 1e-6);
}

TEST(Fig8, DampedDynamicsSettlesOnTheStaticSolution) {
  // gamma = 0.6: Newmark with numerical dissipation of the highest modes. With gamma = 1/2 the
  // linearised step feeds energy into this beam (next test).
  auto sim = Simulation::create(fig8Dynamic(0.6, 600));
  ASSERT_TRUE(sim) << sim.message();
  double worstVolume = 0;
  while (!sim->finished()) {
    StepReport report;
    Status st = sim->step(&report);
    ASSERT_TRUE(st) << st.message();
    worstVolume = std::max(worstVolume, std::abs(volumeRatio(sim.value()) - 1));
  }
  const Fig8Outcome reference = staticOutcome(Formulation::Corotational);
  const Vec3 tip = meanDisplacement(sim.value(), planeX(kFig8Length));
  std::cout << "  dynamic co-rotational after 6 s: tip (" << tip[0] << ", " << tip[1] << ") m, static ("
            << reference.tip[0] << ", " << reference.tip[1] << ") m; worst volume change on the way "
            << 100 * worstVolume << " %\n";
  EXPECT_LT(worstVolume, 0.05);  // no transient ever inflates it (a few per cent of dynamic strain)
  // 5 mm (0.6 % of L): the remaining oscillation after 6 s at zeta ~ alpha / (2 omega_1) plus the
  // one-Newton-iteration-per-step error, which vanishes as the motion stops.
  EXPECT_NEAR(tip[0], reference.tip[0], 5e-3);
  EXPECT_NEAR(tip[1], reference.tip[1], 5e-3);
}

TEST(Fig8, LinearisedTrapezoidalStepFailsCleanlyInsteadOfExploding) {
  // Average-acceleration Newmark (gamma = 1/2) with one linearised Newton iteration per step: on
  // this beam the motion settles, then gains energy from ~2 s on and explodes (to 1e37 m by step
  // 600) unless it is stopped; the energy guard stops it at step 240 (measured). The run must either
  // stay sane or stop with SolveFailed naming the fix, keeping a sane last state; it must never
  // return absurd positions.
  auto sim = Simulation::create(fig8Dynamic(0.5, 600));
  ASSERT_TRUE(sim) << sim.message();
  Status status;
  while (!sim->finished()) {
    status = sim->step();
    if (!status) break;
  }
  if (!status) {
    std::cout << "  gamma = 1/2, one Newton iteration: stopped at step " << sim->stepsTaken() + 1 << ": "
              << status.message() << "\n";
    EXPECT_EQ(status.code(), ErrorCode::SolveFailed);
    EXPECT_NE(status.message().find("newton_iterations"), std::string::npos);
    EXPECT_NE(status.message().find("body 'beam'"), std::string::npos);
  }
  std::vector<double> x;
  ASSERT_TRUE(sim->readPositions(0, x));
  for (double c : x) ASSERT_TRUE(std::isfinite(c));
  EXPECT_LT(std::abs(volumeRatio(sim.value()) - 1), 0.05);
  const Vec3 tip = meanDisplacement(sim.value(), planeX(kFig8Length));
  EXPECT_LT(std::hypot(tip[0], tip[1]), kFig8Length);  // still a beam hanging from its clamp
  // Failing cleanly also means a caller can continue with a remedy: the same state, more Newton
  // iterations, is the documented fix. (Not exercised here: the scene is fixed at create().)
}

}  // namespace
}  // namespace corofem
