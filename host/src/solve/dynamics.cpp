// Implicit Newmark and backward Euler (paper Eq. 14) solved for the velocities by Newton, for a set
// of bodies in lock-step. The scheme, the constraint handling, the warm start and the blow-up rule
// are documented on DynamicsDriver in dynamics.hpp.
#include "solve/dynamics.hpp"

#include "solve/body_scale.hpp"
#include "solve/device_slot.hpp"

#include "util/error.hpp"
#include "util/format.hpp"

#include <algorithm>
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

/// A number as a message streams it ("0.05", "2.39").
std::string num(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

}  // namespace

DynamicsDriver::DynamicsDriver(DeviceSlot& slot, const DynamicDesc& desc, const Log& log)
    : slot_(slot), desc_(desc), log_(log), store_(storeFor(slot, log)), deviceStore_(store_ != nullptr),
      storeGeneration_(slot.generation()) {
  if (!store_) store_ = createHostStepStore(slot);
  bodies_.resize(slot.bodyCount());
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    Body& b = bodies_[i];
    const Problem& p = slot.problem(i);
    b.problem = &p;
    const Eigen::Index n = p.restPositions.size();
    const BodyScale scale = bodyScale(p);
    b.diagonal = scale.diagonal;
    b.forceFloor = scale.forceFloor;
    const Eigen::VectorXd v = p.initialVelocity.size() == n ? p.initialVelocity : Eigen::VectorXd::Zero(n);
    store_->setState(i, StateSlot::Committed, StateVec::X, p.restPositions);
    store_->setState(i, StateSlot::Committed, StateVec::V, (v.array() * scale.freeMask).matrix());  // constrained dofs start at rest
    for (StateVec z : {StateVec::A, StateVec::Fext, StateVec::Reaction}) store_->setZero(i, StateSlot::Committed, z);
    capture(i, StateSlot::Previous);
  }
}

DynamicsDriver::State& DynamicsDriver::scalars(Body& b, StateSlot slot) {
  switch (slot) {
    case StateSlot::Start: return b.start;
    case StateSlot::Previous: return b.previous;
    case StateSlot::Committed: return b;
    default: fail(ErrorCode::Internal, "dynamics: no scalars for the step's result state");
  }
}

void DynamicsDriver::capture(std::size_t body, StateSlot slot) {
  Body& b = bodies_.at(body);
  scalars(b, slot) = static_cast<const State&>(b);
  store_->copy(body, StateSlot::Committed, slot);
}

void DynamicsDriver::restore(std::size_t body, StateSlot slot) {
  Body& b = bodies_.at(body);
  static_cast<State&>(b) = scalars(b, slot);
  store_->copy(body, slot, StateSlot::Committed);
  b.deviceAtCommitted = false;
}

void DynamicsDriver::restoreStart(std::size_t body) {
  Body& b = bodies_.at(body);
  if (b.startHeld)
    restore(body, StateSlot::Start);  // a substep committed: start keeps the step's start for the next attempt
  else
    b.deviceAtCommitted = false;  // nothing committed: the body's state is the step's start
}

const Eigen::VectorXd& DynamicsDriver::positions(std::size_t body) const {
  bodies_.at(body);
  return store_->state(body, StateSlot::Committed, StateVec::X);
}

const Eigen::VectorXd& DynamicsDriver::velocities(std::size_t body) const {
  bodies_.at(body);
  return store_->state(body, StateSlot::Committed, StateVec::V);
}

void DynamicsDriver::removeBody(std::size_t body) {
  bodies_.at(body);
  store_->removeBody(body);
  bodies_.erase(bodies_.begin() + static_cast<std::ptrdiff_t>(body));
}

void DynamicsDriver::setState(std::size_t body, const Eigen::VectorXd& x, const Eigen::VectorXd& v) {
  Body& b = bodies_.at(body);
  const Eigen::Index n = b.problem->restPositions.size();
  if (x.size() != n || v.size() != n)
    fail(ErrorCode::BadInput, "body '", b.problem->name, "': a state needs ", n,
         " positions and velocities (3 per node), got ", x.size(), " and ", v.size());
  if (!x.allFinite() || !v.allFinite())
    fail(ErrorCode::BadInput, "body '", b.problem->name, "': the positions or velocities are not finite; give finite "
         "numbers (m, m/s)");
  store_->setState(body, StateSlot::Committed, StateVec::X, x);
  store_->setState(body, StateSlot::Committed, StateVec::V, (v.array() * store_->freeMask(body)).matrix());
  b.started = false;  // the next step measures a and the energy budget from this state
  capture(body, StateSlot::Previous);
  b.deviceAtCommitted = false;
}

void DynamicsDriver::constraintsChanged(std::size_t body) {
  bodies_.at(body);
  store_->problemChanged(body);
  // Held dofs: their velocities follow from their targets.
  const Eigen::VectorXd v = (store_->state(body, StateSlot::Committed, StateVec::V).array() * store_->freeMask(body)).matrix();
  store_->setState(body, StateSlot::Committed, StateVec::V, v);
}

void DynamicsDriver::loadsChanged(std::size_t body) {
  bodies_.at(body);
  store_->problemChanged(body);
}

void DynamicsDriver::materialChanged(std::size_t body) {
  Body& b = bodies_.at(body);
  b.forceFloor = bodyScale(*b.problem).forceFloor;
  b.started = false;  // the elastic energy changed with the stiffness: the budget is measured again
  b.deviceAtCommitted = false;
}

void DynamicsDriver::setControls(std::size_t body, const BodyControls& c) {
  Body& b = bodies_.at(body);
  const Eigen::Index n = b.problem->restPositions.size();
  for (const Eigen::VectorXd* v : {&c.targets, &c.forces, &c.springTargets})
    if (v->size() != 0 && v->size() != n)
      fail(ErrorCode::Internal, "body '", b.problem->name, "': controls of size ", v->size(), " for ", n, " dofs");
  store_->setControls(body, c);
}

void DynamicsDriver::externalForce(std::size_t body, double t, const Eigen::VectorXd& x, Eigen::VectorXd& f) const {
  const Body& b = bodies_.at(body);
  const BodyControls& c = store_->controls(body);
  b.problem->externalForce(t, /*dynamic=*/true, f);
  if (c.forces.size() == f.size()) f += c.forces;
  // Free dofs only: on a held dof the support's reaction takes the spring's pull (the residual's
  // constrained rows hold it), and counting it as a load as well would count its work twice.
  const Eigen::VectorXd& k = b.problem->springStiffness;
  const Eigen::ArrayXd& free = store_->freeMask(body);
  if (k.size() != x.size() || c.springTargets.size() != x.size()) return;
  for (Eigen::Index d = 0; d < x.size(); ++d)
    if (k[d] != 0.0 && free[d] != 0.0) f[d] += k[d] * (c.springTargets[d] - x[d]);
}

double DynamicsDriver::kineticEnergy(std::size_t body) const {
  const Body& b = bodies_.at(body);
  const Eigen::VectorXd& m = b.problem->lumpedMass;
  const Eigen::VectorXd& v = store_->state(body, StateSlot::Committed, StateVec::V);
  if (m.size() != v.size()) return 0.0;
  return 0.5 * (m.array() * v.array().square()).sum();
}

double DynamicsDriver::elasticEnergy(std::size_t body) {
  syncDevicePositions({body});
  std::vector<double> e;
  slot_.elasticEnergy({body}, e);
  return e.at(0);
}

void DynamicsDriver::syncDevicePositions(const BodySet& set) {
  BodySet stale;
  for (std::size_t i : set)
    if (!bodies_.at(i).deviceAtCommitted) stale.push_back(i);
  if (stale.empty()) return;
  store_->setPositions(slot_, stale, StateSlot::Committed);
  for (std::size_t i : stale) bodies_[i].deviceAtCommitted = true;
}

void DynamicsDriver::start(const BodySet& set, std::vector<std::string>& failure) {
  BodySet fresh;
  for (std::size_t i : set)
    if (!bodies_[i].started) fresh.push_back(i);
  if (fresh.empty()) return;
  store_->setPositions(slot_, fresh, StateSlot::Committed);
  for (std::size_t i : fresh) bodies_[i].deviceAtCommitted = true;
  store_->internalForces(slot_, fresh);
  store_->damping(slot_, fresh, StateSlot::Committed);
  std::vector<double> energy;
  slot_.elasticEnergy(fresh, energy);
  for (std::size_t k = 0; k < fresh.size(); ++k) {
    const std::size_t i = fresh[k];
    Body& b = bodies_[i];
    const Problem& p = *b.problem;
    const Eigen::VectorXd& x = store_->state(i, StateSlot::Committed, StateVec::X);
    const Eigen::VectorXd& fint = store_->scratch(i, Scratch::Fint);
    const Eigen::VectorXd& cv = store_->scratch(i, Scratch::Cv);
    const Eigen::ArrayXd& free = store_->freeMask(i);
    const Eigen::Index size = x.size();
    Eigen::VectorXd fext;
    externalForce(i, b.t, x, fext);
    Eigen::VectorXd a = Eigen::VectorXd::Zero(size);
    for (Eigen::Index d = 0; d < size; ++d) {
      const double m = p.lumpedMass.size() == size ? p.lumpedMass[d] : 0.0;
      if (free[d] != 0.0 && m > 0.0) a[d] = (fext[d] - cv[d] - fint[d]) / m;
    }
    // Reactions of the supports at t = 0 (a = 0 on constrained dofs), and the energy at t = 0.
    const Eigen::VectorXd reaction = ((cv + fint - fext).array() * (1.0 - free)).matrix();
    const bool finite = a.allFinite();
    store_->setState(i, StateSlot::Committed, StateVec::A, a);
    store_->setState(i, StateSlot::Committed, StateVec::Fext, fext);
    store_->setState(i, StateSlot::Committed, StateVec::Reaction, reaction);
    b.initialEnergy = kineticEnergy(i) + energy[k];
    if (!finite) {
      failure[i] = "body '" + p.name +
                   "': the initial acceleration is not finite; check the material, the loads and the initial velocity";
      continue;
    }
    b.started = true;
    capture(i, StateSlot::Previous);
  }
}

std::unique_ptr<StepStore> DynamicsDriver::storeFor(DeviceSlot& slot, const Log& log) {
  try {
    return slot.device().createStepStore(slot);
  } catch (const Error& e) {
    if (e.code() != ErrorCode::DeviceError) throw;
    log(LogLevel::Warning, "the dynamics' vectors stay on the host: the device's store could not be made (", e.what(),
        ")");
    return nullptr;
  }
}

void DynamicsDriver::followDevice() {
  if (slot_.generation() == storeGeneration_) return;
  slot_.dropPositionSource(store_.get());  // the positions the old store set stay the slot's
  std::unique_ptr<StepStore> next = storeFor(slot_, log_);
  const bool onDevice = next != nullptr;
  if (!onDevice && !deviceStore_) {
    storeGeneration_ = slot_.generation();  // the host's store serves every device
    return;
  }
  if (!next) next = createHostStepStore(slot_);
  // The states the old store holds (its device object may be gone; its memory may not be), and the
  // controls; the scratch is the next step's. A store whose device was lost with them gives none:
  // its bodies start again at rest, at their rest positions.
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    Body& b = bodies_[i];
    const Problem& p = *b.problem;
    const Eigen::Index n = p.restPositions.size();
    try {
      for (StateSlot s : {StateSlot::Committed, StateSlot::Start, StateSlot::Previous})
        for (StateVec v : {StateVec::X, StateVec::V, StateVec::A, StateVec::Fext, StateVec::Reaction})
          if (const Eigen::VectorXd& value = store_->state(i, s, v); value.size() == n) next->setState(i, s, v, value);
    } catch (const Error& e) {
      if (e.code() != ErrorCode::DeviceError) throw;
      log_(LogLevel::Warning, "body '", p.name, "': its state was lost with its device (", e.what(),
           "); it starts again at rest");
      next->setState(i, StateSlot::Committed, StateVec::X, p.restPositions);
      for (StateVec z : {StateVec::V, StateVec::A, StateVec::Fext, StateVec::Reaction})
        next->setZero(i, StateSlot::Committed, z);
      next->copy(i, StateSlot::Committed, StateSlot::Previous);
      b.started = false;  // its acceleration and energy budget are measured again
      b.deviceAtCommitted = false;
    }
    next->setControls(i, store_->controls(i));
  }
  store_ = std::move(next);
  deviceStore_ = onDevice;
  storeGeneration_ = slot_.generation();
  for (Body& b : bodies_) b.deviceAtCommitted = false;  // the new device may hold no positions of a body
}

std::vector<BodyOutcome> DynamicsDriver::step(const BodySet& set, const StepCall& call) {
  std::vector<BodyOutcome> out(set.size());
  std::vector<std::string> startFailure(bodies_.size());
  try {
    followDevice();
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
      out[i].error = std::current_exception();
      try {
        restoreStart(set[i]);
      } catch (const Error& e) {
        // A store lost with its device: the next step moves the bodies off it (followDevice).
        if (e.code() != ErrorCode::DeviceError) throw;
      }
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
          restoreStart(set[i]);
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
      store_->swap(set[i], StateSlot::Previous, StateSlot::Start);
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
  {
    BodySet all;
    std::vector<BeginArgs> args(adv.size());
    for (std::size_t j = 0; j < adv.size(); ++j) {
      Advance& a = adv[j];
      const Body& b = bodies_[a.body];
      SchemeMaps& m = a.maps;
      m.h = a.t1 - b.t;
      m.newmark = integratorOf(desc_) == Integrator::Newmark;
      if (m.newmark) {
        const double beta = desc_.newmarkBeta, gamma = desc_.newmarkGamma;
        m.ka = 1.0 / (m.h * gamma);
        m.kx = m.h * beta / gamma;
        m.cv = m.h * (1.0 - gamma);
        m.ca = m.h * m.h * (0.5 - beta);
      } else {
        m.ka = 1.0 / m.h;
        m.kx = m.h;
      }
      all.push_back(a.body);
      args[j] = BeginArgs{m, a.t1, a.fraction, b.startHeld ? StateSlot::Start : StateSlot::Committed};
    }
    store_->begin(all, args);
  }

  const int maxIterations = std::max(1, desc_.newtonIterations);
  for (int iteration = 0;; ++iteration) {
    std::vector<std::size_t> live;  // indices into adv
    for (std::size_t j = 0; j < adv.size(); ++j)
      if (adv[j].running) live.push_back(j);
    if (live.empty()) break;
    BodySet set, damped;
    std::vector<SchemeMaps> maps;
    for (std::size_t j : live) {
      set.push_back(adv[j].body);
      maps.push_back(adv[j].maps);
      const Problem& p = *bodies_[adv[j].body].problem;
      if (p.rayleighMass != 0.0 || p.rayleighStiffness != 0.0) damped.push_back(adv[j].body);
    }
    store_->positions(set, maps);
    const auto evaluate = [&](const BodySet& bodies, const BodySet& dampedBodies) {
      store_->setPositions(slot_, bodies, StateSlot::Result);
      for (std::size_t i : bodies) bodies_[i].deviceAtCommitted = false;
      store_->internalForces(slot_, bodies);
      if (!dampedBodies.empty()) store_->damping(slot_, dampedBodies, StateSlot::Result);
    };
    try {
      evaluate(set, damped);
    } catch (const Error& e) {
      if (e.code() == ErrorCode::DeviceError) throw;  // every device of the slot failed: the step fails
      // A body's own failure (a device that refuses its state) failed the whole call: each body
      // alone finds whose, and the others carry on with the same bits.
      for (std::size_t j : live) {
        const std::size_t body = adv[j].body;
        const bool isDamped = std::find(damped.begin(), damped.end(), body) != damped.end();
        try {
          if (live.size() > 1) evaluate({body}, isDamped ? BodySet{body} : BodySet{});
          else failHere(adv[j], std::string("failed: ") + e.what());
        } catch (const Error& alone) {
          if (alone.code() == ErrorCode::DeviceError) throw;
          failHere(adv[j], std::string("failed: ") + alone.what());
        }
      }
      std::vector<std::size_t> still;
      set.clear();
      maps.clear();
      for (std::size_t j : live)
        if (adv[j].running) {
          still.push_back(j);
          set.push_back(adv[j].body);
          maps.push_back(adv[j].maps);
        }
      live = std::move(still);
      if (live.empty()) break;
    }
    // r = M a + C v + f_int - f_ext, the free norms of its terms and of r, and whether x, v and a
    // are finite, in one pass over the body's vectors.
    std::vector<ResidualSums> sums;
    store_->residual(set, maps, sums);
    for (std::size_t k = 0; k < live.size(); ++k) {
      Advance& a = adv[live[k]];
      const Body& b = bodies_[a.body];
      const ResidualSums& s = sums[k];
      const double scale = std::max({std::sqrt(s.ma), std::sqrt(s.cv), std::sqrt(s.fint), std::sqrt(s.spring),
                                     std::sqrt(s.fext), b.forceFloor});
      a.residualNorm = std::sqrt(s.r);
      const double relative = a.residualNorm / scale;
      if (!std::isfinite(relative) || s.nonFinite != 0.0) {
        failHere(a, "produced non-finite forces, velocities or positions");
        continue;
      }
      if (iteration == 0) {
        a.initialRelative = relative;
        a.initialNorm = a.residualNorm;
      }
      a.stats.residual = relative;
      a.evaluated = true;
      if (relative <= desc_.newtonTolerance || iteration == maxIterations) a.running = false;
    }

    // Newton update: A dv = -r / ka with A = M + (1/ka) C + (kx/ka) K_t, starting at dv = 0 (the
    // previous velocities on the first iteration, the current iterate after).
    std::vector<std::size_t> solving;
    for (std::size_t j : live)
      if (adv[j].running) solving.push_back(j);
    if (solving.empty()) break;
    BodySet solveSet;
    std::vector<PcgSolve> solves(solving.size());
    for (std::size_t k = 0; k < solving.size(); ++k) {
      const Advance& a = adv[solving[k]];
      solveSet.push_back(a.body);
      solves[k].coeffs = SystemCoeffs{1.0, 1.0 / a.maps.ka, a.maps.kx / a.maps.ka};
    }
    try {
      store_->solve(slot_, solveSet, solves);
    } catch (const Error& e) {
      if (e.code() == ErrorCode::DeviceError) throw;  // every device of the slot failed: the step fails
      // As above: each body's solve alone, a body whose own solve throws failing with its error.
      for (std::size_t k = 0; k < solving.size(); ++k) {
        std::vector<PcgSolve> one(1);
        one[0].coeffs = solves[k].coeffs;
        try {
          if (solving.size() > 1) store_->solve(slot_, {solveSet[k]}, one);
          else one[0].failure = e.what();
        } catch (const Error& alone) {
          if (alone.code() == ErrorCode::DeviceError) throw;
          one[0].failure = alone.what();
        }
        solves[k] = std::move(one[0]);
      }
    }
    BodySet updateSet;
    std::vector<std::size_t> updating;  // indices into adv
    for (std::size_t k = 0; k < solving.size(); ++k) {
      Advance& a = adv[solving[k]];
      if (!solves[k].failure.empty()) {
        failHere(a, "failed in the linear solve: " + solves[k].failure);
        continue;
      }
      const LinearSolveStats& ls = solves[k].stats;
      a.stats.newtonIterations += 1;
      a.stats.linearIterations += ls.iterations;
      a.stats.linearResidual = std::max(a.stats.linearResidual, ls.relativeResidual);
      a.allLinearConverged = a.allLinearConverged && ls.converged;
      updateSet.push_back(a.body);
      updating.push_back(solving[k]);
    }
    // v += dv, counting non-finite entries of dv (a failed body's v is scratch).
    std::vector<double> bad;
    store_->update(updateSet, bad);
    for (std::size_t k = 0; k < updating.size(); ++k) {
      Advance& a = adv[updating[k]];
      if (bad[k] != 0.0) {
        failHere(a, "produced non-finite velocities");
        continue;
      }
      a.evaluated = false;  // the loop evaluates the new v before it ends
    }
  }

  // The loop ends for a body only right after evaluating its v: x and a are that evaluation's, and
  // x, v and a were checked there. Growth is judged on the absolute residual: the relative one is
  // bounded by the number of terms when f_int dominates, exactly as it does in a blow-up.
  std::vector<std::size_t> ok;
  for (std::size_t j = 0; j < adv.size(); ++j) {
    Advance& a = adv[j];
    if (!a.failure.empty()) continue;
    const Body& b = bodies_[a.body];
    log_(LogLevel::Debug, "body '", b.problem->name, "': ", a.where, ": ", a.stats.newtonIterations,
         " Newton iterations, relative residual ", sci(a.initialRelative), " -> ", sci(a.stats.residual));
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
  for (std::size_t j : ok) {
    energySet.push_back(adv[j].body);
    if (!adv[j].evaluated) reset.push_back(adv[j].body);
  }
  std::vector<double> elastic;
  try {
    if (!reset.empty()) store_->setPositions(slot_, reset, StateSlot::Result);
    slot_.elasticEnergy(energySet, elastic);
  } catch (const Error& e) {
    if (e.code() == ErrorCode::DeviceError) throw;  // every device of the slot failed: the step fails
    for (std::size_t j : ok) failHere(adv[j], std::string("failed: ") + e.what());
    return;
  }
  // One pass: the reactions (the constrained rows of the last residual, evaluated at the final v,
  // or at the predictor when Newton stopped there); the springs' pull on free dofs joins f_ext (a
  // load from here: its work, and f_n of the next step; on a held dof the reaction takes it); and
  // the loads' and supports' work over dx = x_{n+1} - x_n, and m v^2 (EndSums).
  std::vector<EndSums> sums;
  store_->end(energySet, sums);
  const std::string runawayFix =
      "use more analysis.newton_iterations (with analysis.newton_tolerance), a smaller analysis.time_step, "
      "a dissipative scheme (analysis.integrator \"backward_euler\", or analysis.newmark_gamma 0.6 with "
      "newmark_beta 0.3025), or a tighter solver.tolerance / more solver.max_iterations" + retryFix;
  for (std::size_t k = 0; k < ok.size(); ++k) {
    Advance& a = adv[ok[k]];
    Body& b = bodies_[a.body];
    const EndSums& s = sums[k];
    const double supportWork = b.supportWork + 0.5 * s[0];
    const double loadWork = b.work + 0.5 * s[1];
    const double g = integratorOf(desc_) == Integrator::Newmark ? desc_.newmarkGamma : 1.0;
    const double supportWorkScheme = b.supportWorkScheme + (1.0 - g) * s[2] + g * s[3];
    const double loadWorkScheme = b.loadWorkScheme + (1.0 - g) * s[4] + g * s[5];
    const double kinetic = 0.5 * s[6];
    const double given = b.initialEnergy + std::max(std::abs(loadWork) + std::abs(supportWork),
                                                    std::abs(loadWorkScheme) + std::abs(supportWorkScheme));
    b.deviceAtCommitted = false;  // the device holds the result's x now: committed below, or the step fails
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
    // Commit: the result swapped in. The state before the step goes to Start where Start does not
    // hold it yet (the step's first commit); else the next step overwrites it as its result.
    b.work = loadWork;  // trapezoidal rule in time
    b.supportWork = supportWork;
    b.supportWorkScheme = supportWorkScheme;
    b.loadWorkScheme = loadWorkScheme;
    store_->swap(a.body, StateSlot::Committed, StateSlot::Result);
    if (!b.startHeld) {
      store_->swap(a.body, StateSlot::Start, StateSlot::Result);
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
  capture(body, StateSlot::Start);
  b.t = b.start.t + h;
  store_->setZero(body, StateSlot::Committed, StateVec::V);
  store_->setZero(body, StateSlot::Committed, StateVec::A);
  Eigen::VectorXd fext;
  externalForce(body, b.t, store_->state(body, StateSlot::Committed, StateVec::X), fext);
  store_->setState(body, StateSlot::Committed, StateVec::Fext, fext);
  std::swap(b.previous, b.start);
  store_->swap(body, StateSlot::Previous, StateSlot::Start);
}

void DynamicsDriver::rollback(std::size_t body) {
  bodies_.at(body);
  restore(body, StateSlot::Previous);
}

}  // namespace corofem::detail
