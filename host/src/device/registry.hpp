// The backend registry: every backend compiled into the library (reference, OpenCL; later Vulkan),
// and any an embedder or a test registers, behind one entry each. The scheduler, failover, the
// calibration cache, `corofem run --plan` and the command's device list iterate it; nothing above
// backends/ names a particular API.
#pragma once

#include "device/device.hpp"

#include <corofem/gpu.hpp>
#include <corofem/scene.hpp>
#include <corofem/tuning.hpp>

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

/// What the devices get beyond the scene (SimulationOptions).
struct DeviceOptions {
  OpenCLTuning opencl;
  VulkanTuning vulkan;
  /// The application's device; a backend of its API makes it the device of the selector
  /// kExternalSelector.
  ExternalDevice external;
};

/// The selector of the device an application lends (SimulationOptions::device): "opencl:external".
constexpr const char* kExternalSelector = "external";

/// One place a body can run: a backend and one of its devices.
struct Candidate {
  std::string backend;   ///< the registry name: "reference", "opencl", ...
  std::string device;    ///< the device's name (the reference backend: "host (Eigen, double)")
  std::string selector;  ///< what the backend's factory finds the device by (OpenCL: its index as text)
  std::string driver;    ///< the driver's version (part of the calibration cache's key)
  bool gpu = false;
  /// "reference", or "<backend>:<selector> (<device>)".
  std::string label() const;
};

/// What a body's step needs of a device, for the plan's list of passes (`corofem run --plan`).
struct PlanPasses {
  bool corotational = false;
  RotationMethod rotation = RotationMethod::Polar;
  bool dynamic = false, damping = false;
  PreconditionerKind preconditioner = PreconditionerKind::None;  ///< as resolved for the body

  bool amg() const { return preconditioner == PreconditionerKind::Amg; }
  /// The PCG set-up forms the inverses of the 3x3 node blocks (block_diagonal; amg smooths with them).
  bool nodeBlocks() const { return preconditioner == PreconditionerKind::BlockDiagonal || amg(); }
  /// The PCG set-up's M^-1, as the plans name it ("" without a preconditioner).
  const char* formsInverse() const {
    return preconditioner == PreconditionerKind::None ? "" : nodeBlocks() ? " (forms M^-1: 3x3 blocks)"
                                                                          : " (forms M^-1: diagonal)";
  }
};

/// A body's sizes for the plan's list of device buffers.
struct PlanSizes {
  double elements = 0, nodes = 0;
  double realBytes = 8;          ///< 4 in float, 8 in double
  double amgEntriesPerDof = 0;   ///< the multigrid's level entries per dof (the plan's estimate)
};

/// One device buffer of a body's share, for the plan.
struct PlanBuffer {
  std::string name;
  double bytes = 0;
};

struct BackendEntry {
  std::string name;  ///< "reference", "opencl": what scenes, COROFEM_DEVICE and the reports call it
  /// The devices of this backend on this machine, in the order they are tried (empty: none).
  std::function<std::vector<Candidate>()> candidates;
  /// The candidate a request names: `selector` "" for the backend's default device, else what the
  /// backend understands (OpenCL: an index or a part of a name). An unknown selector may be kept
  /// as given, for the factory's error to list the devices.
  std::function<Candidate(const std::string& selector)> resolve;
  /// "" when the backend can run this body with these solver settings, else why not (a sentence
  /// naming the fix).
  std::function<std::string(const Problem& problem, const SolverDesc& solver)> refuses;
  /// A device of candidate `c` holding `problems` (which outlive it). Throws Error(DeviceError)
  /// for a device that cannot be used, Error(BadInput) for what it cannot run.
  std::function<std::unique_ptr<Device>(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                        const Candidate& c, const DeviceOptions& options)>
      create;
  /// What the backend's answers and speed depend on beyond the scene (a kernel source's hash),
  /// for the calibration cache's key; "" for none.
  std::function<std::string()> buildId;
  /// Bodies scheduled on one of its devices share its buffers and launches (BackendDesc::batch).
  bool batches = false;
  /// Where batches: whether this body joins a batch (null: every body). A body whose device calls
  /// can fail for it alone (a Neo-Hookean element turned inside out fails the reference device's
  /// call) runs alone, so that its failure fails no other body's step.
  std::function<bool(const Problem& problem)> batchable;
  /// The passes a step of such a body runs on the backend's devices, named as its kernels or
  /// shaders, for the plan; null: the plan names them generically.
  std::function<std::vector<std::string>(const PlanPasses& step)> passes;
  /// The device buffers such a body takes on the backend's devices (its share of a batch's), for
  /// the plan; null: the plan lists those of the OpenCL backend's layout.
  std::function<std::vector<PlanBuffer>(const PlanPasses& step, const PlanSizes& sizes)> buffers;
};

/// Registers a backend (replacing one of the same name, a built-in one too: the built-in ones are
/// registered at the registry's first use, this call included). Safe from any thread; devices
/// already made stay as they are, later ones (a failover too) come from the entry then registered.
void registerBackend(BackendEntry entry);
/// Removes a registered backend ("reference" cannot be removed).
void unregisterBackend(const std::string& name);
/// Every registered backend, the reference backend last.
std::vector<BackendEntry> registeredBackends();
/// The backend of that name, or null.
std::shared_ptr<const BackendEntry> findBackend(const std::string& name);
/// The backend of a candidate; throws Error(BadInput) naming the registered ones when there is none.
std::shared_ptr<const BackendEntry> backendOf(const Candidate& c);

/// The reference backend's one candidate.
Candidate referenceCandidate();

/// Why a device backend that runs what the reference backend has except its host-only features
/// (the hyperelastic formulations, the Cholesky solver) refuses this body: a sentence naming the
/// fix, or "" where it uses none of them.
std::string hostOnlyFeature(const Problem& problem, const SolverDesc& solver);

/// The device a selector names among a backend's devices (names[i], gpu[i]: device i's name and
/// whether it is a GPU), the rule every device backend's selector follows: "" the first GPU, else
/// the first device; digits an index; anything else the first device whose name contains it,
/// whatever the case. names.size() where none matches (the caller's error lists its devices).
std::size_t selectDeviceIndex(const std::vector<std::string>& names, const std::vector<bool>& gpu,
                              const std::string& selector);

/// The entry of a backend this build leaves out: no device, and every other call throws
/// Error(NotCompiledIn) with `why` (which names the fix). backends/<name>_unavailable.cpp register it.
BackendEntry unavailableBackend(const std::string& name, const std::string& why);

/// Registers the backends compiled into this library (backends/builtin_backends.cpp).
void registerBuiltinBackends();

}  // namespace corofem::detail
