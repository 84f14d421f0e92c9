// BodyView, and the shared part of the per-body drivers: free-dof norms, scales, energies.
#include "solve/statics.hpp"

#include "solve/body_scale.hpp"
#include "util/error.hpp"
#include "util/finite.hpp"

#include <cmath>

namespace corofem::detail {

LinearSolveStats BodyView::solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) {
  std::vector<PcgSolve> one(1);
  one[0].coeffs = c;
  one[0].b = &b;
  one[0].x = &x;
  slot_->solve({body_}, one);
  if (!one[0].failure.empty()) throw Error(ErrorCode::SolveFailed, one[0].failure);
  return one[0].stats;
}

double BodyView::elasticEnergy() {
  std::vector<double> e;
  slot_->elasticEnergy({body_}, e);
  return e.at(0);
}

BodySolver::BodySolver(const Problem& problem, BodyView body, const Log& log)
    : problem_(problem), body_(body), log_(log) {
  const Eigen::Index n = problem.restPositions.size();
  BodyScale scale = bodyScale(problem);
  freeMask_ = std::move(scale.freeMask);
  diagonal_ = scale.diagonal;
  forceFloor_ = scale.forceFloor;

  x_ = problem.restPositions;
  v_ = Eigen::VectorXd::Zero(n);
  xPrev_ = x_;
}

void BodySolver::setInitialState(const Eigen::VectorXd& x, const Eigen::VectorXd& v) {
  if (x.size() != x_.size() || v.size() != x_.size())
    fail(ErrorCode::BadInput, "body '", problem_.name, "': an initial state needs ", x_.size(),
         " positions and velocities (3 per node), got ", x.size(), " and ", v.size());
  if (!x.allFinite() || !v.allFinite())
    fail(ErrorCode::BadInput, "body '", problem_.name, "': the initial positions or velocities are not finite");
  x_ = x;
  v_ = (v.array() * freeMask_).matrix();
  xPrev_ = x_;
  deviceAtCommitted_ = false;
}

double BodySolver::kineticEnergy() const {
  if (problem_.lumpedMass.size() != v_.size()) return 0.0;
  return 0.5 * (problem_.lumpedMass.array() * v_.array().square()).sum();
}

double BodySolver::elasticEnergy() {
  syncDevicePositions();
  return body_.elasticEnergy();
}

void BodySolver::syncDevicePositions() {
  if (!deviceAtCommitted_) setDevicePositions(x_, true);
}

double BodySolver::freeNorm(const Eigen::VectorXd& v) const { return (v.array() * freeMask_).matrix().norm(); }

bool BodySolver::allFinite(const Eigen::VectorXd& v) { return allFiniteEntries(v); }

void BodySolver::setDevicePositions(const Eigen::VectorXd& x, bool committed) {
  body_.setPositions(x);
  deviceAtCommitted_ = committed;
}

}  // namespace corofem::detail
