// Newton-Raphson statics (paper Eqs. 12-13), one load increment per call. The criteria, the
// quasi-Newton correction and the line search are documented on StaticSolver in body_solver.hpp.
#include "solve/body_solver.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <string>

namespace corofem::detail {

namespace {

std::string sci(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1e", value);
  return buffer;
}

/// Secant pairs kept by the quasi-Newton correction (L-BFGS memory).
constexpr int kHistory = 8;
/// Armijo constant of the line search (sufficient decrease of the potential energy).
constexpr double kArmijo = 1e-4;
/// Step-length reductions tried before the last trial step is taken as it is.
constexpr int kMaxBacktracks = 6;

struct SecantPair {
  Eigen::VectorXd s, y;  ///< step and change of residual, free dofs only
  double rho = 0;        ///< 1 / (y . s)
};

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
  const double displacementFloor = 1e-12 * diagonal_ * std::sqrt(std::max(1.0, freeMask_.sum()));
  const bool debug = std::getenv("COROFEM_DEBUG_NEWTON") != nullptr;

  auto failHere = [&](const std::string& what, const std::string& fix) {
    setBackendPositions(x_, true);  // the backend goes back to the last converged state too
    fail(ErrorCode::SolveFailed, "body '", problem_.name, "': static increment ", increment, "/",
         incrementCount, " ", what, "; ", fix);
  };
  const std::string incrementFix =
      "try more increments (analysis.increments) or a looser analysis.residual_tolerance";

  // Predictor: the free dofs continue along the last increment's displacement (linear
  // extrapolation in the load factor), which puts a linear problem on its answer at once and a
  // nonlinear one much closer than the last converged state. Prescribed values are then written.
  Eigen::VectorXd x = x_;
  if (havePrevious_ && lambda > lambda_ && lambda_ > lambdaPrev_) {
    const double ratio = (lambda - lambda_) / (lambda_ - lambdaPrev_);
    x += ratio * ((x_ - xPrev_).array() * freeMask_).matrix();
  }
  problem_.applyPrescribed(x, lambda, /*dynamic=*/false);
  const Eigen::VectorXd fext = problem_.externalForce(lambda, /*dynamic=*/false);
  const double fextNorm = freeNorm(fext);

  const Eigen::Index n = x.size();
  Eigen::VectorXd fint(n), r(n), trialForce(n), trialResidual(n), q(n), z(n), d(n), trial(n);
  // Residual of Eq. 12 on the free dofs at y (constrained rows are reactions, not unknowns).
  auto evaluate = [&](const Eigen::VectorXd& y, Eigen::VectorXd& force, Eigen::VectorXd& residual) {
    try {
      setBackendPositions(y, false);
      backend_.internalForces(force);
    } catch (const Error& e) {
      failHere(std::string("failed: ") + e.what(), incrementFix);
    }
    residual = ((force - fext).array() * freeMask_).matrix();
  };

  BodyStepStats stats;
  std::deque<SecantPair> history;
  double dxNorm = INFINITY;
  evaluate(x, fint, r);
  for (int iteration = 0;; ++iteration) {
    const double scale = std::max({fextNorm, freeNorm(fint), forceFloor_});
    const double relative = r.norm() / scale;
    stats.residual = relative;
    if (debug) std::fprintf(stderr, "static %d/%d iteration %d: relative residual %.3e, |dx| %.3e\n", increment,
                            incrementCount, iteration, relative, dxNorm);
    if (!std::isfinite(relative) || !allFinite(x))
      failHere("produced non-finite forces or positions after " + std::to_string(iteration) + " Newton iterations",
               "the load is probably far beyond what the mesh can carry in one step: " + incrementFix +
                   ", or check the material (E, nu) and the loads");

    const double displacementScale = std::max(freeNorm(x - problem_.restPositions), displacementFloor);
    const bool residualOk = relative <= desc_.residualTolerance;
    const bool displacementOk = iteration > 0 && dxNorm <= desc_.displacementTolerance * displacementScale;
    if (residualOk && (displacementOk || relative <= linearAcceptance)) break;

    if (iteration == maxIterations) {
      stats.converged = false;
      failHere("did not converge in " + std::to_string(maxIterations) + " Newton iterations (relative residual " +
                   sci(relative) + ", last correction " + sci(dxNorm / displacementScale) + " of the displacement)",
               incrementFix + " or analysis.max_newton_iterations");
    }

    // Direction: Eq. 13's K_t dx = -r, with the L-BFGS two-loop correction built from the last
    // secant pairs (K_t^-1 as the initial inverse Hessian). Without history it is exactly Eq. 13.
    q = r;
    std::vector<double> alphas(history.size());
    for (std::size_t i = history.size(); i-- > 0;) {
      alphas[i] = history[i].rho * history[i].s.dot(q);
      q -= alphas[i] * history[i].y;
    }
    z.setZero();
    LinearSolveStats ls;
    try {
      ls = backend_.solve(SystemCoeffs{0.0, 0.0, 1.0}, q, z);
    } catch (const Error& e) {
      failHere(std::string("failed in the linear solve: ") + e.what(), incrementFix);
    }
    for (std::size_t i = 0; i < history.size(); ++i) {
      const double beta = history[i].rho * history[i].y.dot(z);
      z += (alphas[i] - beta) * history[i].s;
    }
    d = -(z.array() * freeMask_).matrix();
    stats.newtonIterations += 1;
    stats.linearIterations += ls.iterations;
    stats.linearResidual = std::max(stats.linearResidual, ls.relativeResidual);
    if (!allFinite(d))
      failHere("produced a non-finite Newton correction",
               incrementFix + ", or check the constraints (is the body held?)");

    // Line search on the potential energy Pi = U(x) - f_ext . x, whose gradient is r (the
    // co-rotational force with the polar rotation, and the hyperelastic ones, are energy
    // gradients). Using only g(t) = r(x + t d) . d: for a quadratic,
    //   Pi(t) - Pi(0) = t (g(0) + g(t)) / 2 <= kArmijo t g(0)  <=>  g(t) <= (1 - 2 kArmijo) |g(0)|,
    // which needs no energy differences (those cancel to rounding near convergence). A step that
    // fails it is shortened to the secant root of g, the minimiser of the quadratic model. When d
    // is not a descent direction (g(0) >= 0: an indefinite hyperelastic tangent) the full step is
    // taken, as plain Newton would.
    const double g0 = r.dot(d);
    double t = 1.0;
    for (int backtrack = 0;; ++backtrack) {
      trial = x + t * d;
      evaluate(trial, trialForce, trialResidual);
      const double gt = trialResidual.dot(d);
      const bool finite = std::isfinite(gt) && allFinite(trialResidual);
      if (backtrack == kMaxBacktracks) break;
      if (finite && (g0 >= 0.0 || gt <= (1.0 - 2.0 * kArmijo) * std::abs(g0))) break;
      const double secant = finite && gt > g0 ? t * g0 / (g0 - gt) : 0.25 * t;
      t = std::clamp(secant, 0.1 * t, 0.7 * t);
    }
    SecantPair pair;
    pair.s = t * d;
    pair.y = trialResidual - r;
    const double sy = pair.s.dot(pair.y);
    // Keep the pair only where the energy is locally convex along s (y . s > 0), as L-BFGS must.
    if (sy > 1e-12 * pair.s.norm() * pair.y.norm() && std::isfinite(sy)) {
      pair.rho = 1.0 / sy;
      history.push_back(std::move(pair));
      if (static_cast<int>(history.size()) > kHistory) history.pop_front();
    }
    dxNorm = t * d.norm();
    x = trial;
    fint = trialForce;
    r = trialResidual;
  }

  // Converged: commit. The backend holds x (the last evaluation).
  xPrev_ = x_;
  workPrev_ = work_;
  fextPrevSaved_ = fextPrev_;
  lambdaPrev_ = lambda_;
  lambda_ = lambda;
  havePrevious_ = true;
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
  lambda_ = lambdaPrev_;
  havePrevious_ = false;  // one level of history only: no predictor after a rollback
  backendAtCommitted_ = false;
}

}  // namespace corofem::detail
