// Simulation: a scene compiled for a backend, advanced step by step.
//
//   auto sim = corofem::Simulation::create(scene);      // Result<Simulation>
//   while (!sim->finished()) { corofem::StepReport r; if (!sim->step(&r)) ...; }
//   sim->readPositions(0, positions);                    // explicit read-back
#pragma once

#include <corofem/embed.hpp>
#include <corofem/gpu.hpp>
#include <corofem/log.hpp>
#include <corofem/mesh.hpp>
#include <corofem/scene.hpp>
#include <corofem/status.hpp>
#include <corofem/tuning.hpp>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace corofem {

/// Runs task(0), ..., task(count - 1), each exactly once, and returns when every one has returned.
/// The tasks are independent: they may run at once on any threads, in any order (an engine's job
/// system, a thread pool, or a plain loop). They do not throw. A task may use up to about 300 KiB
/// of stack (Eigen's sparse products in the multigrid's set-up keep their scratch there): give
/// fibers or job threads with smaller stacks only to plain loops.
using TaskRunner = std::function<void(std::size_t count, const std::function<void(std::size_t)>& task)>;

/// What one step (dynamics) or one load increment (statics) did, summed over bodies.
struct StepReport {
  int step = 0;                  ///< 1-based index of the step or increment just taken
  double time = 0.0;             ///< simulated time after the step (s); statics: the load factor
  int newtonIterations = 0;      ///< Newton iterations, summed over bodies
  int linearIterations = 0;      ///< PCG iterations, summed over bodies and Newton iterations
  double residual = 0.0;         ///< largest final relative Newton residual over bodies
  double linearResidual = 0.0;   ///< largest final relative PCG residual over bodies
  bool converged = true;         ///< every body's Newton (statics) / linear solves converged
  double wallSeconds = 0.0;      ///< wall time of the step
};

/// Energies of one body at the current state (J).
struct EnergyReport {
  double elastic = 0.0;  ///< strain energy of the formulation
  double kinetic = 0.0;  ///< 1/2 v^T M v with the lumped mass
  double externalWork = 0.0;  ///< work of the external loads since the start
};

/// What an application adds to a scene when it creates a Simulation.
struct SimulationOptions {
  LogDesc log;          ///< where the library's messages go (none: dropped)
  OpenCLTuning opencl;  ///< the OpenCL backend's kernels and strategies (automatic by default)
  VulkanTuning vulkan;  ///< the Vulkan backend's strategies (automatic by default)
  /// Where every body runs, in order of preference, each "<backend>" or "<backend>:<device>"
  /// ("opencl:1", "opencl:pthread", "reference", or a backend the application registered); a
  /// device that fails (at creation too) hands its bodies to the next, and the reference backend
  /// is always the last. Empty (the default): the scene's "backend" decides (scheduler).
  std::vector<std::string> devices;
  /// The application's own device (ExternalDevice: an OpenCL context, queue and device, or a
  /// Vulkan instance, physical device, device and queue): every body runs there, the reference
  /// backend its fallback (as devices = {"opencl:external"} or {"vulkan:external"}), and the
  /// surfaces' buffers (surfaceBuffer) live on it, for the application's renderer to draw from.
  /// None (the default): corofem makes its own.
  ExternalDevice device;
  /// Where the host's work between device calls runs (per-body passes over a batch's bodies, passes
  /// over large node vectors; on the reference backend its element passes, its PCG products and
  /// the "warped_cholesky" factor's two solves each PCG iteration): the application's task system.
  /// Empty (the default): a small pool of the library's own (COROFEM_HOST_THREADS threads). The
  /// Simulation calls it only from inside its own calls (create, step, reads), on the thread that
  /// made them.
  TaskRunner tasks;
  /// The largest mesh, surface and .bou files the Simulation reads and the largest boxes it
  /// generates (create, addBody, warmUp); InputLimits' defaults unless raised. The scene file's
  /// own limit is loadScene's.
  InputLimits inputLimits;
};

/// What a handle holds (Simulation::addHandle): nodes of one body that an application moves as
/// one, with a mouse drag or a VR controller.
struct HandleDesc {
  int body = 0;
  /// The body's nodes it holds (indices into restMesh(body)'s nodes). Empty: the nodes within
  /// `radius` of `point` at the body's current positions, or the node nearest `point` when none
  /// is that near.
  std::vector<std::uint32_t> nodes;
  double point[3] = {0.0, 0.0, 0.0};  ///< (m)
  double radius = 0.0;                ///< (m), >= 0
  /// >= 0 (with `nodes` empty): the render surface's vertex (restSurface(body)) the user picked; the
  /// handle holds the four nodes of the element the vertex is bound to (paper Sec. 5), and its
  /// target places the vertex itself (moveHandle's c is the vertex): the vertex follows it exactly.
  int surfaceVertex = -1;
  /// 0 (the default): a hard constraint, the held nodes follow the target exactly. > 0: a spring of
  /// this stiffness (N/m) that pulls the nodes towards the target and holds none of them: node k
  /// by a zero-length spring of stiffness `stiffness` w_k to its place target + R (g_k - c), w_k
  /// 1/n for n nodes or the surface vertex's barycentric weights (clamped to >= 0), so that the
  /// handle's whole force is stiffness times its stretch, the target minus where c is now. Springs
  /// are implicit (stable at any stiffness and time step) and undamped but for the integrator;
  /// pins and hard handles on the same nodes win.
  double stiffness = 0.0;
};

/// A force an application applies to a body (Simulation::setForces), in N: at a node, or at a
/// point spread over the four nodes of the element that contains it at the current positions (the
/// nearest element where none does) by its barycentric weights.
struct AppliedForce {
  int node = -1;                      ///< the node, or -1: at `point`
  double point[3] = {0.0, 0.0, 0.0};  ///< (m), with node = -1
  double force[3] = {0.0, 0.0, 0.0};  ///< (N)
};

/// One Simulation is used from one thread at a time: its reads (readSurface, surfaceBuffer,
/// energies, the reports) may update device state and must not run during step() on another
/// thread. Different Simulations may run on different threads. A moved-from Simulation may only be
/// assigned to or destroyed.
class Simulation {
 public:
  /// Loads meshes, builds the problem of every body and the backend. Errors: bad input (mesh,
  /// node set, material), not compiled in (backend), device error.
  static Result<Simulation> create(const Scene& scene, const SimulationOptions& options = {});

  Simulation(Simulation&&) noexcept;
  Simulation& operator=(Simulation&&) noexcept;
  ~Simulation();

  /// Advances one time step of the scene's analysis.time_step (dynamics) or one load increment
  /// (statics). When a solve fails, every body keeps its state before the step, the status says
  /// why (ErrorCode::SolveFailed), and the Simulation goes on: the next step starts the bodies
  /// that failed from their last good positions at rest (velocities zero).
  Status step(StepReport* report = nullptr);
  /// Advances one time step of dt seconds (dynamics only; an application's frame time). The same
  /// failure rules as step().
  Status step(double dt, StepReport* report = nullptr);
  bool finished() const;       ///< all steps / increments done (never, for an open-ended analysis)
  int stepsTaken() const;
  /// Steps (dynamics) or increments (statics) the analysis asks for; 0 for an open-ended dynamic
  /// analysis (analysis.steps = 0), which steps until the application stops.
  int stepCount() const;
  double time() const;         ///< simulated time (dynamics, s) or load factor (statics)

  // -- Run-time control (dynamic analyses; BadInput on a static one). Each takes effect at the
  // next step and lasts until changed. Node indices are those of restMesh(body).

  /// Grabs nodes of a body with a handle: a hard constraint (HandleDesc::stiffness 0), from the next
  /// step on the held nodes follow the handle's target exactly (their velocities follow from it),
  /// or a spring that pulls them towards it. Returns the handle's id (> 0). A node held by a newer
  /// hard handle or pin leaves the older one.
  Result<int> addHandle(const HandleDesc& handle);
  /// Makes a handle a spring of this stiffness (N/m, > 0) or a hard constraint (0) from the next
  /// step on; its target and rotation stay.
  Status setHandleStiffness(int handle, double stiffness);
  /// Moves a handle: each held node is placed at target + R (g - c) at the end of the next step,
  /// g its position when grabbed and c the centroid of those positions, R the row-major 3x3
  /// rotation (nullptr: none). The target is where c goes (m).
  Status moveHandle(int handle, const double target[3], const double* rotation = nullptr);
  /// Releases a handle's nodes: each goes back to what held it before the handle took it (the
  /// scene's support or its release, a pin at the node's position now, or an older handle).
  Status removeHandle(int handle);
  /// Pins nodes where they are now (3 dofs each) until unpinned.
  Status pinNodes(int body, const std::vector<std::uint32_t>& nodes);
  /// Frees nodes: pinned ones, and those the scene fixes or prescribes (released from the scene's
  /// supports). Nodes held by a handle stay held (removeHandle releases them).
  Status unpinNodes(int body, const std::vector<std::uint32_t>& nodes);
  /// Replaces the forces the application applies to a body (added to the scene's loads); an empty
  /// list removes them.
  Status setForces(int body, const std::vector<AppliedForce>& forces);
  /// Changes a body's material: Young's modulus (Pa, > 0), Poisson's ratio (-1 < nu < 0.5) and its
  /// Rayleigh damping C = alpha M + beta K (alpha 1/s, beta s, >= 0); its density stays.
  Status setMaterial(int body, double youngsModulus, double poissonRatio, double rayleighMass,
                     double rayleighStiffness);
  /// Adds a body to the live Simulation (its mesh, surface, material, supports and loads as a
  /// scene body's; paths relative to the scene's folder). It runs in a group of its own, on the
  /// device the scheduler gives it, from its rest state and its own time 0 (its loads' ramps start
  /// now): it steps as the same body does in a fresh Simulation. The other bodies keep their state
  /// and devices. Returns its index (bodyCount() - 1).
  Result<int> addBody(const BodyDesc& body);
  /// Removes a body with its handles and frees its device's memory; later bodies' indices move
  /// down by one. A body in a batch (sharing a device's buffers with others) leaves it: the batch's
  /// device is made again for the others, which keep their state (a cost of about a Simulation's
  /// creation for those bodies; the old device lives until the new one holds them, so both fit in
  /// memory at once; their surface buffers are new ones). DeviceError, with nothing changed, where
  /// the new device cannot be made; BadInput for the scene's last body.
  Status removeBody(int body);
  /// Replaces the gravity of every body (m/s^2; acts at once, no ramp).
  Status setGravity(const double gravity[3]);
  /// Sets a body's node positions (3 per node, m); its velocities stay. Nodes held by the scene or
  /// the application are moved back to their targets by the next step.
  Status setPositions(int body, const std::vector<double>& positions);
  /// Sets a body's velocities (3 per node, m/s; held dofs keep theirs at zero).
  Status setVelocities(int body, const std::vector<double>& velocities);
  /// Puts a body back at rest: rest positions, zero velocities (its handles, pins and forces stay).
  Status resetBody(int body);
  /// Moves a body rigidly: positions x -> R x + t, velocities v -> R v (R the row-major rotation,
  /// t in m), and its pins and handles with it. BadInput for a body the scene fixes or prescribes
  /// (unpin those nodes first) or an R that is not a rotation.
  Status teleport(int body, const double rotation[9], const double translation[3]);


  const Scene& scene() const;
  int bodyCount() const;
  const TetMesh& restMesh(int body) const;     ///< the body's mesh as loaded (rest positions)
  const MeshReadReport& meshReport(int body) const;
  Status readPositions(int body, std::vector<double>& out) const;   ///< 3 per node, current
  Status readVelocities(int body, std::vector<double>& out) const;  ///< 3 per node
  EnergyReport energies(int body) const;

  /// The body's render surface (BodyDesc::surface, moved by the mesh's scale and translate), bound
  /// once at create() to the body's tet mesh (paper Sec. 5); nullptr when the body has none.
  const SurfaceMesh* restSurface(int body) const;
  /// What the binding found (inside/outside vertices, largest distance); nullptr without a surface.
  const BindingStatistics* surfaceBinding(int body) const;
  /// The deformed surface at the current state: 3 doubles per vertex and, when `normals` is given,
  /// smooth unit normals (3 floats per vertex). BadInput for a body without a surface.
  ///
  /// On a body that runs on a device with surfaces (the OpenCL and Vulkan backends) the surface is computed on
  /// the device, from the device's own node positions (no host round trip of the tet nodes; see
  /// surfaceBuffer), and this call is the explicit read-back: the positions are then float-rounded
  /// (the device buffer holds floats). On the reference backend it is computed on the host
  /// (deformSurface).
  Status readSurface(int body, std::vector<double>& positions, std::vector<float>* normals = nullptr) const;
  /// The device buffer of the deformed surface when the body has a surface and runs on a device
  /// that computes it (GpuApi::OpenCL: the handle is a cl_mem; GpuApi::Vulkan: a VkBuffer made with
  /// vertex-buffer usage, to bind at `offset`, on the VkDevice the body runs on: drawable by the
  /// application when it lent that device, SimulationOptions::device), else an empty GpuBuffer (no
  /// surface, the reference backend, or an update that could not be enqueued). Layout
  /// (BodyDesc::surfaceLayout, scene key "surface_layout"): interleaved (the default), per vertex 6
  /// float32 -- position x, y, z then unit normal x, y, z -- a 24-byte stride; separate, the
  /// positions only, 3 float32 per vertex (a 12-byte stride), the normals in surfaceNormalBuffer().
  /// Vertices in the order of restSurface(body). On a batch (backend.batch) the surfaces of the
  /// batch's bodies with one layout are one set of buffers and launches: each body's buffer is its
  /// region of the shared output (OpenCL: a sub-buffer; Vulkan: the shared VkBuffer from `offset`),
  /// and bringing one body's surface up to date
  /// updates them all. The call enqueues the update on the device's in-order queue when the body
  /// stepped since the last one and does not wait: work the application enqueues on that queue
  /// afterwards (SimulationOptions::device) sees the current surface. On Vulkan the update is
  /// submitted to the device's queue and ends with a pipeline barrier from its compute writes to
  /// every read of every later command on that queue, so the application's later submissions to
  /// the queue it lent (SimulationOptions::device) draw the current surface with no semaphore or
  /// wait, and corofem's next update waits for them on the device. From another queue (of the same
  /// family on Vulkan) or API, call updateSurface() first, and finish reading before the next
  /// step's surface is asked for. The buffer belongs to the Simulation and stays valid until it is
  /// destroyed, the body moves to another device (a device failure) or its batch's device is made
  /// again (removeBody of another body of the batch); ask for it again after step() rather than
  /// caching it.
  GpuBuffer surfaceBuffer(int body) const;
  /// With "surface_layout": "separate", the device buffer of the surface's unit normals, 3 float32
  /// per vertex, updated together with surfaceBuffer() (the same rules); empty for the interleaved
  /// layout and wherever surfaceBuffer() is empty.
  GpuBuffer surfaceNormalBuffer(int body) const;
  /// Brings the device surface of `body` up to date and waits for it (explicit synchronisation:
  /// step() enqueues nothing for the surface; this or surfaceBuffer() does, lazily). Ok and
  /// nothing to do when the body's surface is computed on the host. BadInput for a body without a
  /// surface or an index out of range; DeviceError when the device fails.
  Status updateSurface(int body) const;
  std::string backendName() const;  ///< "reference", "opencl"
  std::string deviceName() const;   ///< e.g. "host (Eigen, double)" or the OpenCL device name

  /// Where the bodies run and why, as JSON text: {"choice", "reason", "candidates": [{"backend",
  /// "device", "ms_per_step", "from_cache", "error"}], "from_cache"} for the first body, the same
  /// per body under "bodies", and "fallbacks": [{"body", "when", "call", "from", "to", "error"}]
  /// for every device failure survived by moving a body to the next backend.
  std::string schedulerReport() const;
  /// The plan of the scene as JSON text (per body: backend, terms, kernels, buffers with their
  /// sizes, estimated bytes moved per step); see docs/scene-format.md, "Scheduling and plans".
  std::string planReport() const;

 private:
  Status stepWith(double h, StepReport* report);
  struct Impl;
  explicit Simulation(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Compiles and caches ahead of time what creating and stepping `scene` on this machine compiles
/// (the kernels of its plan on the devices it would run on, the scheduler's calibration for
/// "auto"), so that a later Simulation::create does not stall on a cold start: create() and one
/// step of a copy of the scene, discarded. A step that fails to converge is not an error here; the
/// scene's errors are (bad input, no device). `seconds`, when given, receives the time it took.
/// The cache lives in COROFEM_CACHE_DIR (else the user's cache folder); PoCL's kernels in PoCL's
/// own cache (POCL_CACHE_DIR, else ~/.cache/pocl). `corofem warmup` runs it.
Status warmUp(const Scene& scene, const SimulationOptions& options = {}, double* seconds = nullptr);

}  // namespace corofem
