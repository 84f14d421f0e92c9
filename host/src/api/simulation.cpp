// Simulation: the public object that owns every body's mesh, problem and schedule, the devices the
// bodies run on and the drivers that step them, and advances them together. Every public member
// converts exceptions to Status (util/error.hpp).
#include "api/simulation_impl.hpp"

#include "scene/scene_paths.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <map>
#include <sstream>
#include <utility>

namespace corofem {

namespace {

/// Reads the body's surface, moves it like the mesh (scale, then translate) and binds it.
void attachSurface(const BodyDesc& desc, const std::string& baseDir, const InputLimits& limits, const TetMesh& mesh,
                   std::unique_ptr<SurfaceMesh>& surface, std::unique_ptr<SurfaceBinding>& binding) {
  const std::string path = scene::resolveScenePath(baseDir, desc.surface);
  Result<SurfaceMesh> read = readSurfaceMesh(path, nullptr, limits);
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

const Simulation::Impl::Body& Simulation::Impl::body(int index) const {
  if (index < 0 || index >= static_cast<int>(bodies.size()))
    detail::fail(ErrorCode::BadInput, "body index ", index, " is out of range: the scene has ", bodies.size(),
                 " body(ies), numbered from 0");
  return bodies[static_cast<std::size_t>(index)];
}

Simulation::Impl::Body& Simulation::Impl::bodyForSurface(int index) {
  Body& b = const_cast<Body&>(body(index));
  if (!b.binding)
    detail::fail(ErrorCode::BadInput, "body '", scene.bodies[static_cast<std::size_t>(index)].name,
                 "' has no surface; give it one with \"surface\": \"file.obj\" in the scene");
  return b;
}

void Simulation::Impl::makeGroup(std::vector<std::size_t> members, bool batch) {
  Group g;
  g.bodies = std::move(members);
  g.batch = batch;
  const Body& first = bodies[g.bodies.front()];
  g.candidate = first.schedule.choice().label();
  std::vector<const detail::Problem*> problems;
  for (std::size_t i : g.bodies) problems.push_back(bodies[i].problem.get());
  // A batch starts on its device or not at all (its bodies then run unbatched); a body alone falls
  // back at creation unless the choice was explicit.
  const bool fallbackAtCreate = !batch && !first.schedule.explicitChoice;
  g.slot = std::make_unique<detail::DeviceSlot>(problems, scene.solver, first.schedule.order, fallbackAtCreate, device,
                                                log);
  g.driver = detail::createDriver(*g.slot, scene.analysis, log);
  for (std::size_t k = 0; k < g.bodies.size(); ++k) {
    bodies[g.bodies[k]].group = groups.size();
    bodies[g.bodies[k]].index = k;
  }
  groups.push_back(std::move(g));
}

void Simulation::Impl::formGroups() {
  std::vector<char> grouped(bodies.size(), 0);
  if (scene.backend.batch) {
    // (candidate label, preconditioner) -> bodies, scene order: a batch's bodies share their device's
    // preconditioner, so "auto" batches those it gives the same one.
    std::map<std::pair<std::string, PreconditionerKind>, std::vector<std::size_t>> byDevice;
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      const detail::Candidate& c = bodies[i].schedule.choice();
      const detail::Problem& p = *bodies[i].problem;
      if (const auto entry = detail::findBackend(c.backend); entry && entry->batches && (!entry->batchable || entry->batchable(p)))
        byDevice[{c.label(), detail::preconditionerOf(scene.solver, p)}].push_back(i);
    }
    std::map<std::string, std::size_t> onDevice;  // candidate label -> its bodies, every preconditioner
    for (const auto& [key, members] : byDevice) onDevice[key.first] += members.size();
    for (const auto& [key, members] : byDevice) {
      const std::string& label = key.first;
      if (members.size() < 2) {
        if (onDevice[label] > 1)
          unbatched.push_back({members, label,
                               std::string("its preconditioner \"") + toString(key.second) +
                                   "\" (solver.preconditioner \"auto\" chose it for its size and shape) is not the other "
                                   "bodies' on this device, and a batch shares one: it runs alone (naming one "
                                   "preconditioner in the scene batches them all, at the price of a preconditioner "
                                   "measured slower for some of them)"});
        continue;
      }
      try {
        makeGroup(members, true);
      } catch (const detail::Error& e) {
        unbatched.push_back({members, label, std::string(toString(e.code())) + ": " + e.what()});
        continue;
      }
      for (std::size_t i : members) grouped[i] = 1;
    }
  }
  for (std::size_t i = 0; i < bodies.size(); ++i)
    if (!grouped[i]) makeGroup({i}, false);
}

std::vector<detail::BodyOutcome> Simulation::Impl::stepGroup(Group& g, const detail::StepCall& call) {
  std::vector<detail::BodyOutcome> out(g.bodies.size());
  const SleepDesc& cfg = scene.analysis.dynamics.sleep;
  const bool sleeps = !isStatic() && cfg.enabled;
  const double h = call.h;
  const double t0 = time, t1 = time + h;
  // Sleep (analysis.sleep, dynamics): a body asleep stays idle while its loads and prescribed
  // targets stay where they were when it fell asleep; a change wakes it for this step.
  detail::BodySet awake;
  std::vector<std::size_t> awakeAt;  // index into g.bodies of each of `awake`
  std::vector<Eigen::VectorXd> f1(g.bodies.size()), xp1(g.bodies.size());
  for (std::size_t k = 0; k < g.bodies.size(); ++k) {
    Body& b = bodies[g.bodies[k]];
    if (sleeps) {
      const detail::Problem& p = *b.problem;
      f1[k] = p.externalForce(t1, true);
      xp1[k] = p.restPositions;
      p.applyPrescribed(xp1[k], t1, true);
      if (b.sleep.asleep) {
        const bool loadMoved = (f1[k] - b.sleep.fRef).norm() > cfg.loadChange * b.sleep.fRef.norm();
        const bool targetMoved = (xp1[k] - b.sleep.xpRef).cwiseAbs().maxCoeff() > cfg.velocity * h;
        if (!loadMoved && !targetMoved) {
          ++b.sleep.sleptSteps;
          try {
            g.driver->idleStep(b.index, h);
          } catch (...) {
            out[k].error = std::current_exception();
          }
          continue;
        }
        b.sleep.asleep = false;
        b.sleep.quiet = 0;
        ++b.sleep.wakes;
      }
    }
    awake.push_back(b.index);
    awakeAt.push_back(k);
  }
  if (!awake.empty()) {
    std::vector<detail::BodyOutcome> stepped;
    try {
      stepped = g.driver->step(awake, call);
    } catch (...) {
      stepped.assign(awake.size(), detail::BodyOutcome{});
      for (detail::BodyOutcome& o : stepped) o.error = std::current_exception();
    }
    for (std::size_t j = 0; j < awake.size(); ++j) out[awakeAt[j]] = stepped[j];
  }
  // Quiet steps: every free node slower than sleep.velocity after the step, and the loads steady
  // over it. After sleep.steps quiet steps in a row the body falls asleep.
  if (sleeps)
    for (std::size_t j = 0; j < awake.size(); ++j) {
      const std::size_t k = awakeAt[j];
      if (out[k].error) continue;
      Body& b = bodies[g.bodies[k]];
      const detail::Problem& p = *b.problem;
      const Eigen::VectorXd f0 = p.externalForce(t0, true);
      Eigen::VectorXd xp0 = p.restPositions;
      p.applyPrescribed(xp0, t0, true);
      const bool steady = (f1[k] - f0).norm() <= cfg.loadChange * f1[k].norm() &&
                          (xp1[k] - xp0).cwiseAbs().maxCoeff() <= cfg.velocity * h;
      const Eigen::VectorXd& v = g.driver->velocities(b.index);
      double maxSpeed = 0.0;
      for (Eigen::Index n = 0; n + 2 < v.size(); n += 3) {
        if (p.constrained[n] && p.constrained[n + 1] && p.constrained[n + 2]) continue;
        maxSpeed = std::max(maxSpeed, v.segment<3>(n).norm());
      }
      b.sleep.quiet = steady && maxSpeed < cfg.velocity ? b.sleep.quiet + 1 : 0;
      if (b.sleep.quiet >= std::max(1, cfg.steps)) {
        b.sleep.asleep = true;
        b.sleep.fRef = f1[k];
        b.sleep.xpRef = xp1[k];
      }
    }
  return out;
}

Simulation::Impl::Body Simulation::Impl::makeBody(const BodyDesc& desc) const {
  Body body;
  Result<TetMesh> mesh = loadBodyMesh(desc, scene.baseDir, &body.report, inputLimits);
  if (!mesh) throw detail::Error(mesh.status().code(), mesh.message());
  body.mesh = std::move(mesh.value());
  if (!desc.surface.empty())
    attachSurface(desc, scene.baseDir, inputLimits, body.mesh, body.surface, body.binding);
  body.separateStreams = desc.surfaceLayout == SurfaceLayout::Separate;
  body.problem = std::make_unique<detail::Problem>(
      detail::buildProblem(desc, body.mesh, scene.solver, scene.baseDir, inputLimits));
  // A static analysis never uses the mass (statics solve K_t du = r; gravity is rho g V / 4 per
  // node, built from the density above): zero, the device backends allocate no mass buffer.
  if (isStatic()) body.problem->lumpedMass.setZero();
  // Where the body runs: the application's order, the explicit choice (scene / API, else
  // COROFEM_DEVICE), or for "auto" the scheduler's calibrated (or cached) choice.
  body.schedule = detail::scheduleBody(desc, *body.problem, scene, device, devices);
  return body;
}

Result<Simulation> Simulation::create(const Scene& scene, const SimulationOptions& options) {
  return detail::guardResult<Simulation>([&]() {
    auto impl = std::make_unique<Impl>();
    impl->scene = scene;
    impl->log = detail::Log(options.log);
    impl->tasks = options.tasks;
    const detail::TaskScope tasks(impl->tasks);  // calibration and set-up run on the application's tasks
    if (const std::string problem = detail::hostThreadsProblem(); !problem.empty())
      impl->log(LogLevel::Warning, problem);
    impl->device.opencl = options.opencl;
    impl->device.vulkan = options.vulkan;
    impl->device.external = options.device;
    impl->devices = options.devices;
    impl->inputLimits = options.inputLimits;
    if (options.device) {
      // Every body on the application's device, the reference backend its fallback.
      const char* backend = options.device.api == GpuApi::OpenCL ? "opencl" : "vulkan";
      const auto entry = detail::findBackend(backend);
      if (!entry)
        detail::fail(ErrorCode::NotCompiledIn, "SimulationOptions::device: ", backend, " handles need the ", backend,
                     " backend, which this build does not have");
      if (!impl->devices.empty())
        detail::fail(ErrorCode::BadInput, "SimulationOptions: give either `device` (the application's device, where "
                     "every body runs) or `devices` (an order of corofem's devices), not both");
      impl->devices = {std::string(backend) + ":" + detail::kExternalSelector};
    }
    if (scene.bodies.empty())
      detail::fail(ErrorCode::BadInput, "scene '", scene.name, "' has no bodies; add at least one to \"bodies\"");
    for (const BodyDesc& desc : scene.bodies) impl->bodies.push_back(impl->makeBody(desc));
    impl->formGroups();
    // On a device: the surfaces' buffers and kernels now.
    for (Impl::Group& g : impl->groups) impl->ensureSurfaces(g);
    return Simulation(std::move(impl));
  });
}

Simulation::Simulation(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Simulation::Simulation(Simulation&&) noexcept = default;
Simulation& Simulation::operator=(Simulation&&) noexcept = default;
Simulation::~Simulation() = default;

void Simulation::Impl::stepAll(double h, StepReport& r) {
  const int count = stepCount();
  if (count > 0 && stepsTaken >= count)
    detail::fail(ErrorCode::BadInput, "the analysis is finished (", count,
                 " steps taken); check finished() before step(), or make it open-ended (analysis.steps = 0)");
  const detail::StepCall call{stepsTaken + 1, count, h};
  const std::size_t n = bodies.size();
  std::vector<Body::Sleep> sleepBefore;
  for (const Body& b : bodies) sleepBefore.push_back(b.sleep);
  // Each group's step is independent of the others', so their order does not change any answer.
  std::vector<detail::BodyOutcome> outcomes(n);
  for (Group& g : groups) {
    for (SurfaceSet& set : g.surfaces) set.dirty = true;  // recomputed lazily
    g.slot->setWhen("step " + std::to_string(call.index));
    g.slot->beginStep();
    struct EndStep {
      detail::DeviceSlot& slot;
      ~EndStep() { slot.endStep(); }
    } endStep{*g.slot};
    std::vector<detail::BodyOutcome> done;
    try {
      applyHolds(g);
      done = stepGroup(g, call);
    } catch (...) {
      // The drivers turn every failure into their bodies' outcomes; what escapes came before
      // them (the bodies are where they were) and fails the group's bodies.
      done.assign(g.bodies.size(), detail::BodyOutcome{});
      for (detail::BodyOutcome& o : done) o.error = std::current_exception();
    }
    for (std::size_t k = 0; k < g.bodies.size(); ++k) outcomes[g.bodies[k]] = done[k];
  }
  // The report sums the bodies in scene order, up to the first one that failed.
  std::size_t failed = n;
  for (std::size_t i = 0; i < n && failed == n; ++i)
    if (outcomes[i].error) failed = i;
  for (std::size_t i = 0; i < failed; ++i) {
    const detail::BodyStepStats& b = outcomes[i].stats;
    r.newtonIterations += b.newtonIterations;
    r.linearIterations += b.linearIterations;
    r.residual = std::max(r.residual, b.residual);
    r.linearResidual = std::max(r.linearResidual, b.linearResidual);
    r.converged = r.converged && b.converged;
  }
  if (failed < n) {
    // A failing body restored itself; the bodies that completed the step go back one step so
    // that the whole scene stays at the last step every body completed. The bodies that failed
    // start the next step from their positions at rest (a dynamic analysis): a step that failed
    // because the motion ran away is not repeated as it was. The error is that of the first
    // failing body in scene order.
    for (std::size_t b = 0; b < n; ++b) {
      if (!outcomes[b].error) driverOf(bodies[b]).rollback(bodies[b].index);
      else if (!isStatic()) bodies[b].hold.restart = true;
    }
    for (std::size_t b = 0; b < n; ++b) bodies[b].sleep = sleepBefore[b];
    std::rethrow_exception(outcomes[failed].error);
  }
  stepsTaken = call.index;
  if (!isStatic()) time += h;
  r.step = call.index;
}

Status Simulation::step(StepReport* report) {
  return stepWith(impl_->isStatic() ? 0.0 : impl_->scene.analysis.dynamics.timeStep, report);
}

Status Simulation::step(double dt, StepReport* report) {
  std::string refusal;
  if (impl_->isStatic()) {
    refusal = "step(dt) takes a time step; this analysis is static (load increments): call step() instead";
  } else if (!(dt > 0.0 && std::isfinite(dt))) {
    std::ostringstream os;
    os << "step(dt): the time step must be a finite number of seconds > 0, got " << dt;
    refusal = os.str();
  }
  if (refusal.empty()) return stepWith(dt, report);
  if (report) {  // no step taken
    *report = StepReport{};
    report->converged = false;
    report->time = time();
  }
  return Status(ErrorCode::BadInput, refusal);
}

Status Simulation::stepWith(double h, StepReport* report) {
  const auto start = std::chrono::steady_clock::now();
  StepReport r;
  const detail::TaskScope tasks(impl_->tasks);
  Status status = detail::guard([&] { impl_->stepAll(h, r); });
  r.time = time();
  if (!status) r.converged = false;
  r.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (report) *report = r;
  return status;
}

bool Simulation::finished() const { return impl_->stepCount() > 0 && impl_->stepsTaken >= impl_->stepCount(); }
int Simulation::stepsTaken() const { return impl_->stepsTaken; }
int Simulation::stepCount() const { return impl_->stepCount(); }

double Simulation::time() const {
  if (impl_->isStatic()) return static_cast<double>(impl_->stepsTaken) / impl_->stepCount();
  return impl_->time;
}

const Scene& Simulation::scene() const { return impl_->scene; }
int Simulation::bodyCount() const { return static_cast<int>(impl_->bodies.size()); }
const TetMesh& Simulation::restMesh(int body) const {
  assert(body >= 0 && body < bodyCount());  // a reference cannot carry a status
  return impl_->bodies[static_cast<std::size_t>(body)].mesh;
}
const MeshReadReport& Simulation::meshReport(int body) const {
  assert(body >= 0 && body < bodyCount());
  return impl_->bodies[static_cast<std::size_t>(body)].report;
}

Status Simulation::readPositions(int body, std::vector<double>& out) const {
  return detail::guard([&] {
    const Impl::Body& b = impl_->body(body);
    const Eigen::VectorXd& x = impl_->driverOf(b).positions(b.index);
    out.assign(x.data(), x.data() + x.size());
  });
}

Status Simulation::readVelocities(int body, std::vector<double>& out) const {
  return detail::guard([&] {
    const Impl::Body& b = impl_->body(body);
    const Eigen::VectorXd& v = impl_->driverOf(b).velocities(b.index);
    out.assign(v.data(), v.data() + v.size());
  });
}

EnergyReport Simulation::energies(int body) const {
  EnergyReport e;
  if (body < 0 || body >= bodyCount()) return e;
  const Impl::Body& b = impl_->bodies[static_cast<std::size_t>(body)];
  detail::Driver& driver = impl_->driverOf(b);
  e.kinetic = driver.kineticEnergy(b.index);
  e.externalWork = driver.externalWork(b.index);
  const detail::TaskScope tasks(impl_->tasks);
  Status st = detail::guard([&] { e.elastic = driver.elasticEnergy(b.index); });
  if (!st) e.elastic = std::nan("");  // a device failure here has no other channel; NaN marks it
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

// The first body's device as it is now (a failover changes it).
std::string Simulation::backendName() const { return impl_->slotOf(impl_->bodies.front()).device().name(); }
std::string Simulation::deviceName() const { return impl_->slotOf(impl_->bodies.front()).device().deviceName(); }

Status warmUp(const Scene& scene, const SimulationOptions& options, double* seconds) {
  const auto start = std::chrono::steady_clock::now();
  Scene copy = scene;
  if (copy.analysis.kind == AnalysisDesc::Kind::Dynamic && copy.analysis.dynamics.steps == 0) {
    copy.analysis.dynamics.integrator = integratorOf(copy.analysis.dynamics);  // the scheme it will run
    copy.analysis.dynamics.steps = 1;
  }
  Result<Simulation> sim = Simulation::create(copy, options);
  Status status = sim.status();
  if (sim) {
    const Status step = sim->step();
    if (!step && step.code() != ErrorCode::SolveFailed) status = step;
  }
  if (seconds) *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return status;
}

}  // namespace corofem
