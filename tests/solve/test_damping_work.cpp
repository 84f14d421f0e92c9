// Issue 5, "a damping-free scene builds no damping code": what damping costs, measured by counting
// the device calls a dynamic step makes. Rayleigh damping C = alpha M + beta K_t has no kernel of
// its own on any backend (the OpenCL backend folds it into the two coefficients of M and K^R of
// the system matrix), so its only work is the residual's C v: one device apply per Newton
// evaluation with stiffness damping (beta > 0), none with mass damping alone (alpha M v, formed by
// the solver), and a damping-free problem must never ask for it.
#include "mock_backend.hpp"

#include "common/body_drivers.hpp"

#include <gtest/gtest.h>

namespace corofem {
namespace {

/// A device decorator that counts calls and remembers the coefficients of every solve.
class CountingBackend final : public test::ForwardingDevice {
 public:
  explicit CountingBackend(detail::Device& inner) : ForwardingDevice(inner) {}
  void internalForces(const detail::BodySet& b, const detail::Vectors& f) override {
    ++forces;
    ForwardingDevice::internalForces(b, f);
  }
  void apply(const detail::BodySet& b, const std::vector<detail::SystemCoeffs>& c, const detail::ConstVectors& p,
             const detail::Vectors& y) override {
    ++applies;
    ForwardingDevice::apply(b, c, p, y);
  }
  detail::LinearSolveStats solveDirect(std::size_t body, const detail::SystemCoeffs& c, const Eigen::VectorXd& b,
                                       Eigen::VectorXd& x) override {
    ++solves;
    lastCoeffs = c;
    return ForwardingDevice::solveDirect(body, c, b, x);
  }

  int forces = 0, applies = 0, solves = 0;
  detail::SystemCoeffs lastCoeffs;
};

struct Counts {
  int forces = 0, applies = 0, solves = 0;
  detail::SystemCoeffs coeffs;
};

/// Runs `steps` Newmark steps of a loaded spring chain with the given Rayleigh coefficients and
/// Newton iterations, and returns the device calls made by the steps (not by the set-up).
Counts runChain(double alpha, double beta, int newtonIterations, int steps) {
  detail::Problem p = test::springChainProblem(5, 1.0);
  p.rayleighMass = alpha;
  p.rayleighStiffness = beta;
  detail::ExternalForce f;
  f.f = Eigen::VectorXd::Zero(p.restPositions.size());
  f.f.tail<3>() = Eigen::Vector3d(1.0, -2.0, 0.5);
  p.forces.push_back(f);
  test::SpringChainBackend chain(p, 10.0, 5.0);  // hardening: Newton iterations do real work
  CountingBackend backend(chain);
  DynamicDesc desc;
  desc.timeStep = 0.01;
  desc.newtonIterations = newtonIterations;
  desc.newtonTolerance = 1e-14;  // never met early: every allowed iteration runs
  test::DynamicSolver solver(p, backend, desc);
  solver.step(1, steps);  // the first step also computes a_0 (one more force evaluation)
  const Counts before{backend.forces, backend.applies, backend.solves, {}};
  for (int s = 2; s <= steps; ++s) solver.step(s, steps);
  return {backend.forces - before.forces, backend.applies - before.applies, backend.solves - before.solves,
          backend.lastCoeffs};
}

TEST(DampingWork, DampingFreeStepsNeverApplyADampingProduct) {
  for (int iterations : {1, 3}) {
    SCOPED_TRACE(iterations);
    const Counts c = runChain(0.0, 0.0, iterations, 6);
    EXPECT_EQ(c.applies, 0);
    // Each step: a force evaluation before every solve plus one at the final velocities (Newton
    // may stop before `iterations` solves once the residual is at rounding level).
    EXPECT_GE(c.solves, 5);
    EXPECT_LE(c.solves, 5 * iterations);
    EXPECT_EQ(c.forces, c.solves + 5);
    EXPECT_EQ(c.coeffs.mass, 1.0);
  }
}

TEST(DampingWork, RayleighDampingCostsAProductPerForceEvaluationOnlyWithStiffnessDamping) {
  for (auto [alpha, beta] : {std::pair{0.3, 0.0}, std::pair{0.0, 0.02}, std::pair{0.3, 0.02}}) {
    SCOPED_TRACE(alpha);
    SCOPED_TRACE(beta);
    const Counts c = runChain(alpha, beta, 2, 6);
    if (beta == 0.0)
      EXPECT_EQ(c.applies, 0);  // alpha M v, formed by the solver
    else
      EXPECT_EQ(c.applies, c.forces);  // C v beside every f_int, nothing else
    EXPECT_GE(c.solves, 5);  // the system matrix carries C through its coefficients
    // Newmark (gamma 1/2, beta 1/4) on velocities: A = M + h gamma C + h^2 beta K_t.
    EXPECT_DOUBLE_EQ(c.coeffs.damping, 0.01 * 0.5);
  }
}

}  // namespace
}  // namespace corofem
