// Newton-Raphson statics of one body (paper Eqs. 12-13) over its view of a device (BodyView):
// the body's state (positions, external work) and the increments' logic. Statics run one body at a
// time (StaticsDriver, solve/driver.hpp); the dynamics of a set of bodies in lock-step are
// solve/dynamics.hpp's.
//
// Failure contract: a step that fails throws Error(SolveFailed) naming the body, the step and a fix,
// and leaves the driver (and the device's positions) at the state before the step. The previous
// committed state of a step that succeeded can be restored with rollback(), so that a scene with
// several bodies keeps all of them at the last step every body completed.
#pragma once

#include "model/problem.hpp"
#include "solve/device_slot.hpp"
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

/// One body of a DeviceSlot seen alone: its calls are the slot's for the set of that one body.
class BodyView {
 public:
  BodyView(DeviceSlot& slot, std::size_t body) : slot_(&slot), body_(body) {}
  void setPositions(const Eigen::VectorXd& x) { slot_->setPositions({body_}, {&x}); }
  void internalForces(Eigen::VectorXd& f) { slot_->internalForces({body_}, {&f}); }
  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) {
    slot_->apply({body_}, {c}, {&p}, {&y});
  }
  /// A linear solve of the body alone; throws Error(SolveFailed) for a failure, x then unspecified.
  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x);
  double elasticEnergy();
  std::size_t body() const { return body_; }
  DeviceSlot& slot() const { return *slot_; }

 private:
  DeviceSlot* slot_;
  std::size_t body_;
};

/// The state and checks shared by the per-body drivers (StaticSolver).
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
  /// Strain energy at the current positions (refreshes the device's positions when needed).
  double elasticEnergy();
  /// Makes the device's positions the committed ones (a driver may have evaluated trial positions
  /// last): then the device's buffers describe positions(). No-op when they already do.
  void syncDevicePositions();
  /// The body is body `body` of its slot from now on (a body before it left the slot).
  void moveTo(std::size_t body) { body_ = BodyView(body_.slot(), body); }

 protected:
  BodySolver(const Problem& problem, BodyView body, const Log& log);

  /// Euclidean norm over the free dofs.
  double freeNorm(const Eigen::VectorXd& v) const;
  /// True when every entry is finite.
  static bool allFinite(const Eigen::VectorXd& v);
  /// Sets the device's positions to x and remembers whether they are the committed ones.
  void setDevicePositions(const Eigen::VectorXd& x, bool committed);

  const Problem& problem_;
  BodyView body_;
  const Log& log_;  ///< the Simulation's (debug: per-iteration residuals, substep retries)
  Eigen::ArrayXd freeMask_;   ///< 1 on free dofs, 0 on constrained ones
  double diagonal_ = 1.0;     ///< rest bounding-box diagonal (m), the body's length scale
  /// Force below which a residual counts as zero: the force that strains the whole body by 1e-8,
  /// (lambda + 2 mu) * diagonal^2 * 1e-8 (N). It keeps an unloaded body, whose internal forces
  /// are pure rounding, from failing a purely relative test.
  double forceFloor_ = 0.0;

  Eigen::VectorXd x_, v_;               ///< committed state (statics: v only as the application set it)
  Eigen::VectorXd xPrev_;
  double work_ = 0.0, workPrev_ = 0.0;  ///< external work since the start (trapezoidal rule)
  bool deviceAtCommitted_ = false;      ///< the device's positions equal x_
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
///
/// Inverted equilibria: for the rigorous models (St. Venant-Kirchhoff, Neo-Hookean) a converged
/// iterate counts only when every element keeps det F > 0. Neo-Hookean's forces refuse inversion
/// already; St. Venant-Kirchhoff's energy stays finite at det F <= 0, and past a limit point of the
/// load path Newton converges on a branch of inside-out elements (the pipe elbow of
/// docs/tradeoff.md with 25 N increments, past ~1.54 kN). Such an attempt fails like a
/// non-converged one (cut-back), and the step's message gives the count and the lowest det F.
/// (Linear and co-rotational bodies are not checked: the co-rotational force pushes inverted
/// elements back, tests/extremes/test_inversion.cpp.)
class StaticSolver final : public BodySolver {
 public:
  StaticSolver(const Problem& problem, BodyView body, const StaticDesc& desc, const Log& log = Log::none());
  BodyStepStats step(int increment, int incrementCount) override;
  void rollback() override;

 private:
  /// Outcome of one Newton solve at a fixed load factor.
  struct NewtonOutcome {
    bool converged = false;
    double relative = 0;     ///< final relative residual
    double correction = 0;   ///< last |dx| over the displacement scale
    bool inverted = false;   ///< it reached an equilibrium with inverted elements (rigorous models)
    std::string failure;     ///< why it stopped, when not converged
  };
  /// "" when no element is inverted at x (det F > 0 everywhere), else how many are and the worst
  /// ("149 of 8161 elements inverted (det F <= 0; the lowest, -1.1, in element 1234)").
  std::string invertedElements(const Eigen::VectorXd& x) const;
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

}  // namespace corofem::detail
