// A tiny Device of one body for unit tests of the solve/ drivers: a chain of springs along x with
// lumped masses, each Cartesian component an independent 1-D chain. Spring s joins nodes s and s+1
// and carries g(e) = k e + k3 e^3 for the relative displacement e = u_{s+1} - u_s of each component
// (k3 = 0: linear). Dense matrices, exact LDLT solves (the device's direct solve; the drivers are
// given the Cholesky solver for it): closed-form answers and no solver noise. The tests keep the
// object and hand the drivers a view of it (common/body_drivers.hpp).
#pragma once

#include "device/device.hpp"
#include "model/problem.hpp"
#include "util/error.hpp"

#include <Eigen/Dense>

#include <cmath>
#include <limits>
#include <vector>

namespace corofem::test {

class SpringChainBackend final : public detail::Device {
 public:
  SpringChainBackend(const detail::Problem& problem, double k, double k3 = 0.0)
      : problem_(problem), k_(k), k3_(k3), x_(problem.restPositions) {}

  std::string name() const override { return "mock"; }
  std::string deviceName() const override { return "spring chain"; }
  std::size_t bodyCount() const override { return 1; }
  const detail::Problem& problem(std::size_t) const override { return problem_; }

  void setPositions(const detail::BodySet&, const detail::ConstVectors& x) override { setPositions(*x.at(0)); }
  void internalForces(const detail::BodySet&, const detail::Vectors& f) override { internalForces(*f.at(0)); }
  void apply(const detail::BodySet&, const std::vector<detail::SystemCoeffs>& c, const detail::ConstVectors& p,
             const detail::Vectors& y) override {
    apply(c.at(0), *p.at(0), *y.at(0));
  }
  void elasticEnergy(const detail::BodySet&, std::vector<double>& e) override { e.assign(1, elasticEnergy()); }
  std::vector<detail::PcgStart> pcgBegin(const detail::BodySet&, const std::vector<detail::SystemCoeffs>&,
                                         const detail::ConstVectors&, const detail::ConstVectors&, double,
                                         int) override {
    detail::fail(ErrorCode::Internal, "the spring chain solves directly (give the drivers the Cholesky solver)");
  }
  void pcgIterate(int, const std::vector<char>&) override {}
  detail::PcgTicket pcgRead() override { return 0; }
  void pcgTake(detail::PcgTicket, std::vector<detail::PcgScalars>&) override {}
  void pcgResidual(const std::vector<char>&) override {}
  void pcgEnd(const std::vector<int>&, const detail::Vectors&, std::vector<detail::PcgScalars>&) override {}
  bool hasDirectSolve() const override { return true; }
  detail::LinearSolveStats solveDirect(std::size_t, const detail::SystemCoeffs& c, const Eigen::VectorXd& b,
                                       Eigen::VectorXd& x) override {
    return solve(c, b, x);
  }

  void setPositions(const Eigen::VectorXd& x) { x_ = x; }

  void internalForces(Eigen::VectorXd& f) {
    ++forceCalls;
    const Eigen::VectorXd u = x_ - problem_.restPositions;
    f = Eigen::VectorXd::Zero(u.size());
    for (int s = 0; s + 1 < nodes(); ++s)
      for (int c = 0; c < 3; ++c) {
        const double e = u[3 * (s + 1) + c] - u[3 * s + c];
        const double g = k_ * e + k3_ * e * e * e;
        f[3 * (s + 1) + c] += g;
        f[3 * s + c] -= g;
      }
    // Circulatory (follower-like) force, absent from the tangent and the energy: it pumps energy
    // into the x-y motion of every node, as an energy-gaining integration scheme would.
    for (int i = 1; i < nodes(); ++i) {
      f[3 * i] += circulation * u[3 * i + 1];
      f[3 * i + 1] -= circulation * u[3 * i];
    }
    if (nanAfterForceCalls >= 0 && forceCalls > nanAfterForceCalls) f[f.size() - 1] = std::nan("");
  }

  void apply(const detail::SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) { y = matrix(c) * p; }

  detail::LinearSolveStats solve(const detail::SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) {
    ++solveCalls;
    const Eigen::MatrixXd a = matrix(c);
    std::vector<int> free;
    for (int d = 0; d < static_cast<int>(b.size()); ++d)
      if (!problem_.constrained[static_cast<std::size_t>(d)]) free.push_back(d);
    const int nf = static_cast<int>(free.size());
    Eigen::MatrixXd af(nf, nf);
    Eigen::VectorXd bf(nf);
    for (int i = 0; i < nf; ++i) {
      bf[i] = b[free[i]];
      for (int j = 0; j < nf; ++j) af(i, j) = a(free[i], free[j]);
    }
    const Eigen::VectorXd xf = af.ldlt().solve(bf);
    x = Eigen::VectorXd::Zero(b.size());
    for (int i = 0; i < nf; ++i) x[free[i]] = xf[i];
    if (!x.allFinite()) detail::fail(ErrorCode::SolveFailed, "mock solve: not finite");
    detail::LinearSolveStats stats;
    stats.iterations = failLinearSolves ? 999 : 1;
    stats.converged = !failLinearSolves;
    const double bn = bf.norm();
    stats.relativeResidual = bn > 0 ? (af * xf - bf).norm() / bn : 0.0;
    return stats;
  }

  double elasticEnergy() {
    const Eigen::VectorXd u = x_ - problem_.restPositions;
    double energy = 0;
    for (int s = 0; s + 1 < nodes(); ++s)
      for (int c = 0; c < 3; ++c) {
        const double e = u[3 * (s + 1) + c] - u[3 * s + c];
        energy += 0.5 * k_ * e * e + 0.25 * k3_ * e * e * e * e;
      }
    return energy;
  }

  /// Tangent stiffness at the current positions (dense, all dofs).
  Eigen::MatrixXd tangent() const {
    const int n = 3 * nodes();
    Eigen::MatrixXd kt = Eigen::MatrixXd::Zero(n, n);
    const Eigen::VectorXd u = x_ - problem_.restPositions;
    for (int s = 0; s + 1 < nodes(); ++s)
      for (int c = 0; c < 3; ++c) {
        const int i = 3 * s + c, j = 3 * (s + 1) + c;
        const double e = u[j] - u[i];
        const double ks = k_ + 3.0 * k3_ * e * e;
        kt(i, i) += ks;
        kt(j, j) += ks;
        kt(i, j) -= ks;
        kt(j, i) -= ks;
      }
    return kt;
  }

  double circulation = 0.0;     ///< N/m, see internalForces
  int forceCalls = 0;
  int solveCalls = 0;
  int nanAfterForceCalls = -1;  ///< >= 0: forces get a NaN after this many calls
  bool failLinearSolves = false;///< report every linear solve as not converged

 private:
  int nodes() const { return static_cast<int>(problem_.restPositions.size() / 3); }
  /// A = mass M + damping (alpha M + beta K_t) + stiffness K_t.
  Eigen::MatrixXd matrix(const detail::SystemCoeffs& c) const {
    const Eigen::MatrixXd kt = tangent();
    const Eigen::VectorXd m = problem_.lumpedMass;
    Eigen::MatrixXd a = (c.stiffness + c.damping * problem_.rayleighStiffness) * kt;
    a.diagonal() += (c.mass + c.damping * problem_.rayleighMass) * m;
    return a;
  }

  const detail::Problem& problem_;
  double k_, k3_;
  Eigen::VectorXd x_;
};

/// A chain of `nodes` nodes spaced 1 m along x, node 0 fixed, mass `mass` per free node (and on
/// node 0), no loads. Lame parameters chosen so that forceFloor (1e-8 (lambda + 2 mu) diag^2) is
/// far below the test forces.
inline detail::Problem springChainProblem(int nodes, double mass) {
  detail::Problem p;
  p.name = "chain";
  const int n3 = 3 * nodes;
  p.restPositions = Eigen::VectorXd::Zero(n3);
  for (int i = 0; i < nodes; ++i) p.restPositions[3 * i] = i;
  p.lumpedMass = Eigen::VectorXd::Constant(n3, mass);
  p.constrained.assign(static_cast<std::size_t>(n3), 0);
  p.constrained[0] = p.constrained[1] = p.constrained[2] = 1;
  p.initialVelocity = Eigen::VectorXd::Zero(n3);
  p.lame.lambda = 0.0;
  p.lame.mu = 0.5;
  p.density = 1.0;
  p.formulation = Formulation::Linear;
  return p;
}

}  // namespace corofem::test
