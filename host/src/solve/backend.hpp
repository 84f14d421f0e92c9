// The small interface every backend implements (reference Eigen, OpenCL, later Vulkan). Newton,
// the time integrators and the Simulation are written once in solve/ against it.
//
// System matrices: A = mass * M + damping * C + stiffness * K_t, with M the lumped mass,
// C = alpha M + beta K_t (Rayleigh, alpha/beta from the problem) and K_t the tangent stiffness
// at the current positions (R K R^T summed over elements for the co-rotational formulation,
// K for the linear one, the consistent tangent for the hyperelastic ones).
#pragma once

#include "model/problem.hpp"

#include <corofem/scene.hpp>
#include <corofem/tuning.hpp>

#include <Eigen/Core>

#include <memory>
#include <string>
#include <vector>

// OpenCL's opaque handle types, declared so that this header needs no OpenCL.
struct _cl_context;
struct _cl_command_queue;
struct _cl_device_id;
struct _cl_mem;

namespace corofem::detail {

/// Where a backend keeps a body's node positions on an OpenCL device (the device surface reads
/// them there: no host round trip). 3 reals per node, double when isDouble else float, those last
/// given to setPositions minus `centroid` (3 doubles), node n of the body at node firstNode + n of
/// `buffer`, or firstNode + deviceNode[n] where deviceNode is set (a batch holds many bodies in one
/// buffer). Valid while the backend lives.
struct DevicePositions {
  _cl_context* context = nullptr;
  _cl_command_queue* queue = nullptr;  ///< in-order queue that writes them
  _cl_device_id* device = nullptr;
  _cl_mem* buffer = nullptr;
  std::size_t firstNode = 0;
  bool isDouble = false;
  const double* centroid = nullptr;
  /// The device's index (from firstNode) of each of the body's nodes, where the device numbers them
  /// in an order of its own (the OpenCL backend's locality order); nullptr: node i is at i.
  const std::uint32_t* deviceNode = nullptr;
};

struct SystemCoeffs {
  double mass = 0.0;
  double damping = 0.0;
  double stiffness = 1.0;
};

/// A device buffer a backend allocated: what it holds and its size at allocation.
struct DeviceBuffer {
  std::string name;
  std::size_t bytes = 0;
};

struct LinearSolveStats {
  int iterations = 0;             ///< PCG iterations (0 for a direct solve)
  double relativeResidual = 0.0;  ///< |b - A x| / |b| on the free dofs (0 when b = 0)
  bool converged = false;
};

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

/// The reference backend: assembled sparse matrices, Eigen's CG (diagonal preconditioner) or
/// sparse Cholesky, double precision. Supports every formulation.
std::unique_ptr<Backend> createReferenceBackend(const Problem& problem, const SolverDesc& solver);

/// The OpenCL backend (co-rotational and linear formulations). Throws Error(NotCompiledIn) when
/// the library was built without COROFEM_WITH_OPENCL, Error(DeviceError) when no device fits.
std::unique_ptr<Backend> createOpenCLBackend(const Problem& problem, const SolverDesc& solver,
                                             const std::string& deviceSelector, const OpenCLTuning& tuning = {});

}  // namespace corofem::detail
