// One body on a device of its own, as the tests call it: the device's calls for that body and a
// whole linear solve (solveLinear, solve/pcg.hpp). Made through the registry users see.
#pragma once

#include "backends/reference/reference_device.hpp"
#include "device/registry.hpp"
#include "solve/pcg.hpp"
#include "util/error.hpp"

#include <memory>
#include <string>
#include <vector>

namespace corofem::test {

class Backend {
 public:
  Backend(std::unique_ptr<detail::Device> device, const SolverDesc& solver)
      : device_(std::move(device)), solver_(solver) {}
  std::string name() const { return device_->name(); }
  std::string deviceName() const { return device_->deviceName(); }
  void setPositions(const Eigen::VectorXd& x) { device_->setPositions({0}, {&x}); }
  void internalForces(Eigen::VectorXd& f) { device_->internalForces({0}, {&f}); }
  void apply(const detail::SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) {
    device_->apply({0}, {c}, {&p}, {&y});
  }
  /// Throws Error(SolveFailed) for a failure (x then unspecified).
  detail::LinearSolveStats solve(const detail::SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) {
    return detail::solveLinear(*device_, 0, c, b, x, solver_);
  }
  double elasticEnergy() {
    std::vector<double> e;
    device_->elasticEnergy({0}, e);
    return e.at(0);
  }
  std::vector<detail::DeviceBuffer> deviceBuffers() const { return device_->buffers(); }
  bool devicePositions(detail::DevicePositions& out) const { return device_->devicePositions(0, out); }
  detail::Device& device() { return *device_; }

 private:
  std::unique_ptr<detail::Device> device_;
  SolverDesc solver_;
};

/// The reference backend's device holding `problem` alone.
inline std::unique_ptr<Backend> createReferenceBackend(const detail::Problem& problem, const SolverDesc& solver) {
  return std::make_unique<Backend>(detail::createReferenceDevice({&problem}, solver), solver);
}

/// The registered backend `name`'s device `selector` ("" = its default) holding `problem` alone.
inline std::unique_ptr<Backend> createBackend(const std::string& name, const std::string& selector,
                                             const detail::Problem& problem, const SolverDesc& solver,
                                             const detail::DeviceOptions& options = {}) {
  const auto entry = detail::findBackend(name);
  if (!entry) detail::fail(ErrorCode::NotCompiledIn, "no backend '", name, "' in this build");
  const detail::Candidate c = entry->resolve ? entry->resolve(selector) : entry->candidates().at(0);
  return std::make_unique<Backend>(entry->create({&problem}, solver, c, options), solver);
}

}  // namespace corofem::test
