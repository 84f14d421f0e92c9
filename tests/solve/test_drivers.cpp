// Unit tests of the backend-independent drivers (statics Newton, Newmark, backward Euler) on a
// mock spring-chain backend with closed-form answers (tests/solve/mock_backend.hpp).
#include "mock_backend.hpp"

#include "common/body_drivers.hpp"
#include "util/error.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <vector>

namespace corofem {
namespace {

using detail::BodyStepStats;
using test::DynamicSolver;
using test::StaticSolver;
using test::SpringChainBackend;
using test::springChainProblem;

constexpr double kTwoPi = 2 * 3.14159265358979323846;

/// Tip force (N) on the last node of the chain.
void addTipForce(detail::Problem& p, const Eigen::Vector3d& force, double rampTime = 0.0) {
  detail::ExternalForce f;
  f.f = Eigen::VectorXd::Zero(p.restPositions.size());
  f.f.tail<3>() = force;
  f.rampTime = rampTime;
  p.forces.push_back(f);
}

// ------------------------------------------------------------------------------------- statics

TEST(StaticNewton, LinearChainConvergesInOneIteration) {
  detail::Problem p = springChainProblem(5, 1.0);
  addTipForce(p, {2.0, -3.0, 0.5});
  SpringChainBackend backend(p, 10.0);
  StaticSolver solver(p, backend, StaticDesc{});
  const BodyStepStats stats = solver.step(1, 1);
  // A linear problem solved exactly: one Newton iteration, the "linear increment" rule accepts it.
  EXPECT_EQ(stats.newtonIterations, 1);
  EXPECT_TRUE(stats.converged);
  // Four springs in series each carry the tip force: u_tip = 4 F / k, u_i = i F / k.
  for (int i = 0; i < 5; ++i)
    for (int c = 0; c < 3; ++c) {
      const double f = c == 0 ? 2.0 : (c == 1 ? -3.0 : 0.5);
      // 1e-12: the exact LDLT answer up to rounding of a 12x12 solve.
      EXPECT_NEAR(solver.positions()[3 * i + c] - p.restPositions[3 * i + c], i * f / 10.0, 1e-12);
    }
  // External work of a load applied in one increment (trapezoidal rule) is F.u / 2 = elastic energy.
  EXPECT_NEAR(solver.externalWork(), solver.elasticEnergy(), 1e-12);
}

TEST(StaticNewton, HardeningChainConvergesToEquilibrium) {
  detail::Problem p = springChainProblem(4, 1.0);
  const double force = 50.0, k = 10.0, k3 = 40.0;
  addTipForce(p, {force, 0.0, 0.0});
  SpringChainBackend backend(p, k, k3);
  StaticDesc desc;
  desc.residualTolerance = 1e-10;
  StaticSolver solver(p, backend, desc);
  const BodyStepStats stats = solver.step(1, 1);
  EXPECT_GT(stats.newtonIterations, 2);  // genuinely nonlinear: Newton needs several iterations
  EXPECT_LE(stats.residual, 1e-10);
  // Each spring carries F: k e + k3 e^3 = F, solved here by scalar Newton.
  double e = force / k;
  for (int i = 0; i < 100; ++i) e -= (k * e + k3 * e * e * e - force) / (k + 3 * k3 * e * e);
  // 1e-9: residual tolerance 1e-10 relative to F = 50 N over a tangent of ~100 N/m.
  EXPECT_NEAR(solver.positions()[9] - 3.0, 3 * e, 1e-9);
}

TEST(StaticNewton, IncrementsScalePrescribedDisplacementAndLoad) {
  detail::Problem p = springChainProblem(5, 1.0);
  detail::PrescribedDisplacement handle;
  handle.dofs = {12, 13};  // node 4, x and y
  handle.values = {0.8, -0.4};
  p.prescribed.push_back(handle);
  p.constrained[12] = p.constrained[13] = 1;
  SpringChainBackend backend(p, 3.0);
  StaticDesc desc;
  StaticSolver solver(p, backend, desc);
  for (int k = 1; k <= 4; ++k) {
    solver.step(k, 4);
    const double lambda = k / 4.0;
    // Springs in series between two held ends: linear interpolation of the handle displacement.
    for (int i = 0; i < 5; ++i) {
      EXPECT_NEAR(solver.positions()[3 * i] - i, lambda * 0.8 * i / 4.0, 1e-12);  // exact solve, rounding
      EXPECT_NEAR(solver.positions()[3 * i + 1], lambda * -0.4 * i / 4.0, 1e-12);
    }
  }
}

TEST(StaticNewton, NonConvergenceKeepsLastIncrementAndExplains) {
  detail::Problem p = springChainProblem(4, 1.0);
  addTipForce(p, {500.0, 0.0, 0.0});
  SpringChainBackend backend(p, 1.0, 100.0);
  StaticDesc desc;
  desc.maxNewtonIterations = 2;  // far too few for a strongly hardening chain from rest
  StaticSolver solver(p, backend, desc);
  try {
    solver.step(1, 3);
    FAIL() << "expected SolveFailed";
  } catch (const detail::Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::SolveFailed);
    const std::string message = e.what();
    EXPECT_NE(message.find("body 'chain'"), std::string::npos) << message;
    EXPECT_NE(message.find("increment 1/3"), std::string::npos) << message;
    EXPECT_NE(message.find("did not converge in 2 Newton iterations"), std::string::npos) << message;
    EXPECT_NE(message.find("analysis.increments"), std::string::npos) << message;
  }
  // The state is the last converged one: the rest state.
  EXPECT_EQ(solver.positions(), p.restPositions);
}

TEST(StaticNewton, CutBackRescuesAnIncrementTooLargeForTheIterationLimit) {
  detail::Problem p = springChainProblem(4, 1.0);
  const double force = 500.0, k = 1.0, k3 = 100.0;
  addTipForce(p, {force, 0.0, 0.0});
  SpringChainBackend backend(p, k, k3);
  StaticDesc desc;
  desc.maxNewtonIterations = 6;  // too few for the full load from rest, enough for part of it
  StaticSolver solver(p, backend, desc);
  const BodyStepStats stats = solver.step(1, 1);
  EXPECT_TRUE(stats.converged);
  EXPECT_GT(stats.newtonIterations, 6);  // the failed full attempt plus the sub-increments
  double e = std::cbrt(force / k3);
  for (int i = 0; i < 100; ++i) e -= (k * e + k3 * e * e * e - force) / (k + 3 * k3 * e * e);
  // 1e-6: residual tolerance 1e-6 relative to F = 500 N over a tangent of ~1e4 N/m.
  EXPECT_NEAR(solver.positions()[9] - 3.0, 3 * e, 1e-6);
}

TEST(StaticNewton, NonFiniteForcesFailAndKeepState) {
  detail::Problem p = springChainProblem(3, 1.0);
  addTipForce(p, {1.0, 0.0, 0.0});
  SpringChainBackend backend(p, 10.0);
  StaticSolver solver(p, backend, StaticDesc{});
  solver.step(1, 2);
  const Eigen::VectorXd good = solver.positions();
  backend.nanAfterForceCalls = backend.forceCalls;  // the next force evaluation returns a NaN
  EXPECT_THROW(solver.step(2, 2), detail::Error);
  EXPECT_EQ(solver.positions(), good);
  EXPECT_TRUE(solver.positions().allFinite());
}

// ------------------------------------------------------------------------------------- dynamics

/// One free node on a spring (3 independent oscillators), released from u0 at rest.
struct Oscillator {
  detail::Problem problem = springChainProblem(2, 2.0);
  double k = 8.0, m = 2.0;  // omega = 2 rad/s
  double omega() const { return std::sqrt(k / m); }
};

/// Runs `steps` steps of a free vibration that starts from a displacement: a constant tip force
/// applied for t <= 0 is not available, so the oscillator starts from rest with a sudden constant
/// force F (equilibrium F/k): u(t) = F/k (1 - cos omega t), total energy conserved with the work.
struct History {
  std::vector<double> time, u, total, kinetic, elastic;
};
History runOscillator(Oscillator& osc, const DynamicDesc& desc, int steps, double force, double rayleighMass = 0.0,
                      double rayleighStiffness = 0.0) {
  osc.problem.rayleighMass = rayleighMass;
  osc.problem.rayleighStiffness = rayleighStiffness;
  addTipForce(osc.problem, {force, 0.0, 0.0});
  SpringChainBackend backend(osc.problem, osc.k);
  DynamicSolver solver(osc.problem, backend, desc);
  History run;
  for (int s = 1; s <= steps; ++s) {
    solver.step(s, steps);
    run.time.push_back(solver.time());
    run.u.push_back(solver.positions()[3] - 1.0);
    const double kin = solver.kineticEnergy(), el = solver.elasticEnergy();
    run.kinetic.push_back(kin);
    run.elastic.push_back(el);
    run.total.push_back(kin + el - solver.externalWork());
  }
  return run;
}

/// Mean period from the up-crossings of u about `mean` (linear interpolation; the error of the
/// interpolation is O(h^3) at a zero of the sine and does not accumulate over cycles).
double measuredPeriod(const History& run, double mean) {
  std::vector<double> crossings;
  for (std::size_t i = 1; i < run.u.size(); ++i) {
    const double a = run.u[i - 1] - mean, b = run.u[i] - mean;
    if (a < 0 && b >= 0) crossings.push_back(run.time[i - 1] + (run.time[i] - run.time[i - 1]) * a / (a - b));
  }
  if (crossings.size() < 2) return NAN;
  return (crossings.back() - crossings.front()) / static_cast<double>(crossings.size() - 1);
}

TEST(Newmark, AverageAccelerationConservesEnergyOfLinearSystem) {
  Oscillator osc;
  DynamicDesc desc;
  desc.timeStep = 0.05;
  const History run = runOscillator(osc, desc, 1000, 4.0);
  // E = kinetic + elastic - external work. The trapezoidal rule (beta 1/4, gamma 1/2) conserves the
  // energy norm of a linear system exactly; only rounding remains. 1e-8 relative as the brief asks
  // (observed ~1e-15). The scale is the largest elastic energy.
  const double scale = *std::max_element(run.elastic.begin(), run.elastic.end());
  ASSERT_GT(scale, 0.5);  // the oscillator really moves: F^2 / (2k) * 4 = 4 J at the far turning point
  for (double e : run.total) EXPECT_NEAR(e, 0.0, 1e-8 * scale);
}

TEST(Newmark, PeriodElongationMatchesTheory) {
  Oscillator osc;
  DynamicDesc desc;
  const double omegaH = 0.5;
  desc.timeStep = omegaH / osc.omega();
  const History run = runOscillator(osc, desc, 2000, 4.0);
  // Average acceleration: tan(omegaBar h / 2) = omega h / 2, so T_num / T = (omega h / 2) / atan(omega h / 2).
  const double expected = (omegaH / 2) / std::atan(omegaH / 2);
  const double measured = measuredPeriod(run, 4.0 / osc.k) / (kTwoPi / osc.omega());
  // 1e-5: the interpolation error of the crossings, O((omega h)^3) per crossing, divided by ~150
  // cycles; the elongation itself is 2.1e-2, so the test separates the formula from T_num = T.
  EXPECT_NEAR(measured, expected, 1e-5) << "measured T/T0 " << measured << ", theory " << expected;
}

TEST(Newmark, NewtonConvergesForHardeningSpring) {
  Oscillator osc;
  addTipForce(osc.problem, {20.0, 0.0, 0.0});
  SpringChainBackend backend(osc.problem, osc.k, 30.0);
  DynamicDesc desc;
  desc.timeStep = 0.05;
  desc.newtonIterations = 20;
  desc.newtonTolerance = 1e-12;
  DynamicSolver solver(osc.problem, backend, desc);
  double worst = 0;
  int maxIterations = 0;
  for (int s = 1; s <= 200; ++s) {
    const BodyStepStats st = solver.step(s, 200);
    worst = std::max(worst, st.residual);
    maxIterations = std::max(maxIterations, st.newtonIterations);
  }
  EXPECT_LE(worst, 1e-12);          // every step reached the Newton tolerance
  EXPECT_GT(maxIterations, 1);      // the spring is nonlinear enough to need it
  EXPECT_LT(maxIterations, 20);
  // Energy of the nonlinear spring: the trapezoidal rule is not exactly conservative here, but it
  // stays bounded; 1e-2 of the energy scale over 200 steps (h = 0.05, omega ~ 2-10 rad/s).
  const double energy = solver.kineticEnergy() + solver.elasticEnergy() - solver.externalWork();
  EXPECT_NEAR(energy, 0.0, 1e-2 * 20.0 * 20.0 / osc.k);
}

TEST(BackwardEuler, EnergyDecreasesMonotonically) {
  Oscillator osc;
  DynamicDesc desc;
  desc.integrator = Integrator::BackwardEuler;
  desc.timeStep = 0.05;
  const History run = runOscillator(osc, desc, 2000, 4.0);
  // Backward Euler is dissipative: E_{n+1} < E_n whenever the body moves. Tolerance 1e-12 J allows
  // rounding once the motion has died out.
  for (std::size_t i = 1; i < run.total.size(); ++i) EXPECT_LE(run.total[i], run.total[i - 1] + 1e-12) << i;
  EXPECT_LT(run.total.back(), run.total.front() - 0.1);  // it really lost energy
  // It settles at the static equilibrium F / k.
  // The amplitude F/k shrinks by 1/sqrt(1 + (omega h)^2) per step: 0.5 e^{-9.95} = 2.4e-5 m after 2000
  // steps, below the 1e-4 m tolerance.
  EXPECT_NEAR(run.u.back(), 4.0 / osc.k, 1e-4);
}

TEST(Newmark, RayleighMassDampingDecaysAtTheRightRate) {
  Oscillator osc;
  DynamicDesc desc;
  desc.timeStep = 0.01;
  const double alpha = 0.2;  // zeta = alpha / (2 omega) = 0.05
  const History run = runOscillator(osc, desc, 4000, 4.0, alpha);
  // Successive maxima of u - F/k decay by exp(-zeta omega T_d) per period.
  std::vector<double> peaks;
  for (std::size_t i = 1; i + 1 < run.u.size(); ++i)
    if (run.u[i] > run.u[i - 1] && run.u[i] >= run.u[i + 1]) peaks.push_back(run.u[i] - 4.0 / osc.k);
  ASSERT_GE(peaks.size(), 4u);
  const double zeta = alpha / (2 * osc.omega());
  const double td = kTwoPi / (osc.omega() * std::sqrt(1 - zeta * zeta));
  const double expected = std::exp(-zeta * osc.omega() * td);
  // 2e-3: the sampled peaks sit within h of the true ones (relative error ~ (omega h)^2 / 2 = 2e-4)
  // plus the trapezoidal rule's O((omega h)^2) damping error.
  EXPECT_NEAR(peaks[2] / peaks[1], expected, 2e-3);
}

TEST(Newmark, RayleighStiffnessDampingDecaysAtTheRightRate) {
  // C = beta K: zeta = beta omega / 2. The damping term C v goes through Backend::apply with
  // SystemCoeffs{0, 1, 0}, and the system matrix through SystemCoeffs{1, h gamma, h^2 beta}.
  Oscillator osc;
  DynamicDesc desc;
  desc.timeStep = 0.01;
  const double beta = 0.05;  // zeta = 0.05
  const History run = runOscillator(osc, desc, 4000, 4.0, 0.0, beta);
  std::vector<double> peaks;
  for (std::size_t i = 1; i + 1 < run.u.size(); ++i)
    if (run.u[i] > run.u[i - 1] && run.u[i] >= run.u[i + 1]) peaks.push_back(run.u[i] - 4.0 / osc.k);
  ASSERT_GE(peaks.size(), 4u);
  const double zeta = beta * osc.omega() / 2;
  const double td = kTwoPi / (osc.omega() * std::sqrt(1 - zeta * zeta));
  // 2e-3: as for the mass-proportional case (sampled peaks, O((omega h)^2) scheme error).
  EXPECT_NEAR(peaks[2] / peaks[1], std::exp(-zeta * osc.omega() * td), 2e-3);
}

TEST(Dynamics, PrescribedDisplacementFollowsItsRamp) {
  for (Integrator integrator : {Integrator::Newmark, Integrator::BackwardEuler}) {
    detail::Problem p = springChainProblem(3, 1.0);
    detail::PrescribedDisplacement handle;
    handle.dofs = {7};  // node 2, y
    handle.values = {0.3};
    handle.rampTime = 0.5;
    p.prescribed.push_back(handle);
    p.constrained[7] = 1;
    SpringChainBackend backend(p, 5.0);
    DynamicDesc desc;
    desc.integrator = integrator;
    desc.timeStep = 0.1;
    DynamicSolver solver(p, backend, desc);
    for (int s = 1; s <= 10; ++s) {
      solver.step(s, 10);
      const double t = 0.1 * s;
      // Exact: v is chosen so that x(v) lands on the target (rounding only).
      EXPECT_NEAR(solver.positions()[7], 0.3 * std::min(1.0, t / 0.5), 1e-12);
      EXPECT_EQ(solver.positions()[0], 0.0);  // the fixed node does not move at all
      EXPECT_EQ(solver.velocities()[1], 0.0);
    }
    EXPECT_GT(std::abs(solver.positions()[4]), 1e-3);  // the middle node was dragged along
  }
}

TEST(Dynamics, NonFiniteForcesFailAndKeepLastGoodState) {
  Oscillator osc;
  addTipForce(osc.problem, {4.0, 0.0, 0.0});
  SpringChainBackend backend(osc.problem, osc.k);
  DynamicSolver solver(osc.problem, backend, DynamicDesc{});
  for (int s = 1; s <= 5; ++s) solver.step(s, 10);
  const Eigen::VectorXd x = solver.positions(), v = solver.velocities();
  const double t = solver.time();
  backend.nanAfterForceCalls = backend.forceCalls;
  try {
    solver.step(6, 10);
    FAIL() << "expected SolveFailed";
  } catch (const detail::Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::SolveFailed);
    const std::string message = e.what();
    EXPECT_NE(message.find("body 'chain'"), std::string::npos) << message;
    EXPECT_NE(message.find("time step 6/10"), std::string::npos) << message;
    EXPECT_NE(message.find("time_step"), std::string::npos) << message;
  }
  EXPECT_EQ(solver.positions(), x);
  EXPECT_EQ(solver.velocities(), v);
  EXPECT_EQ(solver.time(), t);
  // Recovers once the backend behaves again.
  backend.nanAfterForceCalls = -1;
  EXPECT_NO_THROW(solver.step(6, 10));
}

TEST(Dynamics, UnconvergedSolveWithGrowingResidualFailsTheStep) {
  Oscillator osc;
  addTipForce(osc.problem, {4.0, 0.0, 0.0});
  SpringChainBackend backend(osc.problem, osc.k, 1e4);  // strongly nonlinear
  DynamicDesc desc;
  desc.timeStep = 0.5;  // far too large for the hardening spring
  desc.newtonIterations = 2;
  DynamicSolver solver(osc.problem, backend, desc);
  backend.failLinearSolves = true;  // pretend PCG hit its cap
  // With a converged solve the step would simply be inaccurate; with an unconverged one and a
  // residual that grows, it must fail and keep the state.
  try {
    solver.step(1, 1);
    FAIL() << "expected SolveFailed";
  } catch (const detail::Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::SolveFailed);
    // What happened, not "blew up" (issue 27, item 11: it was said of capped solves that made no
    // progress): tests/solve/test_solve_hardening.cpp checks the PCG wording.
    EXPECT_NE(std::string(e.what()).find("did not reach solver.tolerance"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("the Newton residual grew from"), std::string::npos) << e.what();
  }
  EXPECT_EQ(solver.positions(), osc.problem.restPositions);
}

TEST(Dynamics, RunawayKineticEnergyIsDetected) {
  // A circulatory force (not in the tangent, no energy) feeds energy into the x-y motion without
  // any non-finite value or unconverged solve: kinetic + elastic energy outgrow everything the body
  // was given (initial energy + work of the load), and the step must fail before positions explode.
  Oscillator osc;
  addTipForce(osc.problem, {4.0, 0.0, 0.0});
  SpringChainBackend backend(osc.problem, osc.k);
  backend.circulation = 4.0;
  DynamicDesc desc;
  desc.timeStep = 0.05;
  DynamicSolver solver(osc.problem, backend, desc);
  int failedAt = 0;
  for (int s = 1; s <= 400 && !failedAt; ++s) {
    try {
      solver.step(s, 400);
    } catch (const detail::Error& e) {
      failedAt = s;
      EXPECT_EQ(e.code(), ErrorCode::SolveFailed);
      EXPECT_NE(std::string(e.what()).find("ran away"), std::string::npos) << e.what();
    }
  }
  ASSERT_GT(failedAt, 0) << "the runaway was not detected";
  // Caught while the state is still modest: the static deflection is 0.5 m, the guard fires when the
  // energy is 1.25x what the load gave (amplitudes ~1 m), long before an explosion.
  EXPECT_LT(solver.positions().cwiseAbs().maxCoeff(), 10.0);
  std::cout << "  circulatory pump caught at step " << failedAt << ", max |x| " << solver.positions().cwiseAbs().maxCoeff()
            << " m\n";
  EXPECT_TRUE(solver.positions().allFinite());
}

TEST(Dynamics, RollbackRestoresThePreviousStep) {
  Oscillator osc;
  addTipForce(osc.problem, {4.0, 0.0, 0.0});
  SpringChainBackend backend(osc.problem, osc.k);
  DynamicSolver solver(osc.problem, backend, DynamicDesc{});
  solver.step(1, 3);
  const Eigen::VectorXd x1 = solver.positions(), v1 = solver.velocities();
  const double w1 = solver.externalWork();
  solver.step(2, 3);
  const Eigen::VectorXd x2 = solver.positions(), v2 = solver.velocities();
  ASSERT_NE(x2, x1);
  solver.rollback();
  EXPECT_EQ(solver.positions(), x1);
  EXPECT_EQ(solver.velocities(), v1);
  EXPECT_EQ(solver.externalWork(), w1);
  EXPECT_DOUBLE_EQ(solver.time(), DynamicDesc{}.timeStep);
  // The step again from there: the same bits (the state before a step moves between the driver's
  // buffers without copies; none of them may hold a stale vector).
  solver.step(2, 3);
  EXPECT_EQ(solver.positions(), x2);
  EXPECT_EQ(solver.velocities(), v2);
  solver.step(3, 3);
  const Eigen::VectorXd x3 = solver.positions();
  solver.rollback();
  EXPECT_EQ(solver.positions(), x2);
  solver.step(3, 3);
  EXPECT_EQ(solver.positions(), x3);
}

}  // namespace
}  // namespace corofem
