// Simulation: the public object that owns every body's mesh, problem, backend and driver, and
// advances them together. Every public member converts exceptions to Status (util/error.hpp).
#include <corofem/simulation.hpp>

#include "embed/device_surface.hpp"
#include "model/problem.hpp"
#include "schedule/scheduler.hpp"
#include "scene/scene_paths.hpp"
#include "solve/backend.hpp"
#include "solve/batch_group.hpp"
#include "solve/body_solver.hpp"
#include "util/error.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <map>
#include <utility>

namespace corofem {

namespace {

/// Reads the body's surface, moves it like the mesh (scale, then translate) and binds it.
void attachSurface(const BodyDesc& desc, const std::string& baseDir, const TetMesh& mesh,
                   std::unique_ptr<SurfaceMesh>& surface, std::unique_ptr<SurfaceBinding>& binding) {
  const std::string path = scene::resolveScenePath(baseDir, desc.surface);
  Result<SurfaceMesh> read = readSurfaceMesh(path);
  if (!read) detail::fail(read.status().code(), "body '", desc.name, "': surface: ", read.message());
  SurfaceMesh s = std::move(read.value());
  for (std::size_t i = 0; i < s.vertices.size(); ++i)
    s.vertices[i] = s.vertices[i] * desc.mesh.scale + desc.mesh.translate[i % 3];
  Result<SurfaceBinding> bound = bindSurface(mesh, s);
  if (!bound)
    detail::fail(bound.status().code(), "body '", desc.name, "': binding the surface ", path,
                 " to the body's tet mesh: ", bound.message());
  surface = std::make_unique<SurfaceMesh>(std::move(s));
  binding = std::make_unique<SurfaceBinding>(std::move(bound.value()));
}

}  // namespace

struct Simulation::Impl {
  struct Body {
    TetMesh mesh;
    MeshReadReport report;
    // The problem is heap-held so that the backend and the driver, which keep references to it,
    // survive moves of the Body.
    std::unique_ptr<detail::Problem> problem;
    // The backend is a FailoverBackend over the scheduler's candidates (schedule/scheduler.hpp):
    // a device failure moves the body to the next candidate without the driver noticing.
    std::unique_ptr<detail::Backend> backend;
    detail::FailoverBackend* failover = nullptr;  ///< = backend.get()
    detail::BodySchedule schedule;
    std::unique_ptr<detail::BodySolver> solver;
    // Render surface bound to the tet mesh (paper Sec. 5), when the body names one.
    std::unique_ptr<SurfaceMesh> surface;
    std::unique_ptr<SurfaceBinding> binding;
    // Sleep (analysis.sleep): quiet steps so far, whether the body sleeps, and the loads and
    // prescribed positions it fell asleep under (the reference a change is measured against).
    struct Sleep {
      bool asleep = false;
      int quiet = 0;
      long long sleptSteps = 0, wakes = 0;
      Eigen::VectorXd fRef, xpRef;
    } sleep;
    // The surface on the device when the body's positions are on an OpenCL device (its own OpenCL
    // backend or its batch's): a DeviceSurface on that context and queue, fed from the position
    // buffer there (Backend::devicePositions; declared after the backend: destroyed first).
    // `deviceFor` is the backend it was made for and `deviceEvents` the failover events then (a
    // failover replaces the backend; a new one may reuse the address); `surfaceDirty`: the body
    // stepped since the last update.
    std::unique_ptr<DeviceSurface> deviceSurface;
    const detail::Backend* deviceFor = nullptr;
    std::size_t deviceEvents = 0;
    bool surfaceDirty = true;
    bool separateStreams = false;  ///< BodyDesc::surfaceLayout == Separate: positions and normals in two buffers
    // On an OpenCL batch the surface is its batch's: Batch::surfaces[surfaceGroup], member
    // surfaceMember (-1: none; the body's own surface, above, once it has left the batch).
    int surfaceGroup = -1, surfaceMember = -1;
    std::string surfaceGroupError;  ///< why its batch's surfaces could not be grouped (each has its own)
    // Batching: the group this body's first backend is a view of (index into Impl::batches), and
    // the body's index in that group; -1 = not batched.
    int batch = -1;
    std::size_t slot = 0;
  };

  /// Bodies scheduled on one device that share its buffers and launches (solve/batch_group.hpp).
  /// Each body's FailoverBackend starts on its view of the group; a device failure moves the body
  /// off the group to its next candidate.
  /// The render surfaces of a batch's bodies that share one output layout, updated in one set of
  /// launches from the batch's shared position buffer (embed/device_surface.hpp).
  struct SurfaceGroup {
    std::unique_ptr<detail::DeviceSurfaceGroup> surfaces;
    std::vector<std::size_t> bodies;  ///< scene body indices, in the group's member order
    bool dirty = true;                ///< a body stepped since the last update
  };
  struct Batch {
    std::unique_ptr<detail::BatchGroup> group;
    std::vector<std::size_t> bodies;  ///< scene body indices, in the group's order
    std::string candidate;            ///< the device's candidate label
    std::vector<SurfaceGroup> surfaces;  ///< declared after the group: destroyed first
  };
  /// A set of bodies that could have shared a device but runs unbatched, and why.
  struct Unbatched {
    std::vector<std::size_t> bodies;
    std::string candidate, reason;
  };

  Scene scene;
  detail::Log log;       ///< SimulationOptions::log; the drivers hold a reference
  OpenCLTuning opencl;   ///< SimulationOptions::opencl
  std::vector<Body> bodies;
  std::vector<Batch> batches;
  std::vector<Unbatched> unbatched;
  int stepsTaken = 0;

  // The drivers and views go first, then the groups (their workers and devices), then the
  // problems the devices were made over.
  ~Impl() {
    for (Body& b : bodies) {
      b.deviceSurface.reset();
      b.solver.reset();
      b.backend.reset();
    }
    batches.clear();
  }

  bool isStatic() const { return scene.analysis.kind == AnalysisDesc::Kind::Static; }
  int stepCount() const {
    return isStatic() ? std::max(1, scene.analysis.statics.increments) : std::max(1, scene.analysis.dynamics.steps);
  }
  /// One body's step, or its idle step while it sleeps (analysis.sleep, dynamics only).
  ///
  /// Quiet step: every free node slower than sleep.velocity after the step, and the loads steady
  /// over it: |f_ext(t1) - f_ext(t0)| <= loadChange |f_ext(t1)| and every prescribed target moved
  /// less than velocity * h. After sleep.steps quiet steps in a row the body sleeps: its steps are
  /// idle (positions held, velocities zero, time advancing) until f_ext drifts from the load it
  /// fell asleep under by more than loadChange (relative) or a prescribed target by more than
  /// velocity * h; then it wakes and takes that step normally.
  /// What sleeping changes: the motion left out is that of a body slower than `velocity`, so the
  /// positions differ from an awake run by at most about velocity x (time asleep) while the
  /// motion keeps decaying (tests/schedule/test_sleep.cpp measures it).
  detail::BodyStepStats stepBody(Body& b, int index, int count) {
    const SleepDesc& cfg = scene.analysis.dynamics.sleep;
    if (isStatic() || !cfg.enabled) return b.solver->step(index, count);
    const double h = scene.analysis.dynamics.timeStep;
    const double t0 = (index - 1) * h, t1 = index * h;
    const detail::Problem& p = *b.problem;
    const Eigen::VectorXd f1 = p.externalForce(t1, true);
    Eigen::VectorXd xp1 = p.restPositions;
    p.applyPrescribed(xp1, t1, true);
    auto* dyn = dynamic_cast<detail::DynamicSolver*>(b.solver.get());
    if (b.sleep.asleep && dyn) {
      const bool loadMoved = (f1 - b.sleep.fRef).norm() > cfg.loadChange * b.sleep.fRef.norm();
      const bool targetMoved = (xp1 - b.sleep.xpRef).cwiseAbs().maxCoeff() > cfg.velocity * h;
      if (!loadMoved && !targetMoved) {
        ++b.sleep.sleptSteps;
        return dyn->idleStep(index, count);
      }
      b.sleep.asleep = false;
      b.sleep.quiet = 0;
      ++b.sleep.wakes;
    }
    const detail::BodyStepStats stats = b.solver->step(index, count);
    const Eigen::VectorXd f0 = p.externalForce(t0, true);
    Eigen::VectorXd xp0 = p.restPositions;
    p.applyPrescribed(xp0, t0, true);
    const bool steady = (f1 - f0).norm() <= cfg.loadChange * f1.norm() &&
                        (xp1 - xp0).cwiseAbs().maxCoeff() <= cfg.velocity * h;
    const Eigen::VectorXd& v = b.solver->velocities();
    double maxSpeed = 0.0;
    for (Eigen::Index n = 0; n + 2 < v.size(); n += 3) {
      if (p.constrained[n] && p.constrained[n + 1] && p.constrained[n + 2]) continue;
      maxSpeed = std::max(maxSpeed, v.segment<3>(n).norm());
    }
    b.sleep.quiet = steady && maxSpeed < cfg.velocity ? b.sleep.quiet + 1 : 0;
    if (dyn && b.sleep.quiet >= std::max(1, cfg.steps)) {
      b.sleep.asleep = true;
      b.sleep.fRef = f1;
      b.sleep.xpRef = xp1;
    }
    return stats;
  }

  /// Groups the bodies that share a device's buffers and launches: two or more bodies whose first
  /// candidate is the same OpenCL device, with batching on (backend.batch). A body's render surface
  /// is updated on the device from its nodes in the batch's shared position buffer. Each gets a
  /// FailoverBackend that starts on its view of the group. A batch that cannot be made leaves its
  /// bodies unbatched (recorded with the reason), exactly as without batching.
  void formBatches() {
    if (!scene.backend.batch) return;
    const bool testing = detail::batchDeviceFactoryForTesting();
    std::map<std::string, std::vector<std::size_t>> byDevice;  // candidate label -> bodies, scene order
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      const detail::Candidate& c = bodies[i].schedule.choice();
      if (c.kind == BackendKind::OpenCL || testing) byDevice[c.label()].push_back(i);
    }
    for (const auto& [label, members] : byDevice) {
      if (members.size() < 2) continue;
      std::vector<const detail::Problem*> problems;
      for (std::size_t i : members) problems.push_back(bodies[i].problem.get());
      std::unique_ptr<detail::BatchDevice> device;
      try {
        device = detail::createBatchDeviceFor(problems, scene.solver, bodies[members.front()].schedule.choice().selector,
                                              opencl);
      } catch (const detail::Error& e) {
        unbatched.push_back({members, label, std::string(toString(e.code())) + ": " + e.what()});
        continue;
      } catch (const std::exception& e) {
        unbatched.push_back({members, label, e.what()});
        continue;
      }
      Batch batch;
      batch.group = std::make_unique<detail::BatchGroup>(std::move(device));
      batch.bodies = members;
      batch.candidate = label;
      for (std::size_t k = 0; k < members.size(); ++k) {
        Body& b = bodies[members[k]];
        auto failover = std::make_unique<detail::FailoverBackend>(*b.problem, scene.solver, b.schedule.order,
                                                                  batch.group->view(k), opencl);
        b.failover = failover.get();
        b.backend = std::move(failover);
        b.batch = static_cast<int>(batches.size());
        b.slot = k;
      }
      batches.push_back(std::move(batch));
    }
  }

  /// Per batch whose bodies' positions are on an OpenCL device, one DeviceSurfaceGroup per output
  /// layout for its bodies with render surfaces: their updates in one set of launches.
  void formSurfaceGroups() {
#ifdef COROFEM_WITH_OPENCL
    for (Batch& g : batches)
      for (bool separate : {false, true}) {
        SurfaceGroup sg;
        std::vector<detail::DeviceSurfaceGroup::Member> members;
        std::vector<std::unique_ptr<SurfaceBinding>> remapped;  // bindings in the device's numbering
        detail::DevicePositions where;
        std::size_t nodes = 0;
        for (std::size_t k = 0; k < g.bodies.size(); ++k) {
          Body& b = bodies[g.bodies[k]];
          if (!b.binding || b.separateStreams != separate || !g.group->devicePositions(k, where)) continue;
          sg.bodies.push_back(g.bodies[k]);
          remapped.emplace_back();
          members.push_back({&bindingOn(b, where, remapped.back()), where.firstNode});
          nodes = std::max(nodes, where.firstNode + b.binding->tetNodeCount);
        }
        if (members.empty()) continue;
        DeviceSurfaceOptions o;
        o.doublePrecision = where.isDouble;
        o.context = where.context;
        o.queue = where.queue;
        o.deviceId = where.device;
        o.separateStreams = separate;
        try {
          sg.surfaces = std::make_unique<detail::DeviceSurfaceGroup>(members, nodes, o);
        } catch (const detail::Error& e) {
          // The merged buffers hold every body's vertices and may exceed what the device allocates
          // at once: each body then keeps a surface of its own (made at create(), as unbatched).
          if (e.code() != ErrorCode::DeviceError) throw;
          for (std::size_t i : sg.bodies) bodies[i].surfaceGroupError = e.what();
          continue;
        }
        for (std::size_t m = 0; m < sg.bodies.size(); ++m) {
          bodies[sg.bodies[m]].surfaceGroup = static_cast<int>(g.surfaces.size());
          bodies[sg.bodies[m]].surfaceMember = static_cast<int>(m);
        }
        g.surfaces.push_back(std::move(sg));
      }
#endif
  }

  /// The surface group that updates body b's surface now, or nullptr: b is on an OpenCL batch with
  /// a surface and has not left it (a failover gives it a backend, and a surface, of its own).
  const SurfaceGroup* surfaceGroupOf(const Body& b) const {
    if (b.batch < 0 || b.surfaceGroup < 0) return nullptr;
    const Batch& g = batches[static_cast<std::size_t>(b.batch)];
    if (!g.group->attached(b.slot) || !b.failover->events().empty()) return nullptr;
    return &g.surfaces[static_cast<std::size_t>(b.surfaceGroup)];
  }
  SurfaceGroup* surfaceGroupOf(const Body& b) {
    return const_cast<SurfaceGroup*>(static_cast<const Impl*>(this)->surfaceGroupOf(b));
  }

  /// Brings every surface of the group up to date when a body stepped: each member still on the
  /// batch first makes its committed positions the backend's (syncBackendPositions; a device
  /// failure there moves that body off the batch), then one set of launches for all of them.
  /// Returns the group of body b, or nullptr when b no longer uses one.
  SurfaceGroup* refreshSurfaceGroup(Body& b) {
    SurfaceGroup* sg = surfaceGroupOf(b);
    if (!sg || !sg->dirty) return sg;
    const Batch& g = batches[static_cast<std::size_t>(b.batch)];
    for (std::size_t i : sg->bodies)
      if (surfaceGroupOf(bodies[i])) bodies[i].solver->syncBackendPositions();
    sg = surfaceGroupOf(b);
    if (!sg) return nullptr;
    std::vector<const double*> centroids;
    detail::DevicePositions where;
    for (std::size_t i : sg->bodies) {
      if (!g.group->devicePositions(bodies[i].slot, where)) detail::fail(ErrorCode::Internal, "batch without device positions");
      centroids.push_back(where.centroid);
    }
    sg->surfaces->update(where.buffer, centroids);
    sg->dirty = false;
    return sg;
  }

  /// JSON of the body's batch: {"group", "device", "bodies": [names], "active"} (active: the body
  /// still runs on its view; false after a failover), or null when it is not batched.
  nlohmann::json batchJson(const Body& b) const {
    if (b.batch < 0) return nullptr;
    const Batch& g = batches[static_cast<std::size_t>(b.batch)];
    nlohmann::json names = nlohmann::json::array();
    for (std::size_t i : g.bodies) names.push_back(scene.bodies[i].name);
    return {{"group", b.batch}, {"device", g.candidate}, {"bodies", names}, {"active", g.group->attached(b.slot)}};
  }

  /// [{"name", "bytes"}] of device buffers.
  static nlohmann::json buffersJson(const std::vector<detail::DeviceBuffer>& buffers) {
    nlohmann::json out = nlohmann::json::array();
    for (const detail::DeviceBuffer& d : buffers) out.push_back({{"name", d.name}, {"bytes", d.bytes}});
    return out;
  }

  /// The render surface of a body in the plan: where it is updated, its layout, and on the device
  /// the buffers its DeviceSurface allocated (not counted in the backend's device_buffers_allocated).
  nlohmann::json surfacePlanJson(const Body& b) const {
    nlohmann::json j;
    j["vertices"] = b.binding->vertexCount();
    j["triangles"] = b.surface->triangleCount();
    // The surface updating the body now: its batch's group, or the one made for the backend the
    // body runs on now (after a failover it is remade lazily).
    const SurfaceGroup* sg = surfaceGroupOf(b);
    const DeviceSurface* d = !sg && deviceSurfaceCurrent(b) ? b.deviceSurface.get() : nullptr;
    j["where"] = sg || d ? "device" : "host";
    if (sg || d) {
      const bool separate = sg ? sg->surfaces->separateStreams() : d->separateStreams();
      j["layout"] = separate ? "separate" : "interleaved";
      j["output"] = separate ? "two buffers of 3 float32 per vertex: positions (surfaceDeviceBuffer), normals "
                               "(surfaceNormalDeviceBuffer)"
                             : "one buffer of 6 float32 per vertex: position, normal (surfaceDeviceBuffer)";
      nlohmann::json buffers = nlohmann::json::array();
      for (const DeviceSurfaceBuffer& x : sg ? sg->surfaces->buffers() : d->buffers())
        buffers.push_back({{"name", x.name}, {"bytes", x.bytes}});
      j["device_buffers_allocated"] = buffers;
      j["device_bytes_allocated"] = sg ? sg->surfaces->allocatedBytes() : d->allocatedBytes();
      if (sg) {  // one set of buffers and launches for the batch's surfaces of this layout
        nlohmann::json names = nlohmann::json::array();
        for (std::size_t i : sg->bodies)
          if (surfaceGroupOf(bodies[i])) names.push_back(scene.bodies[i].name);  // not those that left
        j["shared_by"] = names;
      } else if (!b.surfaceGroupError.empty()) {
        j["not_shared"] = b.surfaceGroupError;
      }
    } else {
      j["output"] = "host arrays on request (readSurface; the layout applies to device buffers only)";
    }
    return j;
  }

  /// The groups: [{"device", "bodies", "active_bodies", "rounds", "requests", "largest_round",
  /// "device_seconds", "rounds_by_call", "allocated_bytes", "buffers"}], and [{"device", "bodies", "reason"}] for bodies
  /// left unbatched.
  nlohmann::json batchesJson() const {
    nlohmann::json out = nlohmann::json::array();
    for (const Batch& g : batches) {
      nlohmann::json names = nlohmann::json::array(), active = nlohmann::json::array();
      for (std::size_t k = 0; k < g.bodies.size(); ++k) {
        names.push_back(scene.bodies[g.bodies[k]].name);
        if (g.group->attached(k)) active.push_back(scene.bodies[g.bodies[k]].name);
      }
      const detail::BatchGroupStats st = g.group->stats();
      nlohmann::json byCall = nlohmann::json::object();
      for (std::size_t i = 0; i <= detail::BatchGroupStats::kMixedCalls; ++i)
        if (const detail::BatchCallStats& c = st.byCall[i]; c.rounds > 0)
          byCall[detail::batchCallName(i)] = {{"rounds", c.rounds}, {"requests", c.requests},
                                              {"device_seconds", c.deviceSeconds}, {"wait_seconds", c.waitSeconds}};
      out.push_back({{"device", g.candidate}, {"backend", g.group->name()}, {"bodies", names},
                     {"active_bodies", active}, {"rounds", st.rounds}, {"requests", st.requests},
                     {"largest_round", st.largestRound}, {"device_seconds", st.deviceSeconds},
                     {"rounds_by_call", byCall},
                     {"allocated_bytes", g.group->allocatedBytes()},
                     {"buffers", buffersJson(g.group->deviceBuffers())}});
    }
    return out;
  }
  nlohmann::json unbatchedJson() const {
    nlohmann::json out = nlohmann::json::array();
    for (const Unbatched& u : unbatched) {
      nlohmann::json names = nlohmann::json::array();
      for (std::size_t i : u.bodies) names.push_back(scene.bodies[i].name);
      out.push_back({{"device", u.candidate}, {"bodies", names}, {"reason", u.reason}});
    }
    return out;
  }

  /// The backend the body runs on now when its node positions live on an OpenCL device (its own
  /// OpenCL backend or its view of an OpenCL batch), with where they are; else nullptr.
  static const detail::Backend* deviceBackend(const Body& b, detail::DevicePositions& where) {
    const detail::Backend* active = b.failover->active();
    return active && active->devicePositions(where) ? active : nullptr;
  }

  /// The binding the device surface reads the body's positions with: b.binding, or where the device
  /// numbers the nodes in an order of its own (the OpenCL backend's locality order), a copy in that
  /// numbering made in `holder` (the device surfaces copy what they need at creation).
  static const SurfaceBinding& bindingOn(const Body& b, const detail::DevicePositions& where,
                                         std::unique_ptr<SurfaceBinding>& holder) {
    if (!where.deviceNode) return *b.binding;
    holder = std::make_unique<SurfaceBinding>(*b.binding);
    for (std::uint32_t& n : holder->nodes) n = where.deviceNode[n];
    return *holder;
  }

  /// Whether b.deviceSurface was made for the backend the body runs on now (a failover replaces
  /// the backend, and a new one may reuse the address: the event count tells them apart).
  static bool deviceSurfaceCurrent(const Body& b) {
    detail::DevicePositions where;
    return b.deviceSurface && deviceBackend(b, where) == b.deviceFor && b.failover->events().size() == b.deviceEvents;
  }

  /// Makes b.deviceSurface match the backend the body runs on now: created on the context and queue
  /// (adopted) that hold the body's node positions, in their precision, dropped on a host backend.
  /// Returns it, or nullptr when the surface is computed on the host.
  static DeviceSurface* deviceSurfaceOf(Body& b) {
#ifdef COROFEM_WITH_OPENCL
    if (!b.binding) return nullptr;
    detail::DevicePositions where;
    const detail::Backend* device = deviceBackend(b, where);
    if (device != b.deviceFor || b.failover->events().size() != b.deviceEvents) {
      b.deviceSurface.reset();
      b.deviceFor = nullptr;
      b.deviceEvents = b.failover->events().size();
      b.surfaceDirty = true;
      if (device) {
        DeviceSurfaceOptions o;
        o.doublePrecision = where.isDouble;
        o.context = where.context;
        o.queue = where.queue;
        o.deviceId = where.device;
        o.separateStreams = b.separateStreams;
        std::unique_ptr<SurfaceBinding> remapped;
        Result<DeviceSurface> made = DeviceSurface::create(bindingOn(b, where, remapped), o);
        if (!made) detail::fail(made.status().code(), "the body's surface on the OpenCL device: ", made.message());
        b.deviceSurface = std::make_unique<DeviceSurface>(std::move(made.value()));
        b.deviceFor = device;
      }
    }
    return b.deviceSurface.get();
#else
    (void)b;
    return nullptr;
#endif
  }

  /// Enqueues the device surface update when the body stepped since the last one: the backend's
  /// positions are first made the committed ones (a driver may have left trial positions there),
  /// then the kernels read the backend's centroid-relative position buffer and add the centroid.
  /// Returns the device surface (nullptr on the host path).
  static DeviceSurface* refreshDeviceSurface(Body& b) {
    DeviceSurface* d = deviceSurfaceOf(b);
#ifdef COROFEM_WITH_OPENCL
    if (!d || !b.surfaceDirty) return d;
    b.solver->syncBackendPositions();
    // A device failure inside syncBackendPositions moves the body to another backend.
    d = deviceSurfaceOf(b);
    if (!d) return nullptr;
    detail::DevicePositions where;
    deviceBackend(b, where);
    Status st = d->updateFromDevice(where.buffer, where.centroid, where.firstNode);
    if (!st) throw detail::Error(st.code(), st.message());
    b.surfaceDirty = false;
#endif
    return d;
  }

  /// Body b's surface on the device, up to date (enqueued): its member of the batch's group, or its
  /// own DeviceSurface; neither on the host path (false).
  struct OnDevice {
    SurfaceGroup* group = nullptr;
    std::size_t member = 0;
    DeviceSurface* own = nullptr;
    explicit operator bool() const { return group || own; }
    _cl_mem* vertexBuffer() const { return group ? group->surfaces->vertexBuffer(member) : own->vertexBuffer(); }
    _cl_mem* normalBuffer() const { return group ? group->surfaces->normalBuffer(member) : own->normalBuffer(); }
    /// Blocking read as two streams of 3 floats per vertex.
    void read(float* positions, float* normals) const {
      if (group) return group->surfaces->read(member, positions, normals);
      const Status st = own->read(positions, normals);
      if (!st) throw detail::Error(st.code(), st.message());
    }
    void finish() const {
      if (group) return group->surfaces->finish();
      const Status st = own->finish();
      if (!st) throw detail::Error(st.code(), st.message());
    }
  };
  OnDevice refreshOnDevice(Body& b) {
    OnDevice d;
    if ((d.group = refreshSurfaceGroup(b))) d.member = static_cast<std::size_t>(b.surfaceMember);
    else d.own = refreshDeviceSurface(b);
    return d;
  }

  Body& bodyForSurface(int index) {
    if (index < 0 || index >= static_cast<int>(bodies.size()))
      detail::fail(ErrorCode::BadInput, "body index ", index, " is out of range: the scene has ", bodies.size(),
                   " body(ies), numbered from 0");
    Body& b = bodies[static_cast<std::size_t>(index)];
    if (!b.binding)
      detail::fail(ErrorCode::BadInput, "body '", scene.bodies[static_cast<std::size_t>(index)].name,
                   "' has no surface; give it one with \"surface\": \"file.obj\" in the scene");
    return b;
  }

  const Body& body(int index) const {
    if (index < 0 || index >= static_cast<int>(bodies.size()))
      detail::fail(ErrorCode::BadInput, "body index ", index, " is out of range: the scene has ", bodies.size(),
                   " body(ies), numbered from 0");
    return bodies[static_cast<std::size_t>(index)];
  }
};

Result<Simulation> Simulation::create(const Scene& scene, const SimulationOptions& options) {
  return detail::guardResult<Simulation>([&]() {
    auto impl = std::make_unique<Impl>();
    impl->scene = scene;
    impl->log = detail::Log(options.log);
    impl->opencl = options.opencl;
    if (scene.bodies.empty())
      detail::fail(ErrorCode::BadInput, "scene '", scene.name, "' has no bodies; add at least one to \"bodies\"");
    for (const BodyDesc& desc : scene.bodies) {
      Impl::Body body;
      Result<TetMesh> mesh = loadBodyMesh(desc, scene.baseDir, &body.report);
      if (!mesh) throw detail::Error(mesh.status().code(), mesh.message());
      body.mesh = std::move(mesh.value());
      if (!desc.surface.empty()) attachSurface(desc, scene.baseDir, body.mesh, body.surface, body.binding);
      body.separateStreams = desc.surfaceLayout == SurfaceLayout::Separate;
      body.problem = std::make_unique<detail::Problem>(detail::buildProblem(desc, body.mesh, scene.solver, scene.baseDir));
      // A static analysis never uses the mass (statics solve K_t du = r; gravity is rho g V / 4 per
      // node, built from the density above): zero, the device backends allocate no mass buffer.
      if (scene.analysis.kind == AnalysisDesc::Kind::Static) body.problem->lumpedMass.setZero();

      // Where the body runs: the explicit choice (scene / API, else COROFEM_DEVICE), or for "auto"
      // the scheduler's calibrated (or cached) choice; hyperelastic bodies always on the reference.
      body.schedule = detail::scheduleBody(desc, *body.problem, scene, impl->opencl);
      impl->bodies.push_back(std::move(body));
    }
    impl->formBatches();
    impl->formSurfaceGroups();
    for (Impl::Body& body : impl->bodies) {
      if (body.batch < 0) {
        auto failover = std::make_unique<detail::FailoverBackend>(*body.problem, scene.solver, body.schedule.order,
                                                                  !body.schedule.explicitChoice, impl->opencl);
        body.failover = failover.get();
        body.backend = std::move(failover);
      }
      body.solver = detail::createBodySolver(*body.problem, *body.backend, scene.analysis, impl->log);
      // On an OpenCL backend: the surface's buffers and kernels now (a batch's: formSurfaceGroups).
      if (!impl->surfaceGroupOf(body)) Impl::deviceSurfaceOf(body);
    }
    return Simulation(std::move(impl));
  });
}

Simulation::Simulation(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Simulation::Simulation(Simulation&&) noexcept = default;
Simulation& Simulation::operator=(Simulation&&) noexcept = default;
Simulation::~Simulation() = default;

Status Simulation::step(StepReport* report) {
  const auto start = std::chrono::steady_clock::now();
  StepReport r;
  Status status = detail::guard([&] {
    Impl& s = *impl_;
    const int count = s.stepCount();
    if (s.stepsTaken >= count)
      detail::fail(ErrorCode::BadInput, "the analysis is finished (", count,
                   " steps taken); check finished() before step()");
    const int index = s.stepsTaken + 1;
    for (Impl::Body& b : s.bodies) b.surfaceDirty = true;  // recomputed lazily (readSurface, surfaceDeviceBuffer)
    for (Impl::Batch& g : s.batches)
      for (Impl::SurfaceGroup& sg : g.surfaces) sg.dirty = true;
    const std::size_t n = s.bodies.size();
    std::vector<Impl::Body::Sleep> sleepBefore;
    for (const Impl::Body& b : s.bodies) sleepBefore.push_back(b.sleep);
    for (Impl::Body& b : s.bodies) b.failover->setWhen("step " + std::to_string(index));
    // Each body's step is independent of the others', so their order does not change any answer:
    // the batched bodies run concurrently, each as a fiber of its group's worker threads (their
    // Backend calls meet in the group's rounds), while the others step in scene order on this thread.
    std::vector<detail::BodyStepStats> stats(n);
    std::vector<char> completed(n, 0);
    std::vector<std::exception_ptr> errors(n);
    std::size_t started = 0;  // groups whose workers run now (they use this frame's vectors)
    try {
      for (Impl::Batch& g : s.batches) {
        std::vector<std::size_t> slots(g.bodies.size());
        for (std::size_t k = 0; k < slots.size(); ++k) slots[k] = k;
        g.group->startStep(slots, [&s, &g, &stats, &completed, index, count](std::size_t k) {
          const std::size_t i = g.bodies[k];
          stats[i] = s.stepBody(s.bodies[i], index, count);
          completed[i] = 1;
        });
        ++started;
      }
    } catch (...) {
      // A group that could not start (no thread): wait for those that did, undo them, report it.
      for (std::size_t k = 0; k < started; ++k) s.batches[k].group->finishStep();
      for (std::size_t b = 0; b < n; ++b)
        if (completed[b]) s.bodies[b].solver->rollback();
      for (std::size_t b = 0; b < n; ++b) s.bodies[b].sleep = sleepBefore[b];
      throw;
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (s.bodies[i].batch >= 0) continue;
      try {
        stats[i] = s.stepBody(s.bodies[i], index, count);
        completed[i] = 1;
      } catch (...) {
        // The other bodies still take their step (and go back with the scene below), as the
        // batched bodies do: every body's backend then sees the same sequence of calls whether it
        // is batched or not, so stateful backends (the quaternion method's warm start) give the
        // same bits either way.
        errors[i] = std::current_exception();
      }
    }
    for (Impl::Batch& g : s.batches) {
      const std::vector<std::exception_ptr> e = g.group->finishStep();
      for (std::size_t k = 0; k < e.size(); ++k)
        if (e[k]) errors[g.bodies[k]] = e[k];
    }
    // The report sums the bodies in scene order, up to the first one that failed.
    std::size_t failed = n;
    for (std::size_t i = 0; i < n && failed == n; ++i)
      if (errors[i]) failed = i;
    for (std::size_t i = 0; i < failed; ++i) {
      const detail::BodyStepStats& b = stats[i];
      r.newtonIterations += b.newtonIterations;
      r.linearIterations += b.linearIterations;
      r.residual = std::max(r.residual, b.residual);
      r.linearResidual = std::max(r.linearResidual, b.linearResidual);
      r.converged = r.converged && b.converged;
    }
    if (failed < n) {
      // A failing body restored itself; the bodies that completed the step go back one step so
      // that the whole scene stays at the last step every body completed. The error is that of
      // the first failing body in scene order.
      for (std::size_t b = 0; b < n; ++b)
        if (completed[b]) s.bodies[b].solver->rollback();
      for (std::size_t b = 0; b < n; ++b) s.bodies[b].sleep = sleepBefore[b];
      std::rethrow_exception(errors[failed]);
    }
    s.stepsTaken = index;
    r.step = index;
  });
  r.time = time();
  if (!status) r.converged = false;
  r.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (report) *report = r;
  return status;
}

bool Simulation::finished() const { return impl_->stepsTaken >= impl_->stepCount(); }
int Simulation::stepsTaken() const { return impl_->stepsTaken; }
int Simulation::stepCount() const { return impl_->stepCount(); }

double Simulation::time() const {
  if (impl_->isStatic()) return static_cast<double>(impl_->stepsTaken) / impl_->stepCount();
  return impl_->stepsTaken * impl_->scene.analysis.dynamics.timeStep;
}

const Scene& Simulation::scene() const { return impl_->scene; }
int Simulation::bodyCount() const { return static_cast<int>(impl_->bodies.size()); }
const TetMesh& Simulation::restMesh(int body) const { assert(body >= 0 && body < bodyCount());  // a reference cannot carry a status
  return impl_->bodies[static_cast<std::size_t>(body)].mesh; }
const MeshReadReport& Simulation::meshReport(int body) const {
  assert(body >= 0 && body < bodyCount());
  return impl_->bodies[static_cast<std::size_t>(body)].report;
}

Status Simulation::readPositions(int body, std::vector<double>& out) const {
  return detail::guard([&] {
    const Eigen::VectorXd& x = impl_->body(body).solver->positions();
    out.assign(x.data(), x.data() + x.size());
  });
}

Status Simulation::readVelocities(int body, std::vector<double>& out) const {
  return detail::guard([&] {
    const Eigen::VectorXd& v = impl_->body(body).solver->velocities();
    out.assign(v.data(), v.data() + v.size());
  });
}

EnergyReport Simulation::energies(int body) const {
  EnergyReport e;
  if (body < 0 || body >= bodyCount()) return e;
  detail::BodySolver& solver = *impl_->bodies[static_cast<std::size_t>(body)].solver;
  e.kinetic = solver.kineticEnergy();
  e.externalWork = solver.externalWork();
  Status st = detail::guard([&] { e.elastic = solver.elasticEnergy(); });
  if (!st) e.elastic = std::nan("");  // a backend failure here has no other channel; NaN marks it
  return e;
}

const SurfaceMesh* Simulation::restSurface(int body) const {
  if (body < 0 || body >= bodyCount()) return nullptr;
  return impl_->bodies[static_cast<std::size_t>(body)].surface.get();
}

const BindingStatistics* Simulation::surfaceBinding(int body) const {
  if (body < 0 || body >= bodyCount()) return nullptr;
  const auto& b = impl_->bodies[static_cast<std::size_t>(body)];
  return b.binding ? &b.binding->statistics : nullptr;
}

Status Simulation::readSurface(int body, std::vector<double>& positions, std::vector<float>* normals) const {
  return detail::guard([&] {
    Impl::Body& b = impl_->bodyForSurface(body);
    const std::size_t n = b.binding->vertexCount();
    if (const Impl::OnDevice d = impl_->refreshOnDevice(b)) {
      // Explicit read-back of the device buffer(s), as two streams of 3 floats per vertex.
      std::vector<float> p(3 * n), m(3 * n);
      d.read(p.data(), m.data());
      positions.assign(p.begin(), p.end());
      if (normals) *normals = std::move(m);
      return;
    }
    const Eigen::VectorXd& x = b.solver->positions();
    SurfaceOutput out;
    positions.resize(3 * b.binding->vertexCount());
    out.positionsDouble = positions.data();
    if (normals) {
      normals->resize(3 * b.binding->vertexCount());
      out.normals = normals->data();
    }
    Status st = deformSurface(*b.binding, x.data(), b.mesh.nodeCount(), out);
    if (!st) throw detail::Error(st.code(), st.message());
  });
}

_cl_mem* Simulation::surfaceDeviceBuffer(int body) const {
  _cl_mem* buffer = nullptr;
  const Status st = detail::guard([&] {
    if (body < 0 || body >= bodyCount()) return;
    Impl::Body& b = impl_->bodies[static_cast<std::size_t>(body)];
    if (!b.binding) return;
    if (const Impl::OnDevice d = impl_->refreshOnDevice(b)) buffer = d.vertexBuffer();
  });
  return st ? buffer : nullptr;
}

_cl_mem* Simulation::surfaceNormalDeviceBuffer(int body) const {
  _cl_mem* buffer = nullptr;
  const Status st = detail::guard([&] {
    if (body < 0 || body >= bodyCount()) return;
    Impl::Body& b = impl_->bodies[static_cast<std::size_t>(body)];
    if (!b.binding || !b.separateStreams) return;
    if (const Impl::OnDevice d = impl_->refreshOnDevice(b)) buffer = d.normalBuffer();
  });
  return st ? buffer : nullptr;
}

Status Simulation::updateSurface(int body) const {
  return detail::guard([&] {
    Impl::Body& b = impl_->bodyForSurface(body);
    if (const Impl::OnDevice d = impl_->refreshOnDevice(b)) d.finish();
  });
}

// The first body's backend as it is now (a failover changes it).
std::string Simulation::backendName() const { return impl_->bodies.front().backend->name(); }
std::string Simulation::deviceName() const { return impl_->bodies.front().backend->deviceName(); }

std::string Simulation::schedulerReport() const {
  using nlohmann::json;
  json j;
  json bodies = json::array(), fallbacks = json::array();
  for (const Impl::Body& b : impl_->bodies) {
    json s = json::parse(detail::scheduleJson(b.schedule));
    s["current"] = b.failover->current().label();
    if (impl_->scene.analysis.dynamics.sleep.enabled && !impl_->isStatic())
      s["sleep"] = {{"asleep", b.sleep.asleep}, {"slept_steps", b.sleep.sleptSteps}, {"wakes", b.sleep.wakes}};
    s["batch"] = impl_->batchJson(b);
    bodies.push_back(s);
    for (const detail::FallbackEvent& e : b.failover->events()) fallbacks.push_back(json::parse(detail::fallbackJson(e)));
  }
  // The top level repeats the first body's decision (the whole scene for a one-body scene).
  const json& first = bodies.front();
  j["choice"] = first["choice"];
  j["reason"] = first["reason"];
  j["candidates"] = first["candidates"];
  j["from_cache"] = first["from_cache"];
  j["bodies"] = bodies;
  j["fallbacks"] = fallbacks;
  // Bodies that share a device's buffers and launches, and those that could have but run alone.
  j["batches"] = impl_->batchesJson();
  j["unbatched"] = impl_->unbatchedJson();
  return j.dump();
}

std::string Simulation::planReport() const {
  using nlohmann::json;
  json j;
  j["scene"] = impl_->scene.name;
  j["analysis"] = impl_->isStatic() ? "static" : "dynamic";
  j["steps"] = impl_->stepCount();
  json bodies = json::array();
  for (std::size_t i = 0; i < impl_->bodies.size(); ++i) {
    const Impl::Body& b = impl_->bodies[i];
    detail::BodySchedule now = b.schedule;  // after a fallback at create, the backend in use
    now.order.insert(now.order.begin(), b.failover->current());
    std::vector<std::string> mates;
    if (b.batch >= 0) {  // the bodies still on the batch (a failover takes a body off it)
      const Impl::Batch& g = impl_->batches[static_cast<std::size_t>(b.batch)];
      if (g.group->attached(b.slot))
        for (std::size_t k = 0; k < g.bodies.size(); ++k)
          if (g.group->attached(k)) mates.push_back(impl_->scene.bodies[g.bodies[k]].name);
    }
    json body = json::parse(detail::planJson(impl_->scene.bodies[i], *b.problem, impl_->scene, now, mates));
    // What the body's own device backend allocated, buffer by buffer (the estimate above is the
    // model; a batched body's buffers are the batch's, listed under "batches").
    const std::vector<detail::DeviceBuffer> allocated = b.backend->deviceBuffers();
    if (!allocated.empty()) {
      body["device_buffers_allocated"] = Impl::buffersJson(allocated);
      std::size_t total = 0;
      for (const detail::DeviceBuffer& d : allocated) total += d.bytes;
      body["device_bytes_allocated"] = total;
    }
    // Where the body's node positions live on an OpenCL device: in the mesh's numbering, or in the
    // device's own locality order (mesh/locality_order.hpp; the host's vectors keep the mesh's).
    detail::DevicePositions where;
    if (Impl::deviceBackend(b, where)) body["device_numbering"] = where.deviceNode ? "morton" : "mesh";
    if (b.binding) body["surface"] = impl_->surfacePlanJson(b);
    bodies.push_back(body);
  }
  j["bodies"] = bodies;
  j["batches"] = impl_->batchesJson();
  j["unbatched"] = impl_->unbatchedJson();
  return j.dump();
}

}  // namespace corofem
