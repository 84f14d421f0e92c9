// One body's view of a device (device/device.hpp) as the per-body drivers (solve/body_solver.hpp)
// call it: the device's operations for the set of that one body, and a whole linear solve. The
// system matrices are the device's (A = mass M + damping C + stiffness K_t).
#pragma once

#include "device/device.hpp"
#include "model/problem.hpp"

#include <corofem/scene.hpp>
#include <corofem/tuning.hpp>

#include <Eigen/Core>

#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string name() const = 0;        ///< "reference", "opencl"
  virtual std::string deviceName() const = 0;  ///< human-readable device

  /// Sets the current positions (3N, node-major) and refreshes the per-element state that depends
  /// on them (rotations for the co-rotational formulation, F for the hyperelastic ones).
  virtual void setPositions(const Eigen::VectorXd& x) = 0;

  /// Internal forces at the current positions (3N). Constrained dofs are not zeroed.
  virtual void internalForces(Eigen::VectorXd& f) = 0;

  /// y = A p on all dofs (no projection of constraints).
  virtual void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) = 0;

  /// Solves A x = b on the free dofs; constrained dofs of x are set to 0 and their rows of b
  /// ignored. On entry x holds the starting vector (warm start). Never throws for
  /// non-convergence: the stats say so. Throws Error(SolveFailed) when the result is not finite.
  virtual LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) = 0;

  /// Strain energy at the current positions (J).
  virtual double elasticEnergy() = 0;

  /// The device buffers this backend allocated, each at its allocated size (what `corofem run
  /// --plan` reports as allocated). Empty for host backends and for a body's view of a batch (the
  /// batch reports the buffers its bodies share).
  virtual std::vector<DeviceBuffer> deviceBuffers() const { return {}; }

  /// Fills `out` and returns true when the body's node positions live on an OpenCL device (the
  /// OpenCL backend, a body's view of an OpenCL batch); false for host backends.
  virtual bool devicePositions(DevicePositions& out) const {
    (void)out;
    return false;
  }
};

/// One body of a device seen as a Backend: its calls are the device's for the set of that body,
/// its solve is solveLinear (solve/pcg.hpp).
class DeviceBody : public Backend {
 public:
  DeviceBody(std::shared_ptr<Device> device, std::size_t body, const SolverDesc& solver);
  std::string name() const override { return device_->name(); }
  std::string deviceName() const override { return device_->deviceName(); }
  void setPositions(const Eigen::VectorXd& x) override;
  void internalForces(Eigen::VectorXd& f) override;
  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) override;
  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) override;
  double elasticEnergy() override;
  /// The device's buffers where the body has it to itself.
  std::vector<DeviceBuffer> deviceBuffers() const override;
  bool devicePositions(DevicePositions& out) const override { return device_->devicePositions(body_, out); }
  Device& device() const { return *device_; }

 private:
  std::shared_ptr<Device> device_;
  std::size_t body_;
  SolverDesc solver_;
};

/// The reference backend: assembled sparse matrices, the device backends' PCG in double or
/// sparse Cholesky. Supports every formulation.
std::unique_ptr<Backend> createReferenceBackend(const Problem& problem, const SolverDesc& solver);

/// The OpenCL backend (co-rotational and linear formulations). Throws Error(NotCompiledIn) when
/// the library was built without COROFEM_WITH_OPENCL, Error(DeviceError) when no device fits.
std::unique_ptr<Backend> createOpenCLBackend(const Problem& problem, const SolverDesc& solver,
                                             const std::string& deviceSelector, const OpenCLTuning& tuning = {});

}  // namespace corofem::detail
