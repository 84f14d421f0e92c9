// The one interface every backend implements (reference Eigen, OpenCL, later Vulkan): a device
// holding a set of bodies, each with its own problem, that runs the element operations and the
// building blocks of PCG for any subset of them at once (one body is a set of one). Newton, the
// time integrators and the PCG loop itself (solve/pcg.hpp) are written once above it; a backend
// only runs their steps.
//
// System matrices: A = mass * M + damping * C + stiffness * (K_t + S), with M the lumped mass,
// C = alpha M + beta K_t (Rayleigh, alpha/beta from each body's problem), K_t the tangent
// stiffness at the current positions (R K R^T summed over elements for the co-rotational
// formulation, K for the linear one, the consistent tangent for the hyperelastic ones) and S the
// diagonal of the application's springs (Problem::springStiffness; none: S = 0).
//
// Calls take a BodySet (indices into the device's bodies, strictly ascending) and one vector per
// body of the set, in the set's order, 3N entries each in the problem's own node numbering.
// Bodies outside the set keep their state. A device error (allocation, launch, read-back) throws
// Error(DeviceError) and fails the whole call; a caller's mistake (a wrong vector size) throws
// Error(Internal).
#pragma once

#include "model/problem.hpp"

#include <corofem/embed.hpp>
#include <corofem/gpu.hpp>
#include <corofem/scene.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

class DeviceSlot;
class StepStore;

struct SystemCoeffs {
  double mass = 0.0;
  double damping = 0.0;
  double stiffness = 1.0;
};

/// What one linear solve did.
struct LinearSolveStats {
  int iterations = 0;             ///< PCG iterations (0 for a direct solve)
  double relativeResidual = 0.0;  ///< |b - A x| / |b| on the free dofs (0 when b = 0)
  bool converged = false;
};

/// A device buffer a backend allocated: what it holds and its size at allocation.
struct DeviceBuffer {
  std::string name;
  std::size_t bytes = 0;
};

/// Where a device keeps a body's node positions on an OpenCL device (the device surface reads
/// them there: no host round trip). 3 reals per node, double when isDouble else float, those last
/// given to setPositions minus `centroid` (3 doubles), node n of the body at node firstNode + n of
/// `buffer`, or firstNode + deviceNode[n] where deviceNode is set. Valid while the device lives.
struct DevicePositions {
  ExternalDevice device;  ///< the context, the in-order queue that writes them, the device
  GpuBuffer buffer;       ///< the positions of every body of the device
  std::size_t firstNode = 0;
  bool isDouble = false;
  const double* centroid = nullptr;
  /// The device's index (from firstNode) of each of the body's nodes, where the device numbers them
  /// in an order of its own (a locality order); nullptr: node i is at i.
  const std::uint32_t* deviceNode = nullptr;
};

/// A count of something a device did, by name (the scheduler report's "device_counters").
struct DeviceCounter {
  std::string name;
  long long value = 0;
};

using BodySet = std::vector<std::size_t>;
using ConstVectors = std::vector<const Eigen::VectorXd*>;
using Vectors = std::vector<Eigen::VectorXd*>;

/// Why a body's PCG stopped (the same values as the kernels' kStop*).
enum class PcgStop : unsigned { Running = 0, Converged = 1, Breakdown = 2, NonFinite = 3 };

/// A body's PCG scalars as the device holds them: after the set-up, after any iteration, or after
/// the true residual (pcgEnd).
struct PcgScalars {
  int iterations = 0;   ///< iterations done
  double rr = 0.0;      ///< r . r on the free dofs (the recurrence's r, or b - A x after pcgEnd)
  double bb = 0.0;      ///< |free b|^2
  PcgStop stop = PcgStop::Running;
};

/// How a body enters a solve (pcgBegin).
enum class PcgStart {
  Running,      ///< set up; iterates until it stops
  ZeroRhs,      ///< |free b| = 0: answered x = 0 at once, no iteration
  NonFiniteRhs  ///< b holds NaN or Inf (or overflows the device precision): not solved
};

/// A pending non-blocking read of the PCG scalars (pcgRead).
using PcgTicket = std::size_t;

/// The render surfaces of some of a device's bodies (the coupled mesh, paper Sec. 5), updated on the
/// device from the device's own node positions: positions x_v = sum_k w_vk x_{n_vk} and smooth unit
/// normals, into buffers a renderer draws from (6 float32 per vertex interleaved, or two streams of
/// 3), the same values as deformSurface's to the device's precision.
class DeviceSurfaces {
 public:
  virtual ~DeviceSurfaces() = default;
  /// Enqueues the update of every member from the device's positions now (not waited for).
  virtual void update() = 0;
  /// Blocking read of member m's output as two streams of 3 floats per vertex.
  virtual void read(std::size_t member, float* positions, float* normals) = 0;
  /// Member m's output (positions alone with separate streams) and normals (separate streams only).
  virtual GpuBuffer vertexBuffer(std::size_t member) const = 0;
  virtual GpuBuffer normalBuffer(std::size_t member) const = 0;
  virtual bool separateStreams() const = 0;
  /// Waits for every update enqueued.
  virtual void finish() = 0;
  virtual std::vector<DeviceBuffer> buffers() const = 0;
};

/// One body's surface among a DeviceSurfaces' members.
struct SurfaceMember {
  std::size_t body = 0;
  const SurfaceBinding* binding = nullptr;  ///< bound to the body's mesh in the problem's numbering
};

class Device {
 public:
  virtual ~Device() = default;
  virtual std::string name() const = 0;        ///< the backend: "reference", "opencl"
  virtual std::string deviceName() const = 0;  ///< human-readable device
  virtual std::size_t bodyCount() const = 0;
  /// Body `body`'s problem (as given at creation; it outlives the device).
  virtual const Problem& problem(std::size_t body) const = 0;

  // -- element operations

  /// Sets the bodies' current positions and refreshes the per-element state that depends on them
  /// (rotations for the co-rotational formulation, F for the hyperelastic ones).
  virtual void setPositions(const BodySet& bodies, const ConstVectors& x) = 0;
  /// Internal forces at the current positions. Constrained dofs are not zeroed.
  virtual void internalForces(const BodySet& bodies, const Vectors& f) = 0;
  /// y = A p on all dofs (no projection of constraints), with each body's coefficients.
  virtual void apply(const BodySet& bodies, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& p,
                     const Vectors& y) = 0;
  /// Strain energy at the current positions (J), one per body of the set.
  virtual void elasticEnergy(const BodySet& bodies, std::vector<double>& energy) = 0;
  /// The bodies' constrained dofs changed (an application pinned, released or grabbed nodes):
  /// `constrained[i]` is body bodies[i]'s new mask, 3N entries in the problem's numbering, 1 where
  /// the dof is constrained. Later solves project with it. A device that cannot change its
  /// constraints throws Error(DeviceError) (the slot then moves the bodies to the next candidate).
  virtual void setConstraints(const BodySet& bodies, const std::vector<const std::vector<std::uint8_t>*>& constrained);
  /// The bodies' material changed (an application stiffened or damped a body): `problems[i]`
  /// carries body bodies[i]'s new Lame parameters and Rayleigh coefficients (nothing else of it is
  /// read). A device that cannot change them throws Error(DeviceError).
  virtual void setMaterial(const BodySet& bodies, const std::vector<const Problem*>& problems);
  /// The bodies' springs changed (an application attached or released a spring handle):
  /// `problems[i]->springStiffness` is body bodies[i]'s new S (nothing else of it is read). A
  /// device that cannot change them throws Error(DeviceError).
  virtual void setSprings(const BodySet& bodies, const std::vector<const Problem*>& problems);
  /// Drops body `body` (later bodies' indices move down by one) where the device can do so in
  /// place, the others keeping all they hold (the reference device: its bodies are independent);
  /// false, and nothing changed, where the slot must make a device for the others instead.
  virtual bool removeBody(std::size_t body) {
    (void)body;
    return false;
  }

  // -- PCG building blocks (driven by solvePcg, solve/pcg.hpp): the single-reduction PCG of
  // kernels/opencl/pcg.cl on the projected system (constrained dofs: identity rows and columns,
  // their entries of x kept at 0), preconditioned as the solver says. One solve at a time.

  /// The bodies of a solve in tiles that solvePcg solves one after another (a device whose cache
  /// holds a tile's working set but not the whole set's), or all at once.
  virtual std::vector<BodySet> pcgTiles(const BodySet& bodies) const { return {bodies}; }
  /// Starts the solve of A x = b for each body of the set (its coefficients), x its starting
  /// vector (constrained and non-finite entries taken as 0): r = b - A x, u = M^-1 r, w = A u and
  /// the first scalars, the convergence test included. Returns how each body entered. A null b[i]
  /// and x[i] (a device whose step store staged b and a zero x in the solve's own vectors, PcgSolve::
  /// resident) leave the body's b and x on the device, its b checked there.
  virtual std::vector<PcgStart> pcgBegin(const BodySet& bodies, const std::vector<SystemCoeffs>& coeffs,
                                         const ConstVectors& b, const ConstVectors& x, double tolerance,
                                         int maxIterations) = 0;
  /// Whether the device runs any number of iterations in one launch for this solve (the driver
  /// then asks for all it may run at once; the device still tests convergence after each).
  virtual bool pcgOneLaunch() const { return false; }
  /// Whether the scalars of the set-up can be read before the first pcgIterate (false: they come
  /// with the first read after it).
  virtual bool pcgSetupReadable() const { return true; }
  /// Enqueues `n` more iterations (never past maxIterations) for the bodies still running; a body
  /// the device has stopped costs nothing. `running`: per body of the set, whether the host still
  /// sees it running (the device may narrow its launches to those).
  virtual void pcgIterate(int n, const std::vector<char>& running) = 0;
  /// A non-blocking read of every body's scalars, in order after what was enqueued before it.
  virtual PcgTicket pcgRead() = 0;
  /// Waits for a read (tickets are taken in the order they were issued) and gives its scalars,
  /// one per body of the set.
  virtual void pcgTake(PcgTicket ticket, std::vector<PcgScalars>& scalars) = 0;
  /// Enqueues the true residual r = free (b - A x) for the bodies marked in `bodies` (per body of
  /// the set); pcgEnd gives its r . r. Called at most once per solve, after every iteration.
  virtual void pcgResidual(const std::vector<char>& bodies) = 0;
  /// Ends the solve: x of every running body read back (non-finite entries as the device holds
  /// them; none for a null x[i], whose x stays the device's), and for the bodies given to
  /// pcgResidual their true r . r and b . b in `residual`.
  /// `iterations`: what each body did (the device may plan its next solves with it). Pending reads
  /// are dropped.
  virtual void pcgEnd(const std::vector<int>& iterations, const Vectors& x, std::vector<PcgScalars>& residual) = 0;

  // -- a direct solve (the reference backend's sparse Cholesky)

  /// Whether solveDirect exists on this device.
  virtual bool hasDirectSolve() const { return false; }
  /// Solves A x = b on the free dofs of one body directly. Throws Error(BadInput) where there is none.
  virtual LinearSolveStats solveDirect(std::size_t body, const SystemCoeffs& coeffs, const Eigen::VectorXd& b,
                                       Eigen::VectorXd& x);

  // -- render surfaces

  /// The surfaces of `members` (bodies of this device) updated in one set of launches per update,
  /// each from its body's positions as last set; `separateStreams`: the output layout. Null where
  /// the device has none (the host computes the surfaces: deformSurface). Throws Error(DeviceError)
  /// where the device cannot hold them together (the caller may try them one by one).
  virtual std::unique_ptr<DeviceSurfaces> createSurfaces(const std::vector<SurfaceMember>& members,
                                                         bool separateStreams) {
    (void)members;
    (void)separateStreams;
    return nullptr;
  }

  // -- what it holds

  /// The device buffers it allocated, each at its allocated size (empty for host devices).
  virtual std::vector<DeviceBuffer> buffers() const { return {}; }
  /// What it did so far that the answers do not show, by name (the OpenCL backend: the PCG
  /// strategies a CPU device took, "pcg_group_launches", ...); empty by default.
  virtual std::vector<DeviceCounter> counters() const { return {}; }
  /// Fills `out` and returns true when the body's node positions live on an OpenCL device.
  virtual bool devicePositions(std::size_t body, DevicePositions& out) const {
    (void)body;
    (void)out;
    return false;
  }

  /// A store of the dynamics driver's vectors on this device for the slot's bodies (the slot holds
  /// this device), or null where the device keeps none (the driver keeps the host's store,
  /// createHostStepStore). The store outlives the device object: once the slot holds another
  /// device (a failover, a removed body), its calls go through the slot with host vectors, until
  /// the driver moves the state to a store of the new device.
  virtual std::unique_ptr<StepStore> createStepStore(DeviceSlot& slot);
};

/// The set {0, ..., n - 1}.
BodySet allBodies(std::size_t n);

/// The body's slenderness as preconditionerOf (corofem/scene.hpp) measures it: the longest extent L
/// of its rest bounding box over sqrt(V / L), V its rest volume; 0 for a body without volume.
double slendernessOf(const Problem& p);

/// The preconditioner `solver` gives this body (preconditionerOf, corofem/scene.hpp).
inline PreconditionerKind preconditionerOf(const SolverDesc& solver, const Problem& p) {
  if (solver.preconditioner != PreconditionerKind::Auto) return solver.preconditioner;
  return corofem::preconditionerOf(solver, p.mesh.tetCount(), slendernessOf(p), p.formulation);
}

/// `solver` with its preconditioner "auto" resolved for a device of these bodies
/// (preconditionerOf): Amg where every body would get it alone, else Diagonal. Every device and
/// slot resolves it so (a batch's bodies share one preconditioner).
inline SolverDesc resolvedSolver(SolverDesc solver, const std::vector<const Problem*>& problems) {
  if (solver.preconditioner != PreconditionerKind::Auto) return solver;
  PreconditionerKind kind = problems.empty() ? PreconditionerKind::Diagonal : PreconditionerKind::Amg;
  for (const Problem* p : problems)
    if (preconditionerOf(solver, *p) != PreconditionerKind::Amg)
      kind = PreconditionerKind::Diagonal;
  solver.preconditioner = kind;
  return solver;
}

}  // namespace corofem::detail
