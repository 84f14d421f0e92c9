// Newton-Raphson statics (paper Eqs. 12-13), one load increment per call. The criteria are
// documented on StaticSolver in body_solver.hpp.
#include "solve/body_solver.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace corofem::detail {

namespace {

std::string sci(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1e", value);
  return buffer;
}

}  // namespace

StaticSolver::StaticSolver(const Problem& problem, Backend& backend, const StaticDesc& desc)
    : BodySolver(problem, backend), desc_(desc) {
  fextPrev_ = Eigen::VectorXd::Zero(problem.restPositions.size());
  fextPrevSaved_ = fextPrev_;
}

BodyStepStats StaticSolver::step(int increment, int incrementCount) {
  const double lambda = static_cast<double>(increment) / static_cast<double>(std::max(1, incrementCount));
  const int maxIterations = std::max(1, desc_.maxNewtonIterations);
  // Below this relative residual the increment is accepted without the displacement test
  // (see the class comment: a linear problem solved exactly converges in one iteration).
  const double linearAcceptance = std::min(1e-8, 1e-2 * desc_.residualTolerance);
  const double displacementFloor =
      1e-12 * diagonal_ * std::sqrt(std::max(1.0, freeMask_.sum()));

  auto failHere = [&](const std::string& what, const std::string& fix) {
    setBackendPositions(x_, true);  // the backend goes back to the last converged state too
    fail(ErrorCode::SolveFailed, "body '", problem_.name, "': static increment ", increment, "/",
         incrementCount, " ", what, "; ", fix);
  };
  const std::string incrementFix =
      "try more increments (analysis.increments) or a looser analysis.residual_tolerance";

  Eigen::VectorXd x = x_;
  problem_.applyPrescribed(x, lambda, /*dynamic=*/false);
  const Eigen::VectorXd fext = problem_.externalForce(lambda, /*dynamic=*/false);
  const double fextNorm = freeNorm(fext);

  Eigen::VectorXd fint(x.size()), r(x.size()), dx(x.size());
  BodyStepStats stats;
  double dxNorm = INFINITY;
  double relative = INFINITY;
  for (int iteration = 0;; ++iteration) {
    try {
      setBackendPositions(x, false);
      backend_.internalForces(fint);
    } catch (const Error& e) {
      failHere(std::string("failed: ") + e.what(), incrementFix);
    }
    r = fint - fext;
    const double scale = std::max({fextNorm, freeNorm(fint), forceFloor_});
    relative = freeNorm(r) / scale;
    stats.residual = relative;
    if (!std::isfinite(relative) || !allFinite(x))
      failHere("produced non-finite forces or positions after " + std::to_string(iteration) +
                   " Newton iterations",
               "the load is probably far beyond what the mesh can carry in one step: " + incrementFix +
                   ", or check the material (E, nu) and the loads");

    const double displacementScale = std::max(freeNorm(x - problem_.restPositions), displacementFloor);
    const bool residualOk = relative <= desc_.residualTolerance;
    const bool displacementOk = iteration > 0 && dxNorm <= desc_.displacementTolerance * displacementScale;
    if (residualOk && (displacementOk || relative <= linearAcceptance)) break;

    if (iteration == maxIterations) {
      stats.converged = false;
      failHere("did not converge in " + std::to_string(maxIterations) + " Newton iterations (relative residual " +
                   sci(relative) + ", last correction " + sci(dxNorm / displacementScale) +
                   " of the displacement)",
               incrementFix + " or analysis.max_newton_iterations");
    }

    // Eq. 13: K_t dx = f_ext - f_int on the free dofs (constrained dx = 0).
    dx.setZero();
    LinearSolveStats ls;
    try {
      ls = backend_.solve(SystemCoeffs{0.0, 0.0, 1.0}, -r, dx);
    } catch (const Error& e) {
      failHere(std::string("failed in the linear solve: ") + e.what(), incrementFix);
    }
    stats.newtonIterations += 1;
    stats.linearIterations += ls.iterations;
    stats.linearResidual = std::max(stats.linearResidual, ls.relativeResidual);
    if (!allFinite(dx))
      failHere("produced a non-finite Newton correction", incrementFix + ", or check the constraints (is the body held?)");
    x += dx;
    dxNorm = freeNorm(dx);
  }

  // Converged: commit. The backend holds x (the last setPositions).
  xPrev_ = x_;
  workPrev_ = work_;
  fextPrevSaved_ = fextPrev_;
  // External work by the trapezoidal rule over the increment (exact for loads linear in lambda
  // along a straight path; an estimate otherwise).
  work_ += 0.5 * (fextPrev_ + fext).dot(x - x_);
  fextPrev_ = fext;
  x_ = x;
  backendAtCommitted_ = true;
  stats.converged = true;
  return stats;
}

void StaticSolver::rollback() {
  x_ = xPrev_;
  work_ = workPrev_;
  fextPrev_ = fextPrevSaved_;
  backendAtCommitted_ = false;
}

}  // namespace corofem::detail
