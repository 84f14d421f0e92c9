// Many bodies, one set of launches (issue 5): the interface between the per-body drivers, which
// stay exactly as they are (solve/body_solver.hpp), and a device that runs the same Backend call
// for many bodies at once.
//
// How the pieces fit:
//   BatchDevice   runs one *round*: at most one request per body, every request a Backend call
//                 (setPositions, internalForces, apply, solve, elasticEnergy) of that body. An
//                 OpenCL implementation keeps all bodies in shared buffers (per-body segments,
//                 work-groups never straddle two bodies) and does a round with one launch sequence
//                 per kind of call; each body keeps its own material, coefficients and PCG
//                 convergence (a converged body's work-groups return at once while others iterate).
//   BatchGroup    turns the BatchDevice into one Backend *view* per body. While the group runs a
//                 batched step (startStep .. finishStep), each body's driver runs as a fiber of one of
//                 the group's few threads (or on a thread of its own: COROFEM_BATCH_FIBERS=0);
//                 a view call waits until every body still inside the step has made its call (or
//                 finished its step), then one of them runs the round for all. Outside a batched
//                 step a view call is a round of one. So the drivers' logic (Newton, substeps,
//                 energy guard, failure and rollback) exists once, and batching changes no answer.
//
// Invariants: a round holds at most one request per body; the answer a body gets from a round is
// the answer a Backend of its own would give for the same call (the OpenCL batch: to rounding of
// the same kernels; LoopBatchDevice: bit-identical).
#pragma once

#include "model/problem.hpp"
#include "solve/backend.hpp"

#include <corofem/scene.hpp>

#include <Eigen/Core>

#include <exception>
#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

enum class BatchOp { SetPositions, InternalForces, Apply, Solve, ElasticEnergy };

/// One Backend call of one body. Inputs point at the caller's data, which stays alive and
/// unchanged until the round returns.
struct BatchRequest {
  BatchOp op = BatchOp::SetPositions;
  std::size_t body = 0;                  ///< index into the device's problems
  SystemCoeffs coeffs;                   ///< Apply, Solve
  const Eigen::VectorXd* in = nullptr;   ///< SetPositions: x; Apply: p; Solve: b
  Eigen::VectorXd* out = nullptr;        ///< InternalForces: f; Apply: y; Solve: x (warm start in, solution out)
  LinearSolveStats stats;                ///< Solve: filled by the round
  double energy = 0.0;                   ///< ElasticEnergy: filled by the round
  /// Set by the round when this request failed (the Error the body's own Backend would have
  /// thrown: SolveFailed for a non-finite PCG, DeviceError for a device failure, which then fails
  /// every request of the round). The view rethrows it in the body's thread.
  std::exception_ptr error;
};

/// A device that answers rounds of requests from many bodies.
class BatchDevice {
 public:
  virtual ~BatchDevice() = default;
  virtual std::string name() const = 0;        ///< as Backend::name() ("opencl", "reference")
  virtual std::string deviceName() const = 0;
  virtual std::size_t bodyCount() const = 0;
  /// Runs every request (at most one per body). Never throws for a per-request failure: it sets
  /// that request's `error`. May throw for a failure outside any request (then every request of
  /// the round counts as failed with that error).
  virtual void run(std::vector<BatchRequest*>& round) = 0;
  /// Bytes of device memory this batch allocated (0 for host devices).
  virtual std::size_t allocatedBytes() const { return 0; }
  /// The device buffers its bodies share (empty for host devices).
  virtual std::vector<DeviceBuffer> deviceBuffers() const { return {}; }
  /// Backend::devicePositions of body `body` (false for host devices).
  virtual bool devicePositions(std::size_t body, DevicePositions& out) const {
    (void)body;
    (void)out;
    return false;
  }
};

/// A device's bodies as a BatchDevice: each kind of call in a round is one device call for the
/// bodies that made it (solves through solvePcg, solve/pcg.hpp). A request whose vectors do not fit
/// its body fails alone (Error(Internal)); a device failure fails every request of the round.
class DeviceBatch : public BatchDevice {
 public:
  DeviceBatch(std::shared_ptr<Device> device, const SolverDesc& solver);
  std::string name() const override { return device_->name(); }
  std::string deviceName() const override { return device_->deviceName(); }
  std::size_t bodyCount() const override { return device_->bodyCount(); }
  std::size_t allocatedBytes() const override;
  std::vector<DeviceBuffer> deviceBuffers() const override { return device_->buffers(); }
  bool devicePositions(std::size_t body, DevicePositions& out) const override {
    return device_->devicePositions(body, out);
  }
  void run(std::vector<BatchRequest*>& round) override;
  Device& device() const { return *device_; }

 private:
  void runOp(BatchOp op, std::vector<BatchRequest*>& requests);
  std::shared_ptr<Device> device_;
  SolverDesc solver_;
};

/// The batch as a loop over one Backend per body (reference or any other): no speed-up, but
/// bit-identical to running the bodies separately. Tests the BatchGroup on any machine; also the
/// fallback when no device batches.
std::unique_ptr<BatchDevice> createLoopBatchDevice(std::vector<std::unique_ptr<Backend>> backends);

/// The OpenCL batch: every problem in one set of buffers and launches on `deviceSelector`'s
/// device (the selector of createOpenCLBackend). All bodies share the solver settings that shape
/// the program (precision, rotation method, preconditioner); tolerance and iteration cap are the
/// solver's; material, mass, Rayleigh damping and constraints are each problem's. Throws
/// Error(NotCompiledIn) without COROFEM_WITH_OPENCL, Error(BadInput) for a formulation other than
/// co-rotational or linear, Error(DeviceError) for a device problem. The problems must outlive it.
std::unique_ptr<BatchDevice> createOpenCLBatchDevice(const std::vector<const Problem*>& problems,
                                                     const SolverDesc& solver, const std::string& deviceSelector,
                                                     const OpenCLTuning& tuning = {});

}  // namespace corofem::detail
