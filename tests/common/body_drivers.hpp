// The drivers of one body on a device the test owns (a mock, a reference device), with per-body
// calls: DynamicSolver over the lock-step DynamicsDriver, StaticSolver over the library's own. The
// test keeps its device; the drivers get a view of it (BorrowedDevice) in a slot of their own.
#pragma once

#include "common/device_fakes.hpp"
#include "solve/driver.hpp"
#include "solve/dynamics.hpp"
#include "solve/statics.hpp"

#include <memory>

namespace corofem::test {

/// A device that forwards to one the caller keeps alive (not owned).
class BorrowedDevice final : public ForwardingDevice {
 public:
  explicit BorrowedDevice(detail::Device& device) : ForwardingDevice(device) {}
};

/// The solver settings of a device that solves directly (the mocks): the Cholesky solver.
inline SolverDesc directSolver() {
  SolverDesc s;
  s.linearSolver = LinearSolverKind::Cholesky;
  return s;
}

/// Implicit dynamics of one body (body 0 of `device`).
class DynamicSolver {
 public:
  DynamicSolver(const detail::Problem&, detail::Device& device, const DynamicDesc& desc,
                const SolverDesc& solver = directSolver())
      : slot_(std::make_unique<BorrowedDevice>(device), solver), driver_(slot_, desc), h_(desc.timeStep) {}
  /// Step `index` of `count` (of the scene's time step). Throws the body's error
  /// (Error(SolveFailed)) with the state unchanged.
  detail::BodyStepStats step(int index, int count) {
    std::vector<detail::BodyOutcome> out = driver_.step({0}, detail::StepCall{index, count, h_});
    if (out.at(0).error) std::rethrow_exception(out[0].error);
    return out[0].stats;
  }
  void idleStep(int, int) { driver_.idleStep(0, h_); }
  void rollback() { driver_.rollback(0); }
  void setInitialState(const Eigen::VectorXd& x, const Eigen::VectorXd& v) { driver_.setState(0, x, v); }
  double time() const { return driver_.time(0); }
  const Eigen::VectorXd& positions() const { return driver_.positions(0); }
  const Eigen::VectorXd& velocities() const { return driver_.velocities(0); }
  double kineticEnergy() const { return driver_.kineticEnergy(0); }
  double elasticEnergy() { return driver_.elasticEnergy(0); }
  double externalWork() const { return driver_.externalWork(0); }
  detail::DeviceSlot& slot() { return slot_; }

 private:
  detail::DeviceSlot slot_;
  detail::DynamicsDriver driver_;
  double h_;
};

/// Newton statics of one body (body 0 of `device`).
class StaticSolver {
 public:
  StaticSolver(const detail::Problem& problem, detail::Device& device, const StaticDesc& desc,
               const SolverDesc& solver = directSolver())
      : slot_(std::make_unique<BorrowedDevice>(device), solver), solver_(problem, detail::BodyView(slot_, 0), desc) {}
  detail::BodyStepStats step(int index, int count) { return solver_.step(index, count); }
  void rollback() { solver_.rollback(); }
  void setInitialState(const Eigen::VectorXd& x, const Eigen::VectorXd& v) { solver_.setInitialState(x, v); }
  const Eigen::VectorXd& positions() const { return solver_.positions(); }
  const Eigen::VectorXd& velocities() const { return solver_.velocities(); }
  double kineticEnergy() const { return solver_.kineticEnergy(); }
  double elasticEnergy() { return solver_.elasticEnergy(); }
  double externalWork() const { return solver_.externalWork(); }

 private:
  detail::DeviceSlot slot_;
  detail::StaticSolver solver_;
};

/// The driver of body 0 of a device handed over, for any analysis.
class BodyDriver {
 public:
  BodyDriver(std::unique_ptr<detail::Device> device, const AnalysisDesc& analysis, const SolverDesc& solver)
      : slot_(std::move(device), solver), driver_(detail::createDriver(slot_, analysis)), h_(analysis.dynamics.timeStep) {}
  /// Throws the body's error (Error(SolveFailed)) with the state unchanged.
  detail::BodyStepStats step(int index, int count) {
    std::vector<detail::BodyOutcome> out = driver_->step({0}, detail::StepCall{index, count, h_});
    if (out.at(0).error) std::rethrow_exception(out[0].error);
    return out[0].stats;
  }
  void rollback() { driver_->rollback(0); }
  void setInitialState(const Eigen::VectorXd& x, const Eigen::VectorXd& v) { driver_->setState(0, x, v); }
  const Eigen::VectorXd& positions() const { return driver_->positions(0); }
  const Eigen::VectorXd& velocities() const { return driver_->velocities(0); }
  double kineticEnergy() const { return driver_->kineticEnergy(0); }
  double elasticEnergy() { return driver_->elasticEnergy(0); }
  double externalWork() const { return driver_->externalWork(0); }
  detail::DeviceSlot& slot() { return slot_; }

 private:
  detail::DeviceSlot slot_;
  std::unique_ptr<detail::Driver> driver_;
  double h_;
};

}  // namespace corofem::test
