// Implicit Newmark and backward Euler (paper Eq. 14) solved for the velocities by Newton. The
// scheme, the constraint handling, the warm start and the blow-up rule are documented on
// DynamicSolver in body_solver.hpp.
#include "solve/body_solver.hpp"
#include "util/error.hpp"
#include "util/format.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <utility>

namespace corofem::detail {

namespace {

/// Relative residual above which a step whose linear solves did not converge, and whose residual
/// grew during the step, counts as blown up. Below it the step is merely inexact (the user traded
/// accuracy for speed with a low solver.max_iterations).
constexpr double kBlowUpResidual = 1e-3;

/// Mechanical energy (kinetic + elastic), in units of the energy the body was ever given, above
/// which a step ran away (see DynamicSolver).
constexpr double kRunawayEnergyRatio = 1.25;

}  // namespace

DynamicSolver::DynamicSolver(const Problem& problem, Backend& backend, const DynamicDesc& desc, const Log& log)
    : BodySolver(problem, backend, log), desc_(desc) {
  if (problem.initialVelocity.size() == v_.size()) v_ = problem.initialVelocity;
  v_ = (v_.array() * freeMask_).matrix();  // constrained dofs start at rest
  vPrev_ = v_;
  fextPrev_ = Eigen::VectorXd::Zero(x_.size());
  fextPrevSaved_ = fextPrev_;
  reactionPrev_ = Eigen::VectorXd::Zero(x_.size());
  reactionPrevSaved_ = reactionPrev_;
}

void DynamicSolver::initialAcceleration() {
  const Eigen::Index n = x_.size();
  Eigen::VectorXd fint(n), cv = Eigen::VectorXd::Zero(n);
  setBackendPositions(x_, true);
  backend_.internalForces(fint);
  if (problem_.rayleighMass != 0.0 || problem_.rayleighStiffness != 0.0) dampingForce(v_, cv);
  fextPrev_ = problem_.externalForce(0.0, /*dynamic=*/true);
  a_ = Eigen::VectorXd::Zero(n);
  for (Eigen::Index d = 0; d < n; ++d) {
    const double m = problem_.lumpedMass.size() == n ? problem_.lumpedMass[d] : 0.0;
    if (freeMask_[d] != 0.0 && m > 0.0) a_[d] = (fextPrev_[d] - cv[d] - fint[d]) / m;
  }
  // Reactions of the supports at t = 0 (a = 0 on constrained dofs), and the energy at t = 0.
  reactionPrev_ = ((cv + fint - fextPrev_).array() * (1.0 - freeMask_)).matrix();
  initialEnergy_ = kineticEnergy() + backend_.elasticEnergy();
  if (!allFinite(a_))
    fail(ErrorCode::SolveFailed, "body '", problem_.name,
         "': the initial acceleration is not finite; check the material, the loads and the initial velocity");
}

void DynamicSolver::dampingForce(const Eigen::VectorXd& v, Eigen::VectorXd& cv) {
  if (problem_.rayleighStiffness == 0.0 && problem_.lumpedMass.size() == v.size()) {
    cv = problem_.rayleighMass * problem_.lumpedMass.cwiseProduct(v);  // the reference's apply, to the bit
    return;
  }
  backend_.apply(SystemCoeffs{0.0, 1.0, 0.0}, v, cv);
}

void DynamicSolver::keepForRollback(State& s) {
  xPrev_.swap(s.x);
  vPrev_.swap(s.v);
  aPrev_.swap(s.a);
  workPrev_ = s.work;
  tPrev_ = s.t;
  fextPrevSaved_.swap(s.fextPrev);
  supportWorkSaved_ = s.supportWork;
  reactionPrevSaved_.swap(s.reactionPrev);
}

void DynamicSolver::capture(State& s) const {
  s.x = x_;
  s.v = v_;
  s.a = a_;
  s.fextPrev = fextPrev_;
  s.reactionPrev = reactionPrev_;
  s.work = work_;
  s.t = t_;
  s.supportWork = supportWork_;
}

void DynamicSolver::restore(const State& s) {
  x_ = s.x;
  v_ = s.v;
  a_ = s.a;
  fextPrev_ = s.fextPrev;
  reactionPrev_ = s.reactionPrev;
  work_ = s.work;
  t_ = s.t;
  supportWork_ = s.supportWork;
  backendAtCommitted_ = false;
}

BodyStepStats DynamicSolver::step(int index, int count) {
  if (!started_) {
    initialAcceleration();
    started_ = true;
  }
  State& start = start_;
  capture(start);
  const double h = desc_.timeStep;
  const int maxSubsteps = std::max(1, desc_.maxSubsteps);
  const std::string where = "time step " + std::to_string(index) + "/" + std::to_string(count);
  BodyStepStats total;  // iterations of every attempt: the cost really paid
  std::string tried;    // "1, 2, 4"
  for (int substeps = 1;; substeps *= 2) {
    tried += (tried.empty() ? "" : ", ") + std::to_string(substeps);
    try {
      BodyStepStats attempt;
      attempt.converged = true;
      for (int k = 1; k <= substeps; ++k) {
        // End time of substep k as start + k h / K, so that the step ends exactly at t_n + h.
        const double t1 = start.t + h * k / substeps;
        const BodyStepStats s = advance(t1 - t_, substeps == 1 ? where
                                                 : where + ", substep " + std::to_string(k) + "/" +
                                                       std::to_string(substeps));
        attempt.newtonIterations += s.newtonIterations;
        attempt.linearIterations += s.linearIterations;
        attempt.residual = std::max(attempt.residual, s.residual);
        attempt.linearResidual = std::max(attempt.linearResidual, s.linearResidual);
        attempt.converged = attempt.converged && s.converged;
      }
      total.newtonIterations += attempt.newtonIterations;
      total.linearIterations += attempt.linearIterations;
      total.residual = attempt.residual;
      total.linearResidual = attempt.linearResidual;
      total.converged = attempt.converged;
      total.substeps = substeps;
      break;
    } catch (const Error& e) {
      restore(start);
      setBackendPositions(x_, true);
      if (e.code() != ErrorCode::SolveFailed) throw;
      if (substeps * 2 > maxSubsteps) {
        if (substeps == 1) fail(ErrorCode::SolveFailed, e.what(), " The body keeps its state at t = ", start.t, " s");
        fail(ErrorCode::SolveFailed, "body '", problem_.name, "': ", where, " failed with ", tried,
             " substeps (analysis.max_substeps = ", maxSubsteps, "); the last attempt: ", e.what(),
             " The body keeps its state at t = ", start.t, " s");
      }
    }
  }
  if (total.substeps > 1)
    log_(LogLevel::Debug, "body '", problem_.name, "': time step ", index, "/", count, " retried, succeeded with ",
         total.substeps, " substeps");

  // The rollback copy is the state before the whole step, whatever the substeps.
  keepForRollback(start);
  return total;
}

BodyStepStats DynamicSolver::advance(double h, const std::string& where) {
  const Eigen::Index n = x_.size();
  const double t1 = t_ + h;

  // The affine maps a(v) = ka (v - vb), x(v) = xb + kx v of the scheme. The vectors are the
  // solver's scratch (sized by the first step, then assigned in place: no allocation per step).
  double ka = 0.0, kx = 0.0;
  Eigen::VectorXd &vb = w_.vb, &xb = w_.xb;
  if (desc_.integrator == Integrator::Newmark) {
    const double beta = desc_.newmarkBeta, gamma = desc_.newmarkGamma;
    ka = 1.0 / (h * gamma);
    kx = h * beta / gamma;
    vb = v_ + h * (1.0 - gamma) * a_;
    xb = x_ + h * v_ + h * h * (0.5 - beta) * a_ - kx * vb;
  } else {
    ka = 1.0 / h;
    kx = h;
    vb = v_;
    xb = x_;
  }
  const bool damped = problem_.rayleighMass != 0.0 || problem_.rayleighStiffness != 0.0;
  const SystemCoeffs system{1.0, 1.0 / ka, kx / ka};

  // The caller (step) restores the state of t_n and says so in the message.
  auto failHere = [&](const std::string& what, const std::string& fix) {
    setBackendPositions(x_, true);
    fail(ErrorCode::SolveFailed, "body '", problem_.name, "': ", where, " (t = ", t1, " s) ", what, "; ", fix,
         ".");
  };
  const std::string retryFix =
      desc_.maxSubsteps <= 1 ? ", or let failed steps be retried in substeps with analysis.max_substeps (e.g. 8)" : "";
  const std::string stepFix =
      "try a smaller analysis.time_step, more analysis.newton_iterations or a tighter solver.tolerance "
      "(or more solver.max_iterations)" + retryFix;

  // Targets of the constrained dofs at t_{n+1}: rest position (fixed) or X + ramp * value (prescribed).
  Eigen::VectorXd& target = w_.target;
  target = problem_.restPositions;
  problem_.applyPrescribed(target, t1, /*dynamic=*/true);
  Eigen::VectorXd& fext = w_.fext;
  problem_.externalForce(t1, /*dynamic=*/true, fext);
  const double fextNorm = freeNorm(fext);

  // Newton's starting point: v = v_n on the free dofs; constrained dofs hit their targets.
  Eigen::VectorXd& v = w_.v;
  v = v_;
  for (Eigen::Index d = 0; d < n; ++d)
    if (freeMask_[d] == 0.0) v[d] = (target[d] - xb[d]) / kx;

  const Eigen::VectorXd& mass = problem_.lumpedMass;
  Eigen::VectorXd &x = w_.x, &a = w_.a, &fint = w_.fint, &cv = w_.cv, &r = w_.r, &dv = w_.dv;
  x.resize(n);
  a.resize(n);
  fint.resize(n);
  cv.setZero(n);
  r.resize(n);
  dv.resize(n);
  BodyStepStats stats;
  double initialRelative = 0.0, initialNorm = 0.0, residualNorm = 0.0;
  bool allLinearConverged = true;
  bool evaluated = false;  // stats.residual was measured at the final v
  const int maxIterations = std::max(1, desc_.newtonIterations);
  for (int iteration = 0;; ++iteration) {
    x = xb + kx * v;
    a = ka * (v - vb);
    try {
      setBackendPositions(x, false);
      backend_.internalForces(fint);
      if (damped) dampingForce(v, cv);
    } catch (const Error& e) {
      failHere(std::string("failed: ") + e.what(), stepFix);
    }
    // r = M a + C v + f_int - f_ext, the free norms of its terms and of r, and whether x and v are
    // finite, in one pass over the body's vectors where there were eight (a batch's 100 bodies
    // stream them from memory between rounds). The norms' sums run in dof order (Eigen's
    // reductions summed in its own order: the last bits of the residual may differ from before).
    double maSq = 0.0, cvSq = 0.0, fintSq = 0.0, rSq = 0.0;
    bool finite = true;
    for (Eigen::Index d = 0; d < n; ++d) {
      const double ma = mass[d] * a[d];
      const double rd = ma + cv[d] + fint[d] - fext[d];
      r[d] = rd;
      const double f = freeMask_[d], maf = ma * f, cvf = cv[d] * f, fintf = fint[d] * f, rf = rd * f;
      maSq += maf * maf;
      cvSq += cvf * cvf;
      fintSq += fintf * fintf;
      rSq += rf * rf;
      finite = finite && std::isfinite(x[d]) && std::isfinite(v[d]);
    }
    const double scale = std::max({std::sqrt(maSq), std::sqrt(cvSq), std::sqrt(fintSq), fextNorm, forceFloor_});
    residualNorm = std::sqrt(rSq);
    const double relative = residualNorm / scale;
    if (!std::isfinite(relative) || !finite)
      failHere("produced non-finite forces, velocities or positions", stepFix);
    if (iteration == 0) {
      initialRelative = relative;
      initialNorm = residualNorm;
    }
    stats.residual = relative;
    evaluated = true;
    if (relative <= desc_.newtonTolerance || iteration == maxIterations) break;

    // Newton update: A dv = -r / ka with A = M + (1/ka) C + (kx/ka) K_t. Starting vector dv = 0,
    // i.e. the previous velocities (first iteration) or the current iterate.
    dv.setZero();
    LinearSolveStats ls;
    try {
      w_.rhs = -r / ka;
      ls = backend_.solve(system, w_.rhs, dv);
    } catch (const Error& e) {
      failHere(std::string("failed in the linear solve: ") + e.what(), stepFix);
    }
    stats.newtonIterations += 1;
    stats.linearIterations += ls.iterations;
    stats.linearResidual = std::max(stats.linearResidual, ls.relativeResidual);
    allLinearConverged = allLinearConverged && ls.converged;
    if (!allFinite(dv)) failHere("produced non-finite velocities", stepFix);
    v += dv;
    evaluated = false;  // the loop evaluates the new v before it ends
  }
  log_(LogLevel::Debug, "body '", problem_.name, "': ", where, ": ", stats.newtonIterations,
       " Newton iterations, relative residual ", sci(initialRelative), " -> ", sci(stats.residual));
  // The loop ends only right after evaluating its v: x and a are that evaluation's, and x and v
  // were checked there.
  if (!allFinite(a)) failHere("produced non-finite velocities or positions", stepFix);
  // Growth is judged on the absolute residual: the relative one is bounded by the number of terms
  // when f_int dominates, exactly as it does in a blow-up.
  if (!allLinearConverged && evaluated && residualNorm > initialNorm && stats.residual > kBlowUpResidual)
    failHere("blew up: the linear solve did not converge and the Newton residual grew from " +
                 sci(initialNorm) + " N to " + sci(residualNorm) + " N (relative " + sci(initialRelative) +
                 " to " + sci(stats.residual) + ")",
             stepFix);
  stats.converged = allLinearConverged;

  // Runaway guard (see the class comment). The reactions are the constrained rows of the last
  // residual, evaluated at the final v (or at the predictor when Newton stopped there).
  Eigen::VectorXd& reaction = w_.reaction;
  reaction = (r.array() * (1.0 - freeMask_)).matrix();
  const double supportWork = supportWork_ + 0.5 * (reactionPrev_ + reaction).dot(x - x_);
  const double loadWork = work_ + 0.5 * (fextPrev_ + fext).dot(x - x_);
  const double kinetic = 0.5 * (mass.array() * v.array().square()).sum();
  double elastic = 0.0;
  try {
    if (!evaluated) setBackendPositions(x, false);
    elastic = backend_.elasticEnergy();  // an element pass per step, unless the backend has it from the forces
  } catch (const Error& e) {
    failHere(std::string("failed: ") + e.what(), stepFix);
  }
  evaluated = true;  // the backend now holds x
  const double given = initialEnergy_ + std::abs(loadWork) + std::abs(supportWork);
  if (!(kinetic + elastic <= kRunawayEnergyRatio * given + forceFloor_ * diagonal_))
    failHere("ran away: the kinetic + elastic energy " + sci(kinetic + elastic) + " J exceeds " +
                 std::to_string(kRunawayEnergyRatio).substr(0, 4) + " times the energy the body was ever given (" + sci(given) +
                 " J: initial energy plus the work of the loads and supports); the scheme is feeding energy in",
             "use more analysis.newton_iterations (with analysis.newton_tolerance), a smaller analysis.time_step, "
             "a dissipative scheme (analysis.integrator \"backward_euler\", or analysis.newmark_gamma 0.6 with "
             "newmark_beta 0.3025), or a tighter solver.tolerance / more solver.max_iterations" + retryFix);

  // Commit (step() keeps the rollback copy): swapped with the scratch, whose old contents the next
  // step overwrites.
  work_ = loadWork;  // trapezoidal rule in time
  fextPrev_.swap(fext);
  supportWork_ = supportWork;
  reactionPrev_.swap(reaction);
  x_.swap(x);
  v_.swap(v);
  a_.swap(a);
  t_ = t1;
  backendAtCommitted_ = evaluated;  // the backend's positions are x only when evaluated at the final v
  return stats;
}

BodyStepStats DynamicSolver::idleStep(int, int) {
  if (!started_) {
    initialAcceleration();
    started_ = true;
  }
  State& start = start_;
  capture(start);
  t_ = start.t + desc_.timeStep;
  v_.setZero();
  a_.setZero();
  fextPrev_ = problem_.externalForce(t_, /*dynamic=*/true);
  keepForRollback(start);
  BodyStepStats stats;
  stats.newtonIterations = 0;
  stats.converged = true;
  return stats;
}

void DynamicSolver::rollback() {
  x_ = xPrev_;
  v_ = vPrev_;
  a_ = aPrev_;
  work_ = workPrev_;
  t_ = tPrev_;
  fextPrev_ = fextPrevSaved_;
  supportWork_ = supportWorkSaved_;
  reactionPrev_ = reactionPrevSaved_;
  backendAtCommitted_ = false;
}

}  // namespace corofem::detail
