// Implicit dynamics of a set of bodies in lock-step (paper Eq. 14): every Newton iteration of every
// body still in the step is one device call for all of them (positions, forces, the damping
// product, the linear solves through solvePcg, the energies), the per-dof passes between them are
// the step store's (solve/step_store.hpp: the vectors stay where the store keeps them, the driver
// reads their sums), and a body that has converged, failed or finished its step costs nothing
// more. A body that fails is retried in substeps while the others wait. Each body's sequence of
// device calls is the one it would make alone, so batching changes no answer.
#pragma once

#include "solve/driver.hpp"
#include "solve/step_store.hpp"

#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

/// Implicit time integration of Eq. 14, M a + C v + f_int(x) = f_ext(t), solved for the velocities
/// v_{n+1} by Newton. Both schemes write x and a as affine functions of v:
///   a(v) = ka (v - vb),  x(v) = xb + kx v
///   Newmark:        ka = 1/(h gamma), vb = v_n + h (1 - gamma) a_n, kx = h beta / gamma,
///                   xb = x_n + h v_n + h^2 (1/2 - beta) a_n - kx vb
///   backward Euler: ka = 1/h, vb = v_n, kx = h, xb = x_n
/// The residual r(v) = M a(v) + C v + f_int(x(v)) - f_ext(t_{n+1}) has the Jacobian
/// ka M + C + kx K_t; times 1/ka this is A = M + (1/ka) C + (kx/ka) K_t, i.e. Newmark
/// M + h gamma C + h^2 beta K_t and backward Euler M + h C + h^2 K_t, so each iteration solves
/// A dv = -r / ka (SystemCoeffs{1, 1/ka, kx/ka}). C = alpha M + beta K_t at the current positions.
/// An application's springs (spring handles: Problem::springStiffness S, setControls' targets t)
/// add S (x - t) to r and kx S to its Jacobian: the device's A carries (kx/ka) S with K_t. Their
/// force counts as a load (its work, the runaway guard's budget): a target the application drags
/// gives the body energy as a moving support does.
///
/// Constrained dofs: v is chosen so that x(v) lands on the target at t_{n+1} (rest position for
/// fixed dofs, X + ramp * value for prescribed ones): v = (x_target - xb) / kx. The linear solves
/// leave them alone (dv = 0 there).
///
/// Warm start, as the paper's Sec. 3: Newton starts at v = v_n and the first linear solve starts at
/// dv = 0, which is exactly the paper's "previous velocities as the PCG starting vector" for the
/// system written in v. Later Newton iterations start at dv = 0 too (corrections are small).
/// Measured alternative: starting the first solve at dv = h a_n saved ~1 % of the PCG iterations on
/// the bar meshes (bench_reference), not enough to depart from the paper's choice.
///
/// Relative residual: |r| / max(|M a|, |C v|, |f_int|, |f_ext|, forceFloor) on the free dofs. It is
/// evaluated at the start of every Newton iteration and once more after the last one (also for
/// newtonIterations == 1, the paper's linearised step: one extra force evaluation per step buys the
/// blow-up detection below, and leaves the device at the committed positions for energies()).
/// A step whose residual is already below newtonTolerance at the predictor takes no solve at all.
///
/// Blow-up detection (the step then throws SolveFailed and the state stays at t_n):
///   - any non-finite force, velocity or position;
///   - a linear solve that did not converge together with a residual norm that grew during the
///     step and a relative residual above 1e-3;
///   - a runaway: mechanical energy above 1.25 times the energy the body was ever given,
///     KE_{n+1} + U_{n+1} > 1.25 (KE_0 + U_0 + |W_loads| + |W_supports|) (+ a rounding floor),
///     each W summed step by step by the trapezoidal rule or, where larger, with the scheme's own
///     weights of the step's end forces (backward Euler: the end force; see State).
///     A stable scheme keeps KE + U <= KE_0 + U_0 + W (damping and numerical dissipation only
///     remove energy); the linearised trapezoidal step (gamma = 1/2, one Newton iteration) on a
///     co-rotational body does not: on the Fig. 8 beam (h = 0.01 s) it settles, then gains energy
///     until the motion explodes (to 1e37 m by step 600 without this check). Converged Newton
///     (newtonIterations >= 2 with a tolerance), backward Euler or gamma >= 0.55 stay stable there.
///     Costs one elastic-energy evaluation per step. A large residual alone is not a failure:
///     backward Euler with one Newton iteration runs stably with relative residuals near 1 when
///     a handle is dragged fast.
///
/// Substep retry (DynamicDesc::maxSubsteps, default 1 = off): a step that fails in any of the ways
/// above is retried from t_n as k = 2, 4, 8, ... substeps of h / k (each a full step of the same
/// scheme, with loads and prescribed targets at the substep's end time) while k <= maxSubsteps.
/// Why it helps: the failures above are truncation-error failures of a too-large step (the
/// linearised step's chord error grows like (omega h)^2 for a rotation omega h per step, the
/// energy drift of the linearised trapezoidal rule likewise), so a smaller step removes them; a
/// genuinely non-finite problem (NaN material) fails at every k and still throws, after
/// log2(maxSubsteps) + 1 attempts. The reported stats sum the Newton and PCG iterations of every
/// attempt (the cost really paid) and give the substeps of the attempt that succeeded.
/// Substeps cure isolated violent steps (a fast drag: tests/extremes/test_failure_policy.cpp), not a
/// step too large for the scheme everywhere: the steps that still pass keep feeding energy in until
/// the 1.25x budget is spent, and then even small substeps fail (tests/extremes/test_ranges.cpp).
///
/// Rigid rotation (measured, tests/extremes/test_spin.cpp): average-acceleration Newmark is not
/// energy-conserving for a rotating co-rotational body (the trapezoidal rule conserves energy only
/// for linear systems; its linear-in-v update moves nodes along chords, stretching the body a
/// little each step). A free cube spun at 10 rad/s (omega h = 0.167 rad per step at 60 Hz) runs
/// away at step ~376 with the linearised step and at ~116 with converged Newton; at 240 Hz (0.042
/// rad per step) it keeps KE within 0.2 % over 1000 steps. Backward Euler stays bounded at 60 Hz
/// but dissipates the spin itself (KE down to 1.8 % after 1000 steps).
class DynamicsDriver final : public Driver {
 public:
  DynamicsDriver(DeviceSlot& slot, const DynamicDesc& desc, const Log& log = Log::none());
  std::vector<BodyOutcome> step(const BodySet& bodies, const StepCall& call) override;
  void idleStep(std::size_t body, double h) override;
  void rollback(std::size_t body) override;
  void setState(std::size_t body, const Eigen::VectorXd& x, const Eigen::VectorXd& v) override;
  void constraintsChanged(std::size_t body) override;
  void loadsChanged(std::size_t body) override;
  void materialChanged(std::size_t body) override;
  void setControls(std::size_t body, const BodyControls& controls) override;
  void removeBody(std::size_t body) override;
  const Eigen::VectorXd& positions(std::size_t body) const override;
  const Eigen::VectorXd& velocities(std::size_t body) const override;
  double externalWork(std::size_t body) const override { return bodies_.at(body).work; }
  double kineticEnergy(std::size_t body) const override;
  double elasticEnergy(std::size_t body) override;
  void syncDevicePositions(const BodySet& bodies) override;
  /// The body's simulated time (s).
  double time(std::size_t body) const { return bodies_.at(body).t; }

 private:
  /// The scalars of a state of a body; its vectors are the store's (StateSlot): a state is made of
  /// both.
  struct State {
    double work = 0.0, t = 0.0, supportWork = 0.0;
    /// The loads' and supports' work as the scheme weighs the step's end forces, for the runaway
    /// guard: ((1 - g) F_n + g F_{n+1}) . dx with g = gamma (Newmark; 1/2: the trapezoidal rule)
    /// or 1 (backward Euler, whose implicit step does the work F_{n+1} dx: an abruptly dragged
    /// handle does twice what the trapezoidal rule counts when F_n was 0).
    double loadWorkScheme = 0.0, supportWorkScheme = 0.0;
    void copyScalars(const State& o) { *this = o; }
  };
  /// One body: its constants and the scalars of its committed state (the fields of State), of the
  /// step's start and of the state before its last step (rollback); the vectors of all three, and
  /// the step's scratch, are the store's.
  struct Body : State {
    const Problem* problem = nullptr;
    double diagonal = 1.0;      ///< rest bounding-box diagonal (m), the body's length scale
    /// Force below which a residual counts as zero: (lambda + 2 mu) diagonal^2 1e-8 (N).
    double forceFloor = 0.0;
    /// Kinetic + elastic energy at t = 0 (the runaway guard's budget).
    double initialEnergy = 0.0;
    bool started = false;
    bool deviceAtCommitted = false;  ///< the device's positions equal x
    /// The state before the step in progress (StateSlot::Start): its scalars from the step's start,
    /// its vectors swapped there by the step's first commit, startHeld telling which: until then
    /// the body's committed state is that state, as nothing but a commit changes it.
    State start;
    bool startHeld = false;
    State previous;  ///< the state before the last successful step (StateSlot::Previous)
  };
  /// One body's part of one advance (a step, or a substep of one).
  struct Advance {
    std::size_t body = 0;
    double t1 = 0.0;
    /// How far through the whole step t1 is (1 but in substeps): the application's held targets
    /// are reached in proportion, as the scene's prescribed ones follow their time.
    double fraction = 1.0;
    std::string where;  ///< "time step 3/10", "time step 3/10, substep 2/4"
    SchemeMaps maps;
    double initialRelative = 0.0, initialNorm = 0.0, residualNorm = 0.0;
    bool allLinearConverged = true, evaluated = false, running = true;
    BodyStepStats stats;
    std::string failure;  ///< empty, or the SolveFailed message
  };

  /// The body's scalars of state `slot` (Committed: the body's own).
  State& scalars(Body& b, StateSlot slot);
  /// State `slot` made a copy of the committed one (scalars and vectors).
  void capture(std::size_t body, StateSlot slot);
  /// The committed state made a copy of state `slot`.
  void restore(std::size_t body, StateSlot slot);
  /// Back to the state before the step in progress (start and startHeld).
  void restoreStart(std::size_t body);
  /// a_0 from M a_0 = f_ext(0) - C v_0 - f_int(x_0) on the free dofs, and the energy at t = 0, for
  /// the bodies of `set` not started yet; a body whose a_0 is not finite fails.
  void start(const BodySet& set, std::vector<std::string>& failure);
  /// After the slot made another device (a failover, a removed body): the bodies' states move to
  /// the new device's store, or to the host's from a device's.
  void followDevice();
  /// The slot's device's store, or null for the host's (also where the device's cannot be made).
  static std::unique_ptr<StepStore> storeFor(DeviceSlot& slot, const Log& log);
  /// Per body of a step's set: its stats (every attempt's iterations, the successful attempt's
  /// residuals and substeps), the substep counts tried, the last failure, and the bodies still to
  /// succeed (indices into the set).
  struct Attempts {
    explicit Attempts(std::size_t n) : total(n), tried(n), lastFailure(n) {}
    std::vector<BodyStepStats> total;
    std::vector<std::string> tried, lastFailure;
    std::vector<std::size_t> pending;
  };
  /// The step's attempts with 1, 2, 4... substeps up to analysis.max_substeps, each body retried
  /// as long as it fails; throws what is not a solve failure (a DeviceError when every device
  /// failed), leaving the pending bodies for the caller to restore.
  void runAttempts(const BodySet& set, const std::string& where, double h, Attempts& at, std::vector<BodyOutcome>& out);
  /// f_ext of a body at time t and positions x: the scene's loads, the application's forces, and
  /// its springs' pull k_d (target_d - x_d) on free dofs, into f.
  void externalForce(std::size_t body, double t, const Eigen::VectorXd& x, Eigen::VectorXd& f) const;
  /// One step of the scheme for every Advance, from its body's committed state to t1 = t + h,
  /// committed in place on success (no rollback copy); a failure leaves the body's committed state
  /// as it was and says why in Advance::failure.
  void advance(std::vector<Advance>& adv);
  /// The message of a failed advance.
  std::string failureText(const Advance& a, const std::string& what, const std::string& fix) const;

  DeviceSlot& slot_;
  DynamicDesc desc_;
  const Log& log_;
  std::vector<Body> bodies_;
  std::unique_ptr<StepStore> store_;  ///< the bodies' vectors
  bool deviceStore_ = false;          ///< store_ is a device's (Device::createStepStore), not the host's
  std::size_t storeGeneration_ = 0;   ///< the slot's generation store_ was made for
};

}  // namespace corofem::detail
