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

class Driver {
 public:
  virtual ~Driver() = default;
  /// Advances `bodies` (of the slot) to step / increment `index` (1-based) of `count`.
  virtual std::vector<BodyOutcome> step(const BodySet& bodies, int index, int count) = 0;
  /// A step of a sleeping body (dynamics, analysis.sleep): no solve; the time advances by one
  /// step, the positions stay, velocities and accelerations become zero, f_ext moves to the new
  /// time. Keeps the rollback copy like step().
  virtual void idleStep(std::size_t body) = 0;
  /// Restores the body's state before its last successful step (one level).
  virtual void rollback(std::size_t body) = 0;
  /// Replaces the body's starting state before the first step (a body released from a squashed or
  /// inverted shape): x and v are 3N; constrained dofs of x should sit at their targets at t = 0 and
  /// their velocities are zeroed. Throws Error(BadInput) for a wrong size or a non-finite entry.
  virtual void setInitialState(std::size_t body, const Eigen::VectorXd& x, const Eigen::VectorXd& v) = 0;

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
