// The OpenCL backend (co-rotational and linear formulations): its Device (opencl_device.cpp, over a
// SegmentEngine), and what tests and benchmarks see beyond the Device and Backend interfaces.
#pragma once

#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/program_cache.hpp"
#include "backends/opencl/tuning.hpp"
#include "device/device.hpp"

#include <Eigen/Core>

#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

class SegmentEngine;

/// One body on an OpenCL device of its own, with what the conformance tests and the benchmarks
/// need to see: the device's calls for that body, a whole linear solve (solvePcg), and internals.
class OpenCLBackendInternal {
 public:
  OpenCLBackendInternal(std::unique_ptr<Device> device, SegmentEngine& engine, const SolverDesc& solver);
  ~OpenCLBackendInternal();
  std::string name() const { return device_->name(); }
  std::string deviceName() const { return device_->deviceName(); }
  void setPositions(const Eigen::VectorXd& x) { device_->setPositions({0}, {&x}); }
  void internalForces(Eigen::VectorXd& f) { device_->internalForces({0}, {&f}); }
  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) { device_->apply({0}, {c}, {&p}, {&y}); }
  /// Solves A x = b (x: the starting vector in); throws Error(SolveFailed) for a failure.
  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x);
  double elasticEnergy();
  std::vector<DeviceBuffer> deviceBuffers() const { return device_->buffers(); }
  bool devicePositions(DevicePositions& out) const { return device_->devicePositions(0, out); }
  Device& device() { return *device_; }

  /// The element rotations, 9 per element (row-major R), as last computed by setPositions.
  std::vector<double> readRotations();
  /// The -D options the program was built with.
  const std::string& buildOptions() const;
  /// Where the program came from (memory, disk cache, compiler).
  cl::ProgramOrigin programOrigin() const;
  const cl::ProgramBuild& programBuild() const;
  cl::Context& context();
  /// Bytes of device memory the device allocated (the sum of its buffers' sizes). Only buffers
  /// something reads exist: no mass buffer for a static problem (no nonzero lumped mass),
  /// quaternions only for that rotation method, preconditioner data only with a preconditioner.
  std::size_t allocatedBytes() const;

  // The node positions on the device (e.g. for DeviceSurface::updateFromDevice, no host round trip):
  // 3 reals per node (double when positionsAreDouble(), else float, also in mixed precision), those
  // last given to setPositions, minus positionCentroid() (the mean of those positions, subtracted in
  // double so that float keeps its resolution far from the origin): x_n = pos[m] + centroid, with m
  // = n, or m = DevicePositions::deviceNode[n] where the device numbers the nodes in its locality
  // order (OpenCLTuning::localityOrder).
  /// The buffer of 3 * nodeCount relative positions; owned by the device, valid for its lifetime.
  cl_mem positionBuffer() const;
  bool positionsAreDouble() const;
  /// The centroid subtracted by the last setPositions (0 before the first).
  const double* positionCentroid() const;

  // Device-only work for the benchmark (no transfers); finish() waits for it.
  void enqueueRotations();         ///< rotations from the positions on the device
  void enqueueForces();            ///< element forces + gather
  void enqueueElementForces();     ///< element forces only (no gather)
  void enqueueProduct(const SystemCoeffs& c);  ///< q = A p (element product + gather)
  void enqueueElementProduct(const SystemCoeffs& c);  ///< element product only
  /// PCG set-up from the b and x last given to solve(), then `iterations` iterations, no reads.
  void enqueuePcgIterations(const SystemCoeffs& c, int iterations);
  void finish();
  /// The engine under the device (benchmarks: its kernel profile; tests: its internals).
  SegmentEngine& engine() { return engine_; }

 private:
  std::unique_ptr<Device> device_;
  SegmentEngine& engine_;
  SolverDesc solver_;
};

/// The backend on a given context (shared, private or adopted). Throws Error(BadInput) for a
/// formulation other than co-rotational or linear, Error(DeviceError) for a device problem.
std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendOn(const Problem& problem,
                                                             const SolverDesc& solver,
                                                             std::shared_ptr<cl::Context> context,
                                                             const OpenCLTuning& tuning = {});

/// The OpenCL device of `problems` on a given context (the registry's factory, tests). Throws as
/// SegmentEngine does.
std::unique_ptr<Device> createOpenCLDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                           std::shared_ptr<cl::Context> context, const OpenCLTuning& tuning = {});

/// Bodies on one OpenCL device, with its engine in view (tests, benchmarks).
struct OpenCLBatch {
  std::unique_ptr<Device> device;
  SegmentEngine* engine = nullptr;  ///< the device's own
};

/// The OpenCL device of `problems` on a given context, with its engine (tests, benchmarks).
OpenCLBatch createOpenCLBatchOn(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                std::shared_ptr<cl::Context> context, const OpenCLTuning& tuning = {});

/// The backend on an application's own context, queue and device (retained, never released
/// beyond the backend's own references).
std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendAdopting(const Problem& problem,
                                                                   const SolverDesc& solver,
                                                                   cl_context context,
                                                                   cl_command_queue queue,
                                                                   cl_device_id device,
                                                                   const OpenCLTuning& tuning = {});

}  // namespace corofem::detail
