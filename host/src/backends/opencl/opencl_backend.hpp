// The OpenCL backend (co-rotational and linear formulations): its Device (opencl_device.cpp, over a
// SegmentEngine), and what tests and benchmarks see beyond the Device and Backend interfaces.
#pragma once

#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/program_cache.hpp"
#include "backends/opencl/tuning.hpp"
#include "solve/backend.hpp"
#include "solve/batch.hpp"

#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

class SegmentEngine;

/// Backend plus what the conformance tests and the benchmark need to see.
class OpenCLBackendInternal : public Backend {
 public:
  /// The element rotations, 9 per element (row-major R), as last computed by setPositions.
  virtual std::vector<double> readRotations() = 0;
  /// The -D options the program was built with.
  virtual const std::string& buildOptions() const = 0;
  /// Where the program came from (memory, disk cache, compiler).
  virtual cl::ProgramOrigin programOrigin() const = 0;
  virtual const cl::ProgramBuild& programBuild() const = 0;
  virtual cl::Context& context() = 0;
  /// Bytes of device memory the backend allocated (the sum of its buffers' sizes). Only buffers
  /// something reads exist: no mass buffer for a static problem (no nonzero lumped mass),
  /// quaternions only for that rotation method, preconditioner data only with a preconditioner.
  virtual std::size_t allocatedBytes() const = 0;

  // The node positions on the device (e.g. for DeviceSurface::updateFromDevice, no host round trip):
  // 3 reals per node (double when positionsAreDouble(), else float, also in mixed precision), those
  // last given to setPositions, minus positionCentroid() (the mean of those positions, subtracted in
  // double so that float keeps its resolution far from the origin): x_n = pos[m] + centroid, with m
  // = n, or m = DevicePositions::deviceNode[n] where the device numbers the nodes in its locality
  // order (OpenCLTuning::localityOrder).
  /// The buffer of 3 * nodeCount relative positions; owned by the backend, valid for its lifetime.
  virtual cl_mem positionBuffer() const = 0;
  virtual bool positionsAreDouble() const = 0;
  /// The centroid subtracted by the last setPositions (0 before the first).
  virtual const double* positionCentroid() const = 0;

  // Device-only work for the benchmark (no transfers); finish() waits for it.
  virtual void enqueueRotations() = 0;         ///< rotations from the positions on the device
  virtual void enqueueForces() = 0;            ///< element forces + gather
  virtual void enqueueElementForces() = 0;     ///< element forces only (no gather)
  virtual void enqueueProduct(const SystemCoeffs& c) = 0;  ///< q = A p (element product + gather)
  virtual void enqueueElementProduct(const SystemCoeffs& c) = 0;  ///< element product only
  /// PCG set-up from the b and x last given to solve(), then `iterations` iterations, no reads.
  virtual void enqueuePcgIterations(const SystemCoeffs& c, int iterations) = 0;
  virtual void finish() = 0;
  /// The engine under the backend (benchmarks: its kernel profile; tests: its internals).
  virtual SegmentEngine& engine() = 0;
};

/// The backend on a given context (shared, private or adopted). Throws Error(BadInput) for a
/// formulation other than co-rotational or linear, Error(DeviceError) for a device problem.
std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendOn(const Problem& problem,
                                                             const SolverDesc& solver,
                                                             std::shared_ptr<cl::Context> context,
                                                             const OpenCLTuning& tuning = {});

/// The OpenCL batch device with its engine in view (tests, benchmarks).
class OpenCLBatchDeviceInternal : public DeviceBatch {
 public:
  using DeviceBatch::DeviceBatch;
  virtual SegmentEngine& engine() = 0;
};

/// The OpenCL device of `problems` on a given context (the registry's factory, tests). Throws as
/// SegmentEngine does.
std::unique_ptr<Device> createOpenCLDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                           std::shared_ptr<cl::Context> context, const OpenCLTuning& tuning = {});

/// The OpenCL batch device (solve/batch.hpp: createOpenCLBatchDevice) on a given context and with
/// the tuning options of the single backend (tests, benchmarks).
std::unique_ptr<OpenCLBatchDeviceInternal> createOpenCLBatchDeviceOn(const std::vector<const Problem*>& problems,
                                                       const SolverDesc& solver,
                                                       std::shared_ptr<cl::Context> context,
                                                       const OpenCLTuning& tuning = {});

/// The backend on an application's own context, queue and device (retained, never released
/// beyond the backend's own references).
std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendAdopting(const Problem& problem,
                                                                   const SolverDesc& solver,
                                                                   cl_context context,
                                                                   cl_command_queue queue,
                                                                   cl_device_id device,
                                                                   const OpenCLTuning& tuning = {});

}  // namespace corofem::detail
