// Backend-independent drivers of one body: Newton-Raphson statics (paper Eqs. 12-13) and implicit
// time integration solved for velocities (paper Eq. 14). They own the body's state (positions,
// velocities, accelerations, external work) and drive a Backend through its small interface; they
// never see how the backend stores or solves anything.
//
// Failure contract: a step that fails throws Error(SolveFailed) naming the body, the step and a fix,
// and leaves the driver (and the backend's positions) at the state before the step. The previous
// committed state of a step that succeeded can be restored with rollback(), so that a scene with
// several bodies keeps all of them at the last step every body completed.
#pragma once

#include "model/problem.hpp"
#include "solve/backend.hpp"
#include "util/log.hpp"

#include <corofem/scene.hpp>

#include <Eigen/Core>

#include <memory>
#include <string>

namespace corofem::detail {

/// What one body did in one step or increment.
struct BodyStepStats {
  int newtonIterations = 0;     ///< linear solves done (statics and dynamics)
  int linearIterations = 0;     ///< PCG iterations summed over the Newton iterations
  double residual = 0.0;        ///< final relative Newton residual (see each driver for the scale)
  double linearResidual = 0.0;  ///< largest relative residual of the linear solves
  bool converged = true;        ///< statics: Newton converged; dynamics: every linear solve converged
  int substeps = 1;             ///< dynamics: substeps the step finally took (> 1 after a retry)
};

/// Common interface of the per-body drivers.
class BodySolver {
 public:
  virtual ~BodySolver() = default;

  /// Advances to step / increment `index` (1-based) of `count`. Throws Error(SolveFailed) with the
  /// state unchanged when the step fails.
  virtual BodyStepStats step(int index, int count) = 0;
  /// Restores the state before the last successful step() (one level).
  virtual void rollback() = 0;
  /// Replaces the starting state before the first step (tests and embedders: a body released from
  /// a squashed or inverted shape). x and v are 3N; constrained dofs of x should sit at their
  /// targets at t = 0 and their velocities are zeroed. Dynamics measure the body's initial energy
  /// (the runaway guard's budget) from this state. Throws Error(BadInput) for a wrong size or a
  /// non-finite entry.
  void setInitialState(const Eigen::VectorXd& x, const Eigen::VectorXd& v);

  const Eigen::VectorXd& positions() const { return x_; }
  const Eigen::VectorXd& velocities() const { return v_; }
  double externalWork() const { return work_; }
  /// 1/2 v^T M v with the lumped mass (every dof, constrained ones included).
  double kineticEnergy() const;
  /// Strain energy at the current positions (refreshes the backend's positions when needed).
  double elasticEnergy();
  /// Makes the backend's positions the committed ones (a driver may have evaluated trial positions
  /// last): then the backend's device buffers describe positions(). No-op when they already do.
  void syncBackendPositions();

 protected:
  BodySolver(const Problem& problem, Backend& backend, const Log& log);

  /// Euclidean norm over the free dofs.
  double freeNorm(const Eigen::VectorXd& v) const;
  /// True when every entry is finite.
  static bool allFinite(const Eigen::VectorXd& v);
  /// Sets the backend's positions to x and remembers whether they are the committed ones.
  void setBackendPositions(const Eigen::VectorXd& x, bool committed);

  const Problem& problem_;
  Backend& backend_;
  const Log& log_;  ///< the Simulation's (debug: per-iteration residuals, substep retries)
  Eigen::ArrayXd freeMask_;   ///< 1 on free dofs, 0 on constrained ones
  double diagonal_ = 1.0;     ///< rest bounding-box diagonal (m), the body's length scale
  /// Force below which a residual counts as zero: the force that strains the whole body by 1e-8,
  /// (lambda + 2 mu) * diagonal^2 * 1e-8 (N). It keeps an unloaded body, whose internal forces
  /// are pure rounding, from failing a purely relative test.
  double forceFloor_ = 0.0;

  Eigen::VectorXd x_, v_, a_;           ///< committed state
  Eigen::VectorXd xPrev_, vPrev_, aPrev_;
  double work_ = 0.0, workPrev_ = 0.0;  ///< external work since the start (trapezoidal rule)
  bool backendAtCommitted_ = false;     ///< the backend's positions equal x_
};

/// Newton-Raphson statics, Eqs. 12-13: r(x) = f_int(x) - lambda f_ext = 0 with K_t dx = -r on the
/// free dofs. Increment k of n uses lambda = k / n; prescribed displacements (scaled by lambda) are
/// written into x before the increment's iterations, and the free dofs start from a linear
/// extrapolation of the last increment (from the last converged state on the first increment).
///
/// Convergence at iterate x_i (after i linear solves, i >= 0), with norms over the free dofs:
///   residual      |r_i| <= residualTolerance * max(|lambda f_ext|, |f_int(x_i)|, forceFloor)
///   displacement  |dx_{i-1}| <= displacementTolerance * max(|x_i - X|, 1e-12 * diag * sqrt(free dofs))
/// Both must hold, except that a residual below min(1e-8, 1e-2 * residualTolerance) times the same
/// scale accepts the increment alone (Abaqus' "linear increment" rule): the last correction was then
/// exact to rounding, so a linear problem solved directly converges in one iteration instead of
/// paying a second solve only to measure a zero correction.
///
/// Why more than plain Eq. 13: the co-rotational tangent K_t = sum R K R^T leaves out the change of
/// R with x. For a slender cantilever under a dead tip load that missing term is of the order of
/// alpha = P L^2 / EI times the bending stiffness, and the plain iteration x += -K_t^-1 r contracts
/// only slowly from alpha ~ 1 and stalls beyond alpha ~ 2 (measured: relative residual still 3e-2
/// after 60 iterations at alpha = 3). Each iteration therefore (1) corrects the direction with
/// L-BFGS secant pairs (8 kept, K_t^-1 as the initial inverse Hessian: without history, i.e. in the
/// first iteration and for linear problems, this is exactly Eq. 13), and (2) takes a line search on
/// the potential energy (residual = energy gradient) using directional derivatives only. Each
/// iteration still costs one K_t solve; the line search adds force evaluations only when it
/// shortens a step.
///
/// Automatic cut-back: when Newton does not converge within maxNewtonIterations (or meets a
/// non-finite value), the increment is retried from the last converged state in halves, down to
/// 1/16 of it, and the sub-increment grows back after two successes (Abaqus-style automatic
/// incrementation inside the user's increment). Every step() still ends at lambda = k / n; the
/// report sums the Newton iterations of all attempts. Only when even 1/16 fails does the step throw.
/// Every iteration's residual and step length go to the log at LogLevel::Debug.
class StaticSolver final : public BodySolver {
 public:
  StaticSolver(const Problem& problem, Backend& backend, const StaticDesc& desc, const Log& log = Log::none());
  BodyStepStats step(int increment, int incrementCount) override;
  void rollback() override;

 private:
  /// Outcome of one Newton solve at a fixed load factor.
  struct NewtonOutcome {
    bool converged = false;
    double relative = 0;     ///< final relative residual
    double correction = 0;   ///< last |dx| over the displacement scale
    std::string failure;     ///< why it stopped, when not converged
  };
  /// Newton at load factor lambda from the starting guess x (prescribed values written), x left at
  /// the last iterate. Throws only for backend errors other than SolveFailed.
  NewtonOutcome newton(double lambda, const Eigen::VectorXd& fext, Eigen::VectorXd& x, BodyStepStats& stats);

  /// Converged state beyond the base class's x_ / work_: load factor, f_ext at it, and the converged
  /// state before it (for the predictor's extrapolation).
  struct Track {
    double lambda = 0.0;
    Eigen::VectorXd fext;
    Eigen::VectorXd xBack;
    double lambdaBack = 0.0;
    bool haveBack = false;
  };

  StaticDesc desc_;
  Track track_, trackSaved_;
};

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
/// blow-up detection below, and leaves the backend at the committed positions for energies()).
/// A step whose residual is already below newtonTolerance at the predictor takes no solve at all.
///
/// Blow-up detection (the step then throws SolveFailed and the state stays at t_n):
///   - any non-finite force, velocity or position;
///   - a linear solve that did not converge together with a residual norm that grew during the
///     step and a relative residual above 1e-3;
///   - a runaway: mechanical energy above 1.25 times the energy the body was ever given,
///     KE_{n+1} + U_{n+1} > 1.25 (KE_0 + U_0 + |W_loads| + |W_supports|) (+ a rounding floor).
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
class DynamicSolver final : public BodySolver {
 public:
  DynamicSolver(const Problem& problem, Backend& backend, const DynamicDesc& desc, const Log& log = Log::none());
  BodyStepStats step(int index, int count) override;
  void rollback() override;
  double time() const { return t_; }
  /// Step `index` of a sleeping body (analysis.sleep, decided by the Simulation): no solve; the
  /// time advances by one step, the positions stay, velocities and accelerations become zero (the
  /// body was below the sleep speed), f_ext moves to the new time (the loads do no work: nothing
  /// moves). Keeps the rollback copy like step(). Returns zero iterations.
  BodyStepStats idleStep(int index, int count);

 private:
  /// Everything a step changes (the committed state of the base class plus the integrator's).
  struct State {
    Eigen::VectorXd x, v, a, fextPrev, reactionPrev;
    double work = 0.0, t = 0.0, supportWork = 0.0;
  };
  /// The committed state into `s` (assigned in place: no allocation once sized).
  void capture(State& s) const;
  void restore(const State& s);
  /// Makes `s` (the state before a step) what rollback() returns to; its vectors are swapped, not
  /// copied (a step of a 10k-element body copied 5 vectors of 3N doubles here), and `s` gets the
  /// old rollback copy's, which the next capture overwrites.
  void keepForRollback(State& s);

  /// The damping force C v, C = alpha M + beta K^R (Rayleigh). Mass damping alone (beta = 0, the
  /// common "air drag") is a scaling of the lumped mass: formed here in double, the same expression
  /// and bits as the reference backend's apply, with no backend call. On the OpenCL backend that
  /// call was an upload, an element product, a gather and a blocking read per force evaluation
  /// (twice per step with one Newton iteration); in a batch, a rendezvous round of every body each
  /// time. beta > 0 needs K^R: the backend applies it.
  void dampingForce(const Eigen::VectorXd& v, Eigen::VectorXd& cv);
  /// a_0 from M a_0 = f_ext(0) - C v_0 - f_int(x_0) on the free dofs (0 on constrained ones).
  void initialAcceleration();
  /// One step of the scheme from the committed state to t1 = t_ + h, committed in place (no
  /// rollback copy). `where` names the step in messages ("time step 3/10", "..., substep 2/4").
  /// Throws Error(SolveFailed) with the committed state unchanged when it fails.
  BodyStepStats advance(double h, const std::string& where);

  DynamicDesc desc_;
  /// Scratch of step() (the state before the step) and advance() (the scheme's vectors), kept from
  /// step to step so that a step allocates no vector once the first has sized them: in a batch of
  /// 100 bodies on 2 cores, malloc, free and the page faults of fresh memory were about 5 % of a
  /// step's samples, all in the bodies' host work while the device waits for their next calls.
  State start_;
  struct Scratch {
    Eigen::VectorXd vb, xb, target, fext, v, x, a, fint, cv, r, dv, rhs, reaction;
  } w_;
  double t_ = 0.0, tPrev_ = 0.0;
  bool started_ = false;
  Eigen::VectorXd fextPrev_, fextPrevSaved_;  ///< f_ext(t_n) for the trapezoidal external work
  /// Runaway guard: kinetic + elastic energy at t = 0, work of the supports (reactions on the
  /// constrained dofs, trapezoidal rule; only prescribed dofs move), and the reactions at t_n.
  double initialEnergy_ = 0.0;
  double supportWork_ = 0.0, supportWorkSaved_ = 0.0;
  Eigen::VectorXd reactionPrev_, reactionPrevSaved_;
};

/// Creates the driver the analysis asks for.
/// Creates the driver the analysis asks for; `log` must outlive it.
std::unique_ptr<BodySolver> createBodySolver(const Problem& problem, Backend& backend,
                                             const AnalysisDesc& analysis, const Log& log = Log::none());

}  // namespace corofem::detail
