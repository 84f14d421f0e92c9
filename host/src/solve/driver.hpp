// What the Simulation drives on one device slot: the analysis of the slot's bodies, step by step.
// Statics run one body at a time (StaticsDriver, each body a StaticSolver); dynamics advance a set
// of bodies in lock-step (DynamicsDriver, solve/dynamics.hpp), each device call serving all bodies
// still in the step. Either way a body's answer is the one it gets alone: its own sequence of
// device calls is the same, and the devices answer each body independently of the others.
#pragma once

#include "solve/device_slot.hpp"
#include "solve/statics.hpp"

#include <corofem/scene.hpp>

#include <exception>
#include <memory>
#include <vector>

namespace corofem::detail {

/// How one body's step ended.
struct BodyOutcome {
  BodyStepStats stats;
  /// Null, or why the step failed (an Error: SolveFailed for a step that failed, with the body
  /// back at its state before the step; DeviceError when every device failed).
  std::exception_ptr error;
};

/// Which step a Driver::step call takes.
struct StepCall {
  int index = 1;   ///< 1-based step / increment
  int count = 1;   ///< steps / increments the analysis asks for; 0: open-ended (dynamics)
  double h = 0.0;  ///< dynamics: the step's length (s); statics ignore it
};

/// What an application holds a body by (Driver::setControls); each vector 3N, or empty for none.
struct BodyControls {
  /// Positions of constrained dofs that replace the scene's (rest or prescribed) targets (m); NaN
  /// where the scene's apply.
  Eigen::VectorXd targets;
  /// Forces added to the scene's loads (N).
  Eigen::VectorXd forces;
  /// Where the springs of Problem::springStiffness pull each dof (m): the spring force on dof d is
  /// k_d (springTargets_d - x_d); ignored where k_d = 0.
  Eigen::VectorXd springTargets;
};

class Driver {
 public:
  virtual ~Driver() = default;
  /// Advances `bodies` (of the slot) by one step (dynamics: from each body's time t to t + h) or to
  /// load increment `index` of `count` (statics).
  virtual std::vector<BodyOutcome> step(const BodySet& bodies, const StepCall& call) = 0;
  /// A step of length h of a sleeping body (dynamics, analysis.sleep): no solve; the time advances,
  /// the positions stay, velocities and accelerations become zero, f_ext moves to the new time.
  /// Keeps the rollback copy like step().
  virtual void idleStep(std::size_t body, double h) = 0;
  /// Restores the body's state before its last successful step (one level).
  virtual void rollback(std::size_t body) = 0;
  /// Replaces the body's state, before the first step or between steps (a body released from a
  /// squashed shape, an application setting or resetting it): x and v are 3N; constrained dofs of x
  /// should sit at their targets, their velocities are zeroed. Dynamics measure the acceleration and
  /// the runaway guard's energy budget again from this state at the next step. Throws
  /// Error(BadInput) for a wrong size or a non-finite entry.
  virtual void setState(std::size_t body, const Eigen::VectorXd& x, const Eigen::VectorXd& v) = 0;

  // -- run-time control (dynamics; the statics driver throws Error(BadInput))

  /// The body's Problem::constrained changed (the slot's device was told): the driver's free dofs
  /// follow it from the next step.
  virtual void constraintsChanged(std::size_t body) = 0;
  /// The body's loads or springs changed (Problem::forces, springStiffness; the slot's device was
  /// told of springs): the driver reads them again from the next step.
  virtual void loadsChanged(std::size_t body) = 0;
  /// The body's Problem material changed (the slot's device was told): its force scale and, at
  /// the next step, its acceleration and energy budget are measured again.
  virtual void materialChanged(std::size_t body) = 0;
  /// What an application holds the body by, from the next step until replaced.
  virtual void setControls(std::size_t body, const BodyControls& controls) = 0;
  /// Forgets body `body` (its slot removed it too): later bodies' indices move down by one, and
  /// the others keep their state.
  virtual void removeBody(std::size_t body) = 0;

  virtual const Eigen::VectorXd& positions(std::size_t body) const = 0;
  virtual const Eigen::VectorXd& velocities(std::size_t body) const = 0;
  virtual double externalWork(std::size_t body) const = 0;
  /// 1/2 v^T M v with the lumped mass (every dof, constrained ones included).
  virtual double kineticEnergy(std::size_t body) const = 0;
  /// Strain energy at the committed positions (makes them the device's first).
  virtual double elasticEnergy(std::size_t body) = 0;
  /// Makes the device's positions of these bodies their committed ones (a driver may have left
  /// trial positions there): then the device's buffers describe positions().
  virtual void syncDevicePositions(const BodySet& bodies) = 0;
};

/// The driver the analysis asks for, over the slot's bodies; the slot and `log` outlive it.
std::unique_ptr<Driver> createDriver(DeviceSlot& slot, const AnalysisDesc& analysis, const Log& log = Log::none());

}  // namespace corofem::detail
