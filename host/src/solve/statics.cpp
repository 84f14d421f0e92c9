// Newton-Raphson statics (paper Eqs. 12-13), one load increment per call. The criteria, the
// quasi-Newton correction, the line search and the automatic cut-back are documented on
// StaticSolver in statics.hpp.
#include "solve/statics.hpp"
#include "util/error.hpp"
#include "util/format.hpp"

#include <Eigen/LU>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <string>
#include <vector>

namespace corofem::detail {

namespace {

/// Secant pairs kept by the quasi-Newton correction (L-BFGS memory).
constexpr int kHistory = 8;
/// Armijo constant of the line search (sufficient decrease of the potential energy).
constexpr double kArmijo = 1e-4;
/// Step-length reductions tried before the last trial step is taken as it is.
constexpr int kMaxBacktracks = 6;
/// Halvings of an increment tried before the step fails: down to 1/16 of it.
constexpr int kMaxCuts = 4;
/// Relative residuals above which a stalled Newton is not at the rounding floor of the force
/// evaluation, 20 to 100 times the largest floors measured: float ~1e-3 (a 0.4 m cantilever,
/// E = 1e6 Pa, tests/extremes/test_incompressible.cpp), double 4e-9 (docs/examples/
/// static_cantilever.json) and 5e-7 (the same moved 100 m from the origin: the floor grows with the
/// coordinates' magnitude).
constexpr double kRoundingFloorFloat = 1e-1;
constexpr double kRoundingFloorDouble = 1e-5;

struct SecantPair {
  Eigen::VectorXd s, y;  ///< step and change of residual, free dofs only
  double rho = 0;        ///< 1 / (y . s)
};

/// A load factor in a message ("0.9688").
std::string formatFactor(double lambda) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.4g", lambda);
  return buffer;
}

/// Thrown inside newton() to end an attempt that met a non-finite value (a cut-back may cure it).
struct AttemptFailed {
  std::string why;
};

}  // namespace

StaticSolver::StaticSolver(const Problem& problem, BodyView body, const StaticDesc& desc, const Log& log)
    : BodySolver(problem, body, log), desc_(desc) {
  track_.fext = Eigen::VectorXd::Zero(problem.restPositions.size());
  trackSaved_ = track_;
}

StaticSolver::NewtonOutcome StaticSolver::newton(double lambda, const Eigen::VectorXd& fext, Eigen::VectorXd& x,
                                                 BodyStepStats& stats) {
  const int maxIterations = std::max(1, desc_.maxNewtonIterations);
  // Below this relative residual the increment is accepted without the displacement test
  // (see the class comment: a linear problem solved exactly converges in one iteration).
  const double linearAcceptance = std::min(1e-8, 1e-2 * desc_.residualTolerance);
  const double displacementFloor = 1e-12 * diagonal_ * std::sqrt(std::max(1.0, freeMask_.sum()));
  const double fextNorm = freeNorm(fext);

  const Eigen::Index n = x.size();
  Eigen::VectorXd fint(n), r(n), trialForce(n), trialResidual(n), q(n), z(n), d(n), trial(n);
  // Residual of Eq. 12 on the free dofs at y (constrained rows are reactions, not unknowns).
  // Non-finite results and SolveFailed from the backend end the attempt; other errors propagate.
  auto evaluate = [&](const Eigen::VectorXd& y, Eigen::VectorXd& force, Eigen::VectorXd& residual) {
    try {
      setDevicePositions(y, false);
      body_.internalForces(force);
    } catch (const Error& e) {
      if (e.code() != ErrorCode::SolveFailed) throw;
      throw AttemptFailed{std::string("failed: ") + e.what()};
    }
    residual = ((force - fext).array() * freeMask_).matrix();
  };

  NewtonOutcome out;
  try {
    std::deque<SecantPair> history;
    double dxNorm = INFINITY;
    evaluate(x, fint, r);
    for (int iteration = 0;; ++iteration) {
      const double scale = std::max({fextNorm, freeNorm(fint), forceFloor_});
      const double relative = r.norm() / scale;
      const double displacementScale = std::max(freeNorm(x - problem_.restPositions), displacementFloor);
      out.relative = relative;
      out.correction = dxNorm / displacementScale;
      stats.residual = relative;
      log_(LogLevel::Debug, "body '", problem_.name, "': static load factor ", lambda, ", Newton iteration ", iteration,
           ": relative residual ", sci(relative), ", |dx| ", sci(dxNorm));
      if (!std::isfinite(relative) || !allFinite(x))
        throw AttemptFailed{"produced non-finite forces or positions after " + std::to_string(iteration) +
                            " Newton iterations"};

      const bool residualOk = relative <= desc_.residualTolerance;
      const bool displacementOk = iteration > 0 && dxNorm <= desc_.displacementTolerance * displacementScale;
      if (residualOk && (displacementOk || relative <= linearAcceptance)) {
        if (isHyperelastic(problem_.formulation)) {
          const std::string inverted = invertedElements(x);
          if (!inverted.empty()) {
            out.inverted = true;
            throw AttemptFailed{"reached an equilibrium at load factor " + formatFactor(lambda) + " with " + inverted};
          }
        }
        out.converged = true;
        return out;
      }
      if (iteration == maxIterations) {
        out.failure = "did not converge in " + std::to_string(maxIterations) +
                      " Newton iterations (relative residual " + sci(relative) + ", last correction " +
                      sci(out.correction) + " of the displacement)";
        return out;
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
        ls = body_.solve(SystemCoeffs{0.0, 0.0, 1.0}, q, z);
      } catch (const Error& e) {
        if (e.code() != ErrorCode::SolveFailed) throw;
        throw AttemptFailed{std::string("failed in the linear solve: ") + e.what()};
      }
      for (std::size_t i = 0; i < history.size(); ++i) {
        const double beta = history[i].rho * history[i].y.dot(z);
        z += (alphas[i] - beta) * history[i].s;
      }
      d = -(z.array() * freeMask_).matrix();
      stats.newtonIterations += 1;
      stats.linearIterations += ls.iterations;
      stats.linearResidual = std::max(stats.linearResidual, ls.relativeResidual);
      if (!allFinite(d)) throw AttemptFailed{"produced a non-finite Newton correction"};

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
        bool finite = true;
        try {
          evaluate(trial, trialForce, trialResidual);
        } catch (const AttemptFailed&) {
          if (backtrack == kMaxBacktracks) throw;
          finite = false;
        }
        const double gt = finite ? trialResidual.dot(d) : NAN;
        finite = finite && std::isfinite(gt) && allFinite(trialResidual);
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
      log_(LogLevel::Debug, "body '", problem_.name, "': line search step length ", t, ", g0 ", sci(g0), ", L-BFGS pairs ",
           history.size());
      x = trial;
      fint = trialForce;
      r = trialResidual;
    }
  } catch (const AttemptFailed& e) {
    out.converged = false;
    out.failure = e.why;
    return out;
  }
}

std::string StaticSolver::invertedElements(const Eigen::VectorXd& x) const {
  const TetMesh& mesh = problem_.mesh;
  std::size_t count = 0, worst = 0;
  double lowest = INFINITY;
  for (std::size_t e = 0; e < problem_.elements.size(); ++e) {
    std::array<Vec3d, 4> nodes;
    for (int k = 0; k < 4; ++k) nodes[k] = x.segment<3>(3 * static_cast<Eigen::Index>(mesh.tets[4 * e + k]));
    const double J = deformationGradient(problem_.elements[e], nodes).determinant();
    if (J > 0.0) continue;  // NaN counts as inverted
    ++count;
    if (!(J >= lowest)) {
      lowest = J;
      worst = e;
    }
  }
  if (count == 0) return "";
  char lowestText[32];
  std::snprintf(lowestText, sizeof lowestText, "%.3g", lowest);
  return std::to_string(count) + " of " + std::to_string(problem_.elements.size()) +
         " elements inverted (det F <= 0; the lowest, " + lowestText + ", in element " + std::to_string(worst) + ")";
}

BodyStepStats StaticSolver::step(int increment, int incrementCount) {
  const double target = static_cast<double>(increment) / static_cast<double>(std::max(1, incrementCount));
  BodyStepStats stats;

  // Work on copies; commit only when the whole increment converged.
  Eigen::VectorXd xDone = x_;
  Track track = track_;
  double work = work_;
  double size = target - track.lambda;  // current sub-increment
  int cuts = 0, successes = 0;
  NewtonOutcome last;
  std::string inversion;  ///< the first attempt's that reached an inverted equilibrium, if any
  while (track.lambda < target) {
    const bool reachesTarget = track.lambda + size >= target * (1.0 - 1e-12);
    const double lambda = reachesTarget ? target : track.lambda + size;

    // Predictor: the free dofs continue along the last converged (sub-)increment's displacement
    // (linear extrapolation in the load factor), which puts a linear problem on its answer at once
    // and a nonlinear one closer than the last converged state. Prescribed values are then written.
    Eigen::VectorXd x = xDone;
    if (track.haveBack && track.lambda > track.lambdaBack) {
      const double ratio = (lambda - track.lambda) / (track.lambda - track.lambdaBack);
      x += ratio * ((xDone - track.xBack).array() * freeMask_).matrix();
    }
    problem_.applyPrescribed(x, lambda, /*dynamic=*/false);
    const Eigen::VectorXd fext = problem_.externalForce(lambda, /*dynamic=*/false);

    last = newton(lambda, fext, x, stats);
    if (last.converged) {
      // External work by the trapezoidal rule over the (sub-)increment (exact for a linear
      // response to a proportional load; an estimate otherwise).
      work += 0.5 * (track.fext + fext).dot(x - xDone);
      track.xBack = xDone;
      track.lambdaBack = track.lambda;
      track.haveBack = true;
      track.lambda = lambda;
      track.fext = fext;
      xDone = x;
      if (cuts > 0 && ++successes >= 2) {  // grow back after two successes in a row
        size *= 2.0;
        successes = 0;
      }
      continue;
    }
    if (last.inverted && inversion.empty()) inversion = last.failure;
    if (cuts == kMaxCuts) {
      stats.converged = false;
      setDevicePositions(x_, true);  // the device goes back to the last converged state too
      const std::string where = "body '" + problem_.name + "': static increment " + std::to_string(increment) + "/" +
                                std::to_string(incrementCount) + " ";
      const std::string cut = "even cut into sub-increments down to 1/" + std::to_string(1 << kMaxCuts) + " of it";
      if (last.inverted)
        fail(ErrorCode::SolveFailed, where, last.failure, ", ", cut, ": an inside-out state, not a physical answer. ",
             problem_.formulation == Formulation::StVenantKirchhoff ? "St. Venant-Kirchhoff" : toString(problem_.formulation),
             "'s energy stays finite for inverted elements, so past a limit point "
             "of the load path Newton can converge on such a branch; use the formulation \"neo_hookean\" (which "
             "refuses inverted elements) or \"corotational\", or keep the load below this increment's");
      // A stall at the rounding floor of the force evaluation: the corrections have shrunk to
      // nothing while the residual stays well above the tolerance, yet below what rounding can
      // explain in the precision the forces were evaluated in (kRoundingFloorFloat / Double; the
      // reference backend's is always double, as in schedule/plan.cpp, the others' the solver's).
      // More iterations or increments cannot help. A larger stalled residual is no floor (a limit
      // point of the load path, or the co-rotational tangent far beyond its range, stalls too).
      const bool inDouble = body_.slot().current().backend == "reference" ||
                            body_.slot().solver().precision == Precision::Double;
      const bool stalled = std::isfinite(last.relative) && last.relative > 10.0 * desc_.residualTolerance &&
                           last.correction < 1e-3 &&
                           last.relative < (inDouble ? kRoundingFloorDouble : kRoundingFloorFloat);
      const std::string alsoInverted =
          inversion.empty() ? "" : " (a larger sub-increment " + inversion + ")";
      if (stalled) {
        const std::string precision =
            inDouble ? "double precision"
                     : "float precision (solver.precision \"" + std::string(toString(body_.slot().solver().precision)) + "\")";
        char above[32];
        std::snprintf(above, sizeof above, "%.0e", std::pow(10.0, std::ceil(std::log10(2.0 * last.relative))));
        fail(ErrorCode::SolveFailed, where, last.failure, alsoInverted, ", ", cut,
             ". The corrections have stalled while the residual has not: the residual is at the rounding floor of "
             "the force evaluation in ", precision, " on '", body_.slot().device().deviceName(),
             "' (it grows with the coordinates' magnitude), below which analysis.residual_tolerance = ",
             sci(desc_.residualTolerance), " cannot be reached; ",
             inDouble ? "use a residual_tolerance above the stalled residual (e.g. "
                      : "use solver.precision \"double\" or a residual_tolerance above the stalled residual (e.g. ",
             above, ")");
      }
      fail(ErrorCode::SolveFailed, where, last.failure, alsoInverted, ", ", cut,
           "; try more increments (analysis.increments), a looser analysis.residual_tolerance or more "
           "analysis.max_newton_iterations; check the constraints (is the body held?) and the material");
    }
    ++cuts;
    successes = 0;
    size *= 0.5;
    // A cut-back restarts from the last converged state with the predictor of that state.
  }

  // Converged: commit. The device holds the last evaluated positions, which are xDone.
  xPrev_ = x_;
  workPrev_ = work_;
  trackSaved_ = track_;
  x_ = xDone;
  work_ = work;
  track_ = track;
  deviceAtCommitted_ = true;
  stats.converged = true;
  return stats;
}

void StaticSolver::rollback() {
  x_ = xPrev_;
  work_ = workPrev_;
  track_ = trackSaved_;
  deviceAtCommitted_ = false;
}

}  // namespace corofem::detail
