// Implicit Newmark and backward Euler (paper Eq. 14) solved for the velocities by Newton, for a set
// of bodies in lock-step. The scheme, the constraint handling, the warm start and the blow-up rule
// are documented on DynamicsDriver in dynamics.hpp.
#include "solve/dynamics.hpp"

#include "solve/body_scale.hpp"

#include "util/error.hpp"
#include "util/format.hpp"
#include "util/parallel.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace corofem::detail {

namespace {

/// Relative residual above which a step whose linear solves did not converge, and whose residual
/// grew during the step, counts as blown up. Below it the step is merely inexact (the user traded
/// accuracy for speed with a low solver.max_iterations).
constexpr double kBlowUpResidual = 1e-3;

/// Mechanical energy (kinetic + elastic), in units of the energy the body was ever given, above
/// which a step ran away (see DynamicsDriver).
constexpr double kRunawayEnergyRatio = 1.25;

/// fn(i) for every i < n on the host's threads (each i a body's own work: no shared writes).
template <class Fn>
void forEach(std::size_t n, Fn&& fn) {
  parallelChunks(n, 1, [&](std::size_t, std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) fn(i);
  });
}

bool allFinite(const Eigen::VectorXd& v) { return v.allFinite(); }

/// Dofs of one body per chunk of the host's threads in the per-dof passes of a step. A body of at
/// most this many dofs runs on one thread, its sums in dof order; a larger one's sums are taken per
/// chunk, then added in chunk order: the same bits with any number of threads, and a body gets the
/// same bits alone as in a batch.
constexpr std::size_t kDofChunk = 16384;

/// chunkSums over a body's n dofs in chunks of kDofChunk, fn(begin, end, sums) on Eigen indices.
template <std::size_t K, class Fn>
std::array<double, K> overDofs(Eigen::Index n, Fn&& fn) {
  return chunkSums<K>(static_cast<std::size_t>(n), kDofChunk, [&](std::size_t lo, std::size_t hi, std::array<double, K>& sums) {
    fn(static_cast<Eigen::Index>(lo), static_cast<Eigen::Index>(hi), sums);
  });
}

/// A number as a message streams it ("0.05", "2.39").
std::string num(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

}  // namespace

DynamicsDriver::DynamicsDriver(DeviceSlot& slot, const DynamicDesc& desc, const Log& log)
    : slot_(slot), desc_(desc), log_(log) {
  bodies_.resize(slot.bodyCount());
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    Body& b = bodies_[i];
    const Problem& p = slot.problem(i);
    b.problem = &p;
    const Eigen::Index n = p.restPositions.size();
    BodyScale scale = bodyScale(p);
    b.freeMask = std::move(scale.freeMask);
    b.diagonal = scale.diagonal;
    b.forceFloor = scale.forceFloor;
    b.x = p.restPositions;
    b.v = p.initialVelocity.size() == n ? p.initialVelocity : Eigen::VectorXd::Zero(n);
    b.v = (b.v.array() * b.freeMask).matrix();  // constrained dofs start at rest
    b.a = Eigen::VectorXd::Zero(n);
    b.fextPrev = Eigen::VectorXd::Zero(n);
    b.reactionPrev = Eigen::VectorXd::Zero(n);
    capture(b, b.previous);
  }
}

double DynamicsDriver::freeNorm(const Body& b, const Eigen::VectorXd& v) const {
  return (v.array() * b.freeMask).matrix().norm();
}

void DynamicsDriver::capture(const Body& b, State& s) const { s = static_cast<const State&>(b); }

void DynamicsDriver::restore(Body& b, const State& s) {
  static_cast<State&>(b) = s;
  b.deviceAtCommitted = false;
}

void DynamicsDriver::restoreStart(Body& b) {
  if (b.startHeld)
    restore(b, b.start);  // a substep committed: start keeps the step's start for the next attempt
  else
    b.deviceAtCommitted = false;  // nothing committed: the body's state is the step's start
}

void DynamicsDriver::setState(std::size_t body, const Eigen::VectorXd& x, const Eigen::VectorXd& v) {
  Body& b = bodies_.at(body);
  if (x.size() != b.x.size() || v.size() != b.x.size())
    fail(ErrorCode::BadInput, "body '", b.problem->name, "': a state needs ", b.x.size(),
         " positions and velocities (3 per node), got ", x.size(), " and ", v.size());
  if (!x.allFinite() || !v.allFinite())
    fail(ErrorCode::BadInput, "body '", b.problem->name, "': the positions or velocities are not finite; give finite "
         "numbers (m, m/s)");
  b.x = x;
  b.v = (v.array() * b.freeMask).matrix();
  b.started = false;  // the next step measures a and the energy budget from this state
  capture(b, b.previous);
  b.deviceAtCommitted = false;
}

void DynamicsDriver::constraintsChanged(std::size_t body) {
  Body& b = bodies_.at(body);
  b.freeMask = bodyScale(*b.problem).freeMask;
  b.v = (b.v.array() * b.freeMask).matrix();  // held dofs: their velocities follow from their targets
}

void DynamicsDriver::materialChanged(std::size_t body) {
  Body& b = bodies_.at(body);
  b.forceFloor = bodyScale(*b.problem).forceFloor;
  b.started = false;  // the elastic energy changed with the stiffness: the budget is measured again
  b.deviceAtCommitted = false;
}

void DynamicsDriver::setControls(std::size_t body, const BodyControls& c) {
  Body& b = bodies_.at(body);
  const Eigen::Index n = b.x.size();
  for (const Eigen::VectorXd* v : {&c.targets, &c.forces, &c.springTargets})
    if (v->size() != 0 && v->size() != n)
      fail(ErrorCode::Internal, "body '", b.problem->name, "': controls of size ", v->size(), " for ", n, " dofs");
  b.heldTarget = c.targets;
  b.appliedForce = c.forces;
  b.springTarget = c.springTargets;
}

void DynamicsDriver::externalForce(const Body& b, double t, Eigen::VectorXd& f) const {
  b.problem->externalForce(t, /*dynamic=*/true, f);
  if (b.appliedForce.size() == f.size()) f += b.appliedForce;
}

void DynamicsDriver::addSpringForces(const Body& b, const Eigen::VectorXd& x, Eigen::VectorXd& f) const {
  // Free dofs only: on a held dof the support's reaction takes the spring's pull (the residual's
  // constrained rows hold it), and counting it as a load as well would count its work twice.
  const Eigen::VectorXd& k = b.problem->springStiffness;
  if (k.size() != x.size() || b.springTarget.size() != x.size()) return;
  for (Eigen::Index d = 0; d < x.size(); ++d)
    if (k[d] != 0.0 && b.freeMask[d] != 0.0) f[d] += k[d] * (b.springTarget[d] - x[d]);
}

double DynamicsDriver::kineticEnergy(std::size_t body) const {
  const Body& b = bodies_.at(body);
  const Eigen::VectorXd& m = b.problem->lumpedMass;
  if (m.size() != b.v.size()) return 0.0;
  return 0.5 * (m.array() * b.v.array().square()).sum();
}

double DynamicsDriver::elasticEnergy(std::size_t body) {
  syncDevicePositions({body});
  std::vector<double> e;
  slot_.elasticEnergy({body}, e);
  return e.at(0);
}

void DynamicsDriver::syncDevicePositions(const BodySet& set) {
  BodySet stale;
  ConstVectors xs;
  for (std::size_t i : set)
    if (!bodies_.at(i).deviceAtCommitted) {
      stale.push_back(i);
      xs.push_back(&bodies_[i].x);
    }
  if (stale.empty()) return;
  slot_.setPositions(stale, xs);
  for (std::size_t i : stale) bodies_[i].deviceAtCommitted = true;
}

void DynamicsDriver::dampingForces(const BodySet& set, const ConstVectors& v, const Vectors& cv) {
  // Mass damping alone (beta = 0, the common "air drag") is a scaling of the lumped mass: formed
  // here in double, the same expression and bits as the reference device's apply, with no device
  // call (on a device that call is an upload, a product and a read per force evaluation).
  BodySet stiff;
  ConstVectors stiffV;
  Vectors stiffCv;
  for (std::size_t i = 0; i < set.size(); ++i) {
    const Problem& p = *bodies_[set[i]].problem;
    if (p.rayleighStiffness == 0.0 && p.lumpedMass.size() == v[i]->size()) {
      *cv[i] = p.rayleighMass * p.lumpedMass.cwiseProduct(*v[i]);
    } else {
      stiff.push_back(set[i]);
      stiffV.push_back(v[i]);
      stiffCv.push_back(cv[i]);
    }
  }
  if (!stiff.empty()) slot_.apply(stiff, std::vector<SystemCoeffs>(stiff.size(), SystemCoeffs{0.0, 1.0, 0.0}), stiffV, stiffCv);
}

void DynamicsDriver::start(const BodySet& set, std::vector<std::string>& failure) {
  BodySet fresh;
  for (std::size_t i : set)
    if (!bodies_[i].started) fresh.push_back(i);
  if (fresh.empty()) return;
  const std::size_t n = fresh.size();
  ConstVectors xs(n), vs(n);
  Vectors fs(n), cvs(n);
  std::vector<Eigen::VectorXd> fint(n), cv(n);
  BodySet damped;
  ConstVectors dampedV;
  Vectors dampedCv;
  for (std::size_t k = 0; k < n; ++k) {
    Body& b = bodies_[fresh[k]];
    xs[k] = &b.x;
    fs[k] = &fint[k];
    cv[k] = Eigen::VectorXd::Zero(b.x.size());
    if (b.problem->rayleighMass != 0.0 || b.problem->rayleighStiffness != 0.0) {
      damped.push_back(fresh[k]);
      dampedV.push_back(&b.v);
      dampedCv.push_back(&cv[k]);
    }
  }
  slot_.setPositions(fresh, xs);
  for (std::size_t i : fresh) bodies_[i].deviceAtCommitted = true;
  slot_.internalForces(fresh, fs);
  if (!damped.empty()) dampingForces(damped, dampedV, dampedCv);
  std::vector<double> energy;
  slot_.elasticEnergy(fresh, energy);
  for (std::size_t k = 0; k < n; ++k) {
    Body& b = bodies_[fresh[k]];
    const Problem& p = *b.problem;
    const Eigen::Index size = b.x.size();
    externalForce(b, b.t, b.fextPrev);
    addSpringForces(b, b.x, b.fextPrev);
    b.a = Eigen::VectorXd::Zero(size);
    for (Eigen::Index d = 0; d < size; ++d) {
      const double m = p.lumpedMass.size() == size ? p.lumpedMass[d] : 0.0;
      if (b.freeMask[d] != 0.0 && m > 0.0) b.a[d] = (b.fextPrev[d] - cv[k][d] - fint[k][d]) / m;
    }
    // Reactions of the supports at t = 0 (a = 0 on constrained dofs), and the energy at t = 0.
    b.reactionPrev = ((cv[k] + fint[k] - b.fextPrev).array() * (1.0 - b.freeMask)).matrix();
    b.initialEnergy = kineticEnergy(fresh[k]) + energy[k];
    if (!allFinite(b.a)) {
      failure[fresh[k]] = "body '" + p.name +
                          "': the initial acceleration is not finite; check the material, the loads and the initial velocity";
      continue;
    }
    b.started = true;
    capture(b, b.previous);
  }
}

std::vector<BodyOutcome> DynamicsDriver::step(const BodySet& set, const StepCall& call) {
  std::vector<BodyOutcome> out(set.size());
  std::vector<std::string> startFailure(bodies_.size());
  try {
    start(set, startFailure);
  } catch (...) {
    // The initial state could not be evaluated (every device failed): nothing moved.
    for (BodyOutcome& o : out) o.error = std::current_exception();
    return out;
  }
  const std::string where =
      "time step " + std::to_string(call.index) + (call.count > 0 ? "/" + std::to_string(call.count) : "");
  Attempts at(set.size());
  std::vector<std::size_t>& pending = at.pending;
  for (std::size_t i = 0; i < set.size(); ++i) {
    if (!startFailure[set[i]].empty()) {
      out[i].error = std::make_exception_ptr(Error(ErrorCode::SolveFailed, startFailure[set[i]]));
      continue;
    }
    Body& b = bodies_[set[i]];
    b.start.copyScalars(b);  // the vectors follow at the first commit, without a copy
    b.startHeld = false;
    pending.push_back(i);
  }
  try {
    runAttempts(set, where, call.h, at, out);
  } catch (...) {
    // Every device of the slot failed (a DeviceError), or something other than a solve failed
    // (out of memory, the application's task runner): the bodies still stepping keep their state
    // at the step's start; substeps would not help.
    for (std::size_t i : pending) {
      restoreStart(bodies_[set[i]]);
      out[i].error = std::current_exception();
    }
  }
  return out;
}

void DynamicsDriver::runAttempts(const BodySet& set, const std::string& where, double h, Attempts& at,
                                 std::vector<BodyOutcome>& out) {
  std::vector<std::size_t>& pending = at.pending;
  std::vector<BodyStepStats>& total = at.total;
  std::vector<std::string>& tried = at.tried;
  std::vector<std::string>& lastFailure = at.lastFailure;
  const int maxSubsteps = std::max(1, desc_.maxSubsteps);
  for (int substeps = 1; !pending.empty(); substeps *= 2) {
    std::vector<BodyStepStats> attempt(set.size());
    for (std::size_t i : pending) {
      tried[i] += (tried[i].empty() ? "" : ", ") + std::to_string(substeps);
      attempt[i].converged = true;
    }
    std::vector<std::size_t> going = pending;  // still succeeding in this attempt
    for (int k = 1; k <= substeps && !going.empty(); ++k) {
      std::vector<Advance> adv(going.size());
      for (std::size_t j = 0; j < going.size(); ++j) {
        Body& b = bodies_[set[going[j]]];
        Advance& a = adv[j];
        a.body = set[going[j]];
        // End time of substep k as start + k h / K, so that the step ends exactly at t_n + h.
        a.t1 = b.start.t + h * k / substeps;
        a.h = a.t1 - b.t;
        a.fraction = static_cast<double>(k) / substeps;
        a.where = substeps == 1 ? where
                                : where + ", substep " + std::to_string(k) + "/" + std::to_string(substeps);
      }
      advance(adv);
      std::vector<std::size_t> still;
      for (std::size_t j = 0; j < going.size(); ++j) {
        const std::size_t i = going[j];
        const BodyStepStats& s = adv[j].stats;
        attempt[i].newtonIterations += s.newtonIterations;
        attempt[i].linearIterations += s.linearIterations;
        attempt[i].residual = std::max(attempt[i].residual, s.residual);
        attempt[i].linearResidual = std::max(attempt[i].linearResidual, s.linearResidual);
        attempt[i].converged = attempt[i].converged && s.converged;
        if (adv[j].failure.empty()) {
          still.push_back(i);
        } else {
          lastFailure[i] = adv[j].failure;
          restoreStart(bodies_[set[i]]);
        }
      }
      going = std::move(still);
    }
    // Every attempt's iterations count (the cost really paid), failed ones too.
    for (std::size_t i : pending) {
      total[i].newtonIterations += attempt[i].newtonIterations;
      total[i].linearIterations += attempt[i].linearIterations;
    }
    // The bodies that went through every substep succeeded with this many.
    for (std::size_t i : going) {
      total[i].residual = attempt[i].residual;
      total[i].linearResidual = attempt[i].linearResidual;
      total[i].converged = attempt[i].converged;
      total[i].substeps = substeps;
      if (substeps > 1)
        log_(LogLevel::Debug, "body '", bodies_[set[i]].problem->name, "': ", where, " retried, succeeded with ",
             substeps, " substeps");
      // The rollback copy is the state before the whole step, whatever the substeps.
      std::swap(bodies_[set[i]].previous, bodies_[set[i]].start);  // held: the step committed
      bodies_[set[i]].startHeld = false;
      out[i].stats = total[i];
    }
    std::vector<std::size_t> retry;
    for (std::size_t i : pending) {
      if (std::find(going.begin(), going.end(), i) != going.end()) continue;
      const Body& b = bodies_[set[i]];
      if (substeps * 2 > maxSubsteps) {
        const std::string message =
            substeps == 1 ? lastFailure[i] + " The body keeps its state at t = " + num(b.start.t) + " s"
                          : "body '" + b.problem->name + "': " + where + " failed with " + tried[i] +
                                " substeps (analysis.max_substeps = " + std::to_string(maxSubsteps) +
                                "); the last attempt: " + lastFailure[i] + " The body keeps its state at t = " +
                                num(b.start.t) + " s";
        out[i].stats = total[i];
        out[i].error = std::make_exception_ptr(Error(ErrorCode::SolveFailed, message));
      } else {
        retry.push_back(i);
      }
    }
    pending = std::move(retry);
  }
}

std::string DynamicsDriver::failureText(const Advance& a, const std::string& what, const std::string& fix) const {
  return "body '" + bodies_[a.body].problem->name + "': " + a.where + " (t = " + num(a.t1) + " s) " + what + "; " +
         fix + ".";
}

void DynamicsDriver::advance(std::vector<Advance>& adv) {
  const std::string retryFix =
      desc_.maxSubsteps <= 1 ? ", or let failed steps be retried in substeps with analysis.max_substeps (e.g. 8)" : "";
  const std::string stepFix =
      "try a smaller analysis.time_step, more analysis.newton_iterations or a tighter solver.tolerance "
      "(or more solver.max_iterations)" + retryFix;
  auto failHere = [&](Advance& a, const std::string& what) {
    if (a.failure.empty()) a.failure = failureText(a, what, stepFix);
    a.running = false;
  };

  // The affine maps a(v) = ka (v - vb), x(v) = xb + kx v of the scheme, the targets of the
  // constrained dofs at t_{n+1} (rest position, or X + ramp * value for prescribed ones), f_ext,
  // and Newton's starting point v = v_n (constrained dofs hitting their targets).
  forEach(adv.size(), [&](std::size_t j) {
    Advance& a = adv[j];
    Body& b = bodies_[a.body];
    const Problem& p = *b.problem;
    auto& w = b.w;
    const double h = a.h;
    const Eigen::Index n = b.x.size();
    // vb = v + cv a and xb = x + h v + ca a - kx vb (Newmark), or vb = v and xb = x.
    const bool newmark = integratorOf(desc_) == Integrator::Newmark;
    double cv = 0.0, ca = 0.0;
    if (newmark) {
      const double beta = desc_.newmarkBeta, gamma = desc_.newmarkGamma;
      a.ka = 1.0 / (h * gamma);
      a.kx = h * beta / gamma;
      cv = h * (1.0 - gamma);
      ca = h * h * (0.5 - beta);
    } else {
      a.ka = 1.0 / h;
      a.kx = h;
    }
    // The targets, read on constrained dofs only (the other entries are left as they were).
    w.target.resize(n);
    p.applyPrescribed(w.target, a.t1, /*dynamic=*/true);
    if (b.heldTarget.size() == n) {
      const Eigen::VectorXd& x0 = b.startHeld ? b.start.x : b.x;  // the step's start
      for (Eigen::Index d = 0; d < n; ++d)
        if (!std::isnan(b.heldTarget[d]))
          w.target[d] = a.fraction == 1.0 ? b.heldTarget[d] : x0[d] + a.fraction * (b.heldTarget[d] - x0[d]);
    }
    const std::vector<double> scales = p.loadScales(a.t1, /*dynamic=*/true);
    const bool applied = b.appliedForce.size() == n;
    for (Eigen::VectorXd* v : {&w.vb, &w.xb, &w.fext, &w.v, &w.x, &w.a, &w.fint, &w.cv, &w.r, &w.dv, &w.rhs}) v->resize(n);
    // One pass: vb, xb, f_ext (the loads, then the application's forces) and its free norm, and
    // Newton's starting v. The same arithmetic, term by term, as the vector expressions it fuses.
    const std::array<double, 1> fextSq = overDofs<1>(n, [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 1>& sum) {
      for (Eigen::Index d = lo; d < hi; ++d) {
        const double vb = newmark ? b.v[d] + cv * b.a[d] : b.v[d];
        const double xb = newmark ? b.x[d] + h * b.v[d] + ca * b.a[d] - a.kx * vb : b.x[d];
        w.vb[d] = vb;
        w.xb[d] = xb;
        double f = p.externalForceAt(scales, d);
        if (applied) f += b.appliedForce[d];
        w.fext[d] = f;
        const double ff = f * b.freeMask[d];
        sum[0] += ff * ff;
        w.v[d] = b.freeMask[d] == 0.0 ? (w.target[d] - xb) / a.kx : b.v[d];
        w.cv[d] = 0.0;
      }
    });
    a.fextNorm = std::sqrt(fextSq[0]);
  });

  const int maxIterations = std::max(1, desc_.newtonIterations);
  for (int iteration = 0;; ++iteration) {
    std::vector<std::size_t> live;  // indices into adv
    for (std::size_t j = 0; j < adv.size(); ++j)
      if (adv[j].running) live.push_back(j);
    if (live.empty()) break;
    BodySet set;
    ConstVectors xs, vs;
    Vectors fs, cvs;
    forEach(live.size(), [&](std::size_t k) {
      const Advance& a = adv[live[k]];
      auto& w = bodies_[a.body].w;
      overDofs<0>(w.v.size(), [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 0>&) {
        for (Eigen::Index d = lo; d < hi; ++d) {
          w.x[d] = w.xb[d] + a.kx * w.v[d];
          w.a[d] = a.ka * (w.v[d] - w.vb[d]);
        }
      });
    });
    for (std::size_t j : live) {
      Body& b = bodies_[adv[j].body];
      set.push_back(adv[j].body);
      xs.push_back(&b.w.x);
      fs.push_back(&b.w.fint);
    }
    BodySet damped;
    for (std::size_t j : live) {
      const Problem& p = *bodies_[adv[j].body].problem;
      if (p.rayleighMass != 0.0 || p.rayleighStiffness != 0.0) {
        damped.push_back(adv[j].body);
        vs.push_back(&bodies_[adv[j].body].w.v);
        cvs.push_back(&bodies_[adv[j].body].w.cv);
      }
    }
    try {
      slot_.setPositions(set, xs);
      for (std::size_t i : set) bodies_[i].deviceAtCommitted = false;
      slot_.internalForces(set, fs);
      if (!damped.empty()) dampingForces(damped, vs, cvs);
    } catch (const Error& e) {
      if (e.code() == ErrorCode::DeviceError) throw;  // every device of the slot failed: the step fails
      for (std::size_t j : live) failHere(adv[j], std::string("failed: ") + e.what());
      break;
    }
    // r = M a + C v + f_int - f_ext, the free norms of its terms and of r, and whether x and v are
    // finite, in one pass over the body's vectors. The norms' sums run in dof order.
    forEach(live.size(), [&](std::size_t k) {
      Advance& a = adv[live[k]];
      Body& b = bodies_[a.body];
      auto& w = b.w;
      const Eigen::VectorXd& mass = b.problem->lumpedMass;
      const Eigen::Index n = b.x.size();
      // The springs' S (x - t) joins f_int here (a zero vector's worth of work without springs).
      const Eigen::VectorXd& ks = b.problem->springStiffness;
      const bool springs = ks.size() == n && b.springTarget.size() == n;
      // Sums: |M a|^2, |C v|^2, |f_int|^2, |S (x - t)|^2, |r|^2 (free dofs), non-finite x or v.
      const std::array<double, 6> sums = overDofs<6>(n, [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 6>& sum) {
        for (Eigen::Index d = lo; d < hi; ++d) {
          const double ma = mass[d] * w.a[d];
          const double spring = springs && ks[d] != 0.0 ? ks[d] * (w.x[d] - b.springTarget[d]) : 0.0;
          const double rd = ma + w.cv[d] + w.fint[d] + spring - w.fext[d];
          w.r[d] = rd;
          const double f = b.freeMask[d], maf = ma * f, cvf = w.cv[d] * f, fintf = w.fint[d] * f, sf = spring * f,
                       rf = rd * f;
          sum[0] += maf * maf;
          sum[1] += cvf * cvf;
          sum[2] += fintf * fintf;
          sum[3] += sf * sf;
          sum[4] += rf * rf;
          if (!std::isfinite(w.x[d]) || !std::isfinite(w.v[d])) sum[5] += 1.0;
        }
      });
      const double maSq = sums[0], cvSq = sums[1], fintSq = sums[2], springSq = sums[3], rSq = sums[4];
      const bool finite = sums[5] == 0.0;
      const double scale = std::max(
          {std::sqrt(maSq), std::sqrt(cvSq), std::sqrt(fintSq), std::sqrt(springSq), a.fextNorm, b.forceFloor});
      a.residualNorm = std::sqrt(rSq);
      const double relative = a.residualNorm / scale;
      if (!std::isfinite(relative) || !finite) {
        failHere(a, "produced non-finite forces, velocities or positions");
        return;
      }
      if (iteration == 0) {
        a.initialRelative = relative;
        a.initialNorm = a.residualNorm;
      }
      a.stats.residual = relative;
      a.evaluated = true;
      if (relative <= desc_.newtonTolerance || iteration == maxIterations) a.running = false;
    });

    // Newton update: A dv = -r / ka with A = M + (1/ka) C + (kx/ka) K_t, starting at dv = 0 (the
    // previous velocities on the first iteration, the current iterate after).
    std::vector<std::size_t> solving;
    for (std::size_t j : live)
      if (adv[j].running) solving.push_back(j);
    if (solving.empty()) break;
    BodySet solveSet;
    std::vector<PcgSolve> solves(solving.size());
    forEach(solving.size(), [&](std::size_t k) {
      const Advance& a = adv[solving[k]];
      auto& w = bodies_[a.body].w;
      overDofs<0>(w.r.size(), [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 0>&) {
        for (Eigen::Index d = lo; d < hi; ++d) {
          w.dv[d] = 0.0;
          w.rhs[d] = -w.r[d] / a.ka;
        }
      });
    });
    for (std::size_t k = 0; k < solving.size(); ++k) {
      Advance& a = adv[solving[k]];
      Body& b = bodies_[a.body];
      solveSet.push_back(a.body);
      solves[k].coeffs = SystemCoeffs{1.0, 1.0 / a.ka, a.kx / a.ka};
      solves[k].b = &b.w.rhs;
      solves[k].x = &b.w.dv;
    }
    try {
      slot_.solve(solveSet, solves);
    } catch (const Error& e) {
      if (e.code() == ErrorCode::DeviceError) throw;  // every device of the slot failed: the step fails
      for (std::size_t j : solving) failHere(adv[j], std::string("failed in the linear solve: ") + e.what());
      break;
    }
    for (std::size_t k = 0; k < solving.size(); ++k) {
      Advance& a = adv[solving[k]];
      Body& b = bodies_[a.body];
      if (!solves[k].failure.empty()) {
        failHere(a, "failed in the linear solve: " + solves[k].failure);
        continue;
      }
      const LinearSolveStats& ls = solves[k].stats;
      a.stats.newtonIterations += 1;
      a.stats.linearIterations += ls.iterations;
      a.stats.linearResidual = std::max(a.stats.linearResidual, ls.relativeResidual);
      a.allLinearConverged = a.allLinearConverged && ls.converged;
      auto& w = b.w;  // v += dv, counting non-finite entries of dv (a failed body's v is scratch)
      const std::array<double, 1> bad = overDofs<1>(w.v.size(), [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 1>& sum) {
        for (Eigen::Index d = lo; d < hi; ++d) {
          if (!std::isfinite(w.dv[d])) sum[0] += 1.0;
          w.v[d] += w.dv[d];
        }
      });
      if (bad[0] != 0.0) {
        failHere(a, "produced non-finite velocities");
        continue;
      }
      a.evaluated = false;  // the loop evaluates the new v before it ends
    }
  }

  // The loop ends for a body only right after evaluating its v: x and a are that evaluation's, and
  // x and v were checked there. Growth is judged on the absolute residual: the relative one is
  // bounded by the number of terms when f_int dominates, exactly as it does in a blow-up.
  std::vector<std::size_t> ok;
  for (std::size_t j = 0; j < adv.size(); ++j) {
    Advance& a = adv[j];
    if (!a.failure.empty()) continue;
    Body& b = bodies_[a.body];
    log_(LogLevel::Debug, "body '", b.problem->name, "': ", a.where, ": ", a.stats.newtonIterations,
         " Newton iterations, relative residual ", sci(a.initialRelative), " -> ", sci(a.stats.residual));
    if (!allFinite(b.w.a)) {
      failHere(a, "produced non-finite velocities or positions");
      continue;
    }
    if (!a.allLinearConverged && a.evaluated && a.residualNorm > a.initialNorm && a.stats.residual > kBlowUpResidual) {
      // What was seen, not a diagnosis: the relative residual may have stayed near 1 (a solve
      // stopped far from its tolerance made no progress), or the state may be running away.
      const SolverDesc& solver = slot_.solver();
      const bool pcg = solver.linearSolver == LinearSolverKind::Pcg;
      const std::string solves =
          pcg ? "its linear solves stopped at solver.max_iterations = " + std::to_string(solver.maxIterations) +
                    " with a relative residual up to " + sci(a.stats.linearResidual) + " (solver.tolerance " +
                    sci(solver.tolerance) + ")"
              : "its direct solves did not reach solver.tolerance = " + sci(solver.tolerance) +
                    " (relative residual up to " + sci(a.stats.linearResidual) + ")";
      const std::string fix =
          pcg ? "raise solver.max_iterations until the solves converge, or try a smaller analysis.time_step (easier "
                "systems)" + retryFix + "; a step whose solves still stop short of the tolerance completes inexact, "
                "flagged unconverged (StepReport::converged, summary.json)"
              : "try a smaller analysis.time_step" + retryFix + ", and check the constraints and the material";
      if (a.failure.empty())
        a.failure = failureText(a, "failed: " + solves + ", and the Newton residual grew from " + sci(a.initialNorm) +
                                       " N to " + sci(a.residualNorm) + " N (relative " + sci(a.initialRelative) +
                                       " to " + sci(a.stats.residual) +
                                       ") instead of falling, so the step's answer cannot be trusted",
                                fix);
      a.running = false;
      continue;
    }
    a.stats.converged = a.allLinearConverged;
    ok.push_back(j);
  }
  if (ok.empty()) return;

  // Runaway guard (see the class comment): an elastic-energy evaluation per step, at the final v.
  BodySet reset, energySet;
  ConstVectors resetX;
  for (std::size_t j : ok) {
    Body& b = bodies_[adv[j].body];
    energySet.push_back(adv[j].body);
    if (!adv[j].evaluated) {
      reset.push_back(adv[j].body);
      resetX.push_back(&b.w.x);
    }
  }
  std::vector<double> elastic;
  try {
    if (!reset.empty()) slot_.setPositions(reset, resetX);
    slot_.elasticEnergy(energySet, elastic);
  } catch (const Error& e) {
    if (e.code() == ErrorCode::DeviceError) throw;  // every device of the slot failed: the step fails
    for (std::size_t j : ok) failHere(adv[j], std::string("failed: ") + e.what());
    return;
  }
  const std::string runawayFix =
      "use more analysis.newton_iterations (with analysis.newton_tolerance), a smaller analysis.time_step, "
      "a dissipative scheme (analysis.integrator \"backward_euler\", or analysis.newmark_gamma 0.6 with "
      "newmark_beta 0.3025), or a tighter solver.tolerance / more solver.max_iterations" + retryFix;
  for (std::size_t k = 0; k < ok.size(); ++k) {
    Advance& a = adv[ok[k]];
    Body& b = bodies_[a.body];
    auto& w = b.w;
    const Eigen::VectorXd& mass = b.problem->lumpedMass;
    const Eigen::Index n = b.x.size();
    const Eigen::VectorXd& ks = b.problem->springStiffness;
    const bool springs = ks.size() == n && b.springTarget.size() == n;
    w.reaction.resize(n);
    // One pass: the reactions (the constrained rows of the last residual, evaluated at the final v,
    // or at the predictor when Newton stopped there); the springs' pull on free dofs joins f_ext
    // (a load from here: its work, and f_n of the next step; on a held dof the reaction takes it);
    // and the sums of the loads' and supports' work over dx = x_{n+1} - x_n and of m v^2:
    // (R_n + R).dx, (F_n + F).dx, R_n.dx, R.dx, F_n.dx, F.dx, m v^2.
    const std::array<double, 7> sums = overDofs<7>(n, [&](Eigen::Index lo, Eigen::Index hi, std::array<double, 7>& sum) {
      for (Eigen::Index d = lo; d < hi; ++d) {
        const double reaction = w.r[d] * (1.0 - b.freeMask[d]);
        w.reaction[d] = reaction;
        if (springs && ks[d] != 0.0 && b.freeMask[d] != 0.0) w.fext[d] += ks[d] * (b.springTarget[d] - w.x[d]);
        const double dx = w.x[d] - b.x[d], f = w.fext[d];
        sum[0] += (b.reactionPrev[d] + reaction) * dx;
        sum[1] += (b.fextPrev[d] + f) * dx;
        sum[2] += b.reactionPrev[d] * dx;
        sum[3] += reaction * dx;
        sum[4] += b.fextPrev[d] * dx;
        sum[5] += f * dx;
        sum[6] += mass[d] * (w.v[d] * w.v[d]);
      }
    });
    const double supportWork = b.supportWork + 0.5 * sums[0];
    const double loadWork = b.work + 0.5 * sums[1];
    const double g = integratorOf(desc_) == Integrator::Newmark ? desc_.newmarkGamma : 1.0;
    const double supportWorkScheme = b.supportWorkScheme + (1.0 - g) * sums[2] + g * sums[3];
    const double loadWorkScheme = b.loadWorkScheme + (1.0 - g) * sums[4] + g * sums[5];
    const double kinetic = 0.5 * sums[6];
    const double given = b.initialEnergy + std::max(std::abs(loadWork) + std::abs(supportWork),
                                                    std::abs(loadWorkScheme) + std::abs(supportWorkScheme));
    b.deviceAtCommitted = false;  // the device holds w.x now: committed below, or the step fails
    if (!(kinetic + elastic[k] <= kRunawayEnergyRatio * given + b.forceFloor * b.diagonal)) {
      a.failure = failureText(a,
                              "ran away: the kinetic + elastic energy " + sci(kinetic + elastic[k]) + " J exceeds " +
                                  std::to_string(kRunawayEnergyRatio).substr(0, 4) +
                                  " times the energy the body was ever given (" + sci(given) +
                                  " J: initial energy plus the work of the loads and supports); the scheme is "
                                  "feeding energy in",
                              runawayFix);
      continue;
    }
    // Commit: swapped with the scratch. The state before the step goes to start where start does
    // not hold it yet (the step's first commit); else the next step overwrites it as scratch.
    b.work = loadWork;  // trapezoidal rule in time
    b.fextPrev.swap(w.fext);
    b.supportWork = supportWork;
    b.supportWorkScheme = supportWorkScheme;
    b.loadWorkScheme = loadWorkScheme;
    b.reactionPrev.swap(w.reaction);
    b.x.swap(w.x);
    b.v.swap(w.v);
    b.a.swap(w.a);
    if (!b.startHeld) {
      b.start.fextPrev.swap(w.fext);
      b.start.reactionPrev.swap(w.reaction);
      b.start.x.swap(w.x);
      b.start.v.swap(w.v);
      b.start.a.swap(w.a);
      b.startHeld = true;
    }
    b.t = a.t1;
    b.deviceAtCommitted = true;  // the device's positions are x: evaluated at the final v
  }
}

void DynamicsDriver::idleStep(std::size_t body, double h) {
  std::vector<std::string> failure(bodies_.size());
  start({body}, failure);
  if (!failure[body].empty()) fail(ErrorCode::SolveFailed, failure[body]);
  Body& b = bodies_[body];
  capture(b, b.start);
  b.t = b.start.t + h;
  b.v.setZero();
  b.a.setZero();
  externalForce(b, b.t, b.fextPrev);
  addSpringForces(b, b.x, b.fextPrev);
  std::swap(b.previous, b.start);
}

void DynamicsDriver::rollback(std::size_t body) {
  Body& b = bodies_.at(body);
  restore(b, b.previous);
}

}  // namespace corofem::detail
