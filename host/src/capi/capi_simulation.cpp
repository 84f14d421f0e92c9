// The C API's stepping, queries, reads, render surfaces and reports (corofem.h, "stepping",
// "bodies and reads", "render surfaces" and "reports").
#include "capi/capi_support.hpp"

#include <string>

namespace corofem::capi {
namespace {

void fillReport(const StepReport& r, corofem_step_report* out) {
  if (!out) return;
  out->step = r.step;
  out->time = r.time;
  out->newton_iterations = r.newtonIterations;
  out->linear_iterations = r.linearIterations;
  out->residual = r.residual;
  out->linear_residual = r.linearResidual;
  out->converged = r.converged ? 1 : 0;
  out->wall_seconds = r.wallSeconds;
}

corofem_gpu_buffer bufferOf(const GpuBuffer& b) {
  corofem_gpu_buffer out;
  out.api = b.api == GpuApi::OpenCL   ? COROFEM_GPU_OPENCL
            : b.api == GpuApi::Vulkan ? COROFEM_GPU_VULKAN
                                      : COROFEM_GPU_NONE;
  out.handle = b.handle;
  out.offset = b.offset;
  out.stride = b.stride;
  out.bytes = b.bytes;
  return out;
}

/// A value query: the simulation, the out pointer checked, then out = get(simulation).
template <class T, class Get>
corofem_status query(const char* function, const corofem_simulation* s, T* out, Get&& get) {
  return call(function, [&] {
    const Simulation& sim = simulationOf(s, function);
    require(out, function, "the result pointer", "pass the address of a variable to receive the value");
    *out = get(sim);
    return Status::ok();
  });
}

/// A text read: copies text(simulation) under the array rule.
template <class Text>
corofem_status readText(const char* function, const corofem_simulation* s, char* out, std::size_t capacity,
                        std::size_t* needed, Text&& text) {
  return call(function, [&] {
    copyText(text(simulationOf(s, function)), out, capacity, needed, function);
    return Status::ok();
  });
}

/// A read of positions or velocities (Simulation::readPositions / readVelocities).
template <class Read>
corofem_status readState(const char* function, const corofem_simulation* s, int body, double* out,
                         std::size_t capacity, std::size_t* needed, Read&& read) {
  return call(function, [&] {
    const Simulation& sim = simulationOf(s, function);
    checkBody(sim, body, function);
    const std::size_t size = 3 * sim.restMesh(body).nodeCount();
    if (!fits(out, capacity, size, needed, function, "the array", "doubles")) return Status::ok();
    std::vector<double> values;
    if (Status st = read(sim, values); !st) return st;
    copyOut(values, out, capacity, needed, function, "the array", "doubles");
    return Status::ok();
  });
}

corofem_status surfaceBuffer(const char* function, const corofem_simulation* s, int body, corofem_gpu_buffer* out,
                             bool normals) {
  return call(function, [&] {
    const Simulation& sim = simulationOf(s, function);
    checkBody(sim, body, function);
    require(out, function, "buffer", "pass the address of a corofem_gpu_buffer");
    *out = bufferOf(normals ? sim.surfaceNormalBuffer(body) : sim.surfaceBuffer(body));
    return Status::ok();
  });
}

}  // namespace
}  // namespace corofem::capi

using namespace corofem;
using namespace corofem::capi;

extern "C" {

corofem_status corofem_simulation_step(corofem_simulation* simulation, corofem_step_report* report) {
  static constexpr const char* kFn = "corofem_simulation_step";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    StepReport r;
    const Status st = sim.step(&r);
    fillReport(r, report);
    return st;
  });
}

corofem_status corofem_simulation_step_dt(corofem_simulation* simulation, double dt, corofem_step_report* report) {
  static constexpr const char* kFn = "corofem_simulation_step_dt";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    StepReport r;
    const Status st = sim.step(dt, &r);
    fillReport(r, report);
    return st;
  });
}

corofem_status corofem_simulation_finished(const corofem_simulation* simulation, int* finished) {
  return query("corofem_simulation_finished", simulation, finished,
               [](const Simulation& s) { return s.finished() ? 1 : 0; });
}

corofem_status corofem_simulation_steps_taken(const corofem_simulation* simulation, int* steps) {
  return query("corofem_simulation_steps_taken", simulation, steps, [](const Simulation& s) { return s.stepsTaken(); });
}

corofem_status corofem_simulation_step_count(const corofem_simulation* simulation, int* steps) {
  return query("corofem_simulation_step_count", simulation, steps, [](const Simulation& s) { return s.stepCount(); });
}

corofem_status corofem_simulation_time(const corofem_simulation* simulation, double* time) {
  return query("corofem_simulation_time", simulation, time, [](const Simulation& s) { return s.time(); });
}

corofem_status corofem_simulation_body_count(const corofem_simulation* simulation, int* count) {
  return query("corofem_simulation_body_count", simulation, count, [](const Simulation& s) { return s.bodyCount(); });
}

corofem_status corofem_simulation_find_body(const corofem_simulation* simulation, const char* name, int* body) {
  static constexpr const char* kFn = "corofem_simulation_find_body";
  return call(kFn, [&] {
    const Simulation& sim = simulationOf(simulation, kFn);
    require(name, kFn, "name", "pass a body's name as the scene gives it");
    require(body, kFn, "body", "pass the address of an int");
    const std::vector<BodyDesc>& bodies = sim.scene().bodies;
    std::string names;
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      if (bodies[i].name == name) {
        *body = static_cast<int>(i);
        return Status::ok();
      }
      names += (i ? ", \"" : "\"") + bodies[i].name + "\"";
    }
    return Status(ErrorCode::BadInput,
                  std::string(kFn) + ": no body is named \"" + name + "\"; the scene's bodies are " + names);
  });
}

corofem_status corofem_simulation_node_count(const corofem_simulation* simulation, int body, size_t* count) {
  static constexpr const char* kFn = "corofem_simulation_node_count";
  return call(kFn, [&] {
    const Simulation& sim = simulationOf(simulation, kFn);
    checkBody(sim, body, kFn);
    require(count, kFn, "count", "pass the address of a size_t");
    *count = sim.restMesh(body).nodeCount();
    return Status::ok();
  });
}

corofem_status corofem_simulation_element_count(const corofem_simulation* simulation, int body, size_t* count) {
  static constexpr const char* kFn = "corofem_simulation_element_count";
  return call(kFn, [&] {
    const Simulation& sim = simulationOf(simulation, kFn);
    checkBody(sim, body, kFn);
    require(count, kFn, "count", "pass the address of a size_t");
    *count = sim.restMesh(body).tetCount();
    return Status::ok();
  });
}

corofem_status corofem_simulation_read_rest_positions(const corofem_simulation* simulation, int body,
                                                      double* positions, size_t capacity, size_t* needed) {
  static constexpr const char* kFn = "corofem_simulation_read_rest_positions";
  return call(kFn, [&] {
    const Simulation& sim = simulationOf(simulation, kFn);
    checkBody(sim, body, kFn);
    copyOut(sim.restMesh(body).nodes, positions, capacity, needed, kFn, "positions", "doubles");
    return Status::ok();
  });
}

corofem_status corofem_simulation_read_elements(const corofem_simulation* simulation, int body, uint32_t* tets,
                                                size_t capacity, size_t* needed) {
  static constexpr const char* kFn = "corofem_simulation_read_elements";
  return call(kFn, [&] {
    const Simulation& sim = simulationOf(simulation, kFn);
    checkBody(sim, body, kFn);
    copyOut(sim.restMesh(body).tets, tets, capacity, needed, kFn, "tets", "indices");
    return Status::ok();
  });
}

corofem_status corofem_simulation_read_positions(const corofem_simulation* simulation, int body, double* positions,
                                                 size_t capacity, size_t* needed) {
  return readState("corofem_simulation_read_positions", simulation, body, positions, capacity, needed,
                   [&](const Simulation& s, std::vector<double>& out) { return s.readPositions(body, out); });
}

corofem_status corofem_simulation_read_velocities(const corofem_simulation* simulation, int body, double* velocities,
                                                  size_t capacity, size_t* needed) {
  return readState("corofem_simulation_read_velocities", simulation, body, velocities, capacity, needed,
                   [&](const Simulation& s, std::vector<double>& out) { return s.readVelocities(body, out); });
}

corofem_status corofem_simulation_energies(const corofem_simulation* simulation, int body, corofem_energies* energies) {
  static constexpr const char* kFn = "corofem_simulation_energies";
  return call(kFn, [&] {
    const Simulation& sim = simulationOf(simulation, kFn);
    checkBody(sim, body, kFn);
    require(energies, kFn, "energies", "pass the address of a corofem_energies");
    const EnergyReport e = sim.energies(body);
    energies->elastic = e.elastic;
    energies->kinetic = e.kinetic;
    energies->external_work = e.externalWork;
    return Status::ok();
  });
}

corofem_status corofem_simulation_surface_size(const corofem_simulation* simulation, int body, size_t* vertices,
                                               size_t* triangles) {
  static constexpr const char* kFn = "corofem_simulation_surface_size";
  return call(kFn, [&] {
    const Simulation& sim = simulationOf(simulation, kFn);
    checkBody(sim, body, kFn);
    require(vertices, kFn, "vertices", "pass the address of a size_t");
    require(triangles, kFn, "triangles", "pass the address of a size_t");
    const SurfaceMesh* surface = sim.restSurface(body);
    *vertices = surface ? surface->vertexCount() : 0;
    *triangles = surface ? surface->triangleCount() : 0;
    return Status::ok();
  });
}

corofem_status corofem_simulation_read_surface_triangles(const corofem_simulation* simulation, int body,
                                                         uint32_t* triangles, size_t capacity, size_t* needed) {
  static constexpr const char* kFn = "corofem_simulation_read_surface_triangles";
  return call(kFn, [&] {
    const Simulation& sim = simulationOf(simulation, kFn);
    checkBody(sim, body, kFn);
    const SurfaceMesh* surface = sim.restSurface(body);
    if (!surface)
      detail::fail(ErrorCode::BadInput, kFn, ": body '", sim.scene().bodies[static_cast<std::size_t>(body)].name,
                   "' has no surface; give it one with \"surface\": \"file.obj\" in the scene");
    copyOut(surface->triangles, triangles, capacity, needed, kFn, "triangles", "indices");
    return Status::ok();
  });
}

corofem_status corofem_simulation_read_surface(const corofem_simulation* simulation, int body, double* positions,
                                               size_t positions_capacity, float* normals, size_t normals_capacity,
                                               size_t* needed) {
  static constexpr const char* kFn = "corofem_simulation_read_surface";
  return call(kFn, [&] {
    const Simulation& sim = simulationOf(simulation, kFn);
    checkBody(sim, body, kFn);
    const SurfaceMesh* surface = sim.restSurface(body);
    const std::size_t size = surface ? 3 * surface->vertexCount() : 0;
    const bool readPositions = fits(positions, positions_capacity, size, needed, kFn, "positions", "doubles");
    const bool readNormals = fits(normals, normals_capacity, size, needed, kFn, "normals", "floats");
    if (!readPositions) {
      if (readNormals)
        detail::fail(ErrorCode::BadInput, kFn,
                     ": normals are read together with the positions; pass an array for both");
      if (surface) return Status::ok();  // a size query
    }
    std::vector<double> p;
    std::vector<float> n;
    if (Status st = sim.readSurface(body, p, readNormals ? &n : nullptr); !st) return st;
    copyOut(p, positions, positions_capacity, needed, kFn, "positions", "doubles");
    if (readNormals) copyOut(n, normals, normals_capacity, needed, kFn, "normals", "floats");
    return Status::ok();
  });
}

corofem_status corofem_simulation_surface_buffer(const corofem_simulation* simulation, int body,
                                                 corofem_gpu_buffer* buffer) {
  return surfaceBuffer("corofem_simulation_surface_buffer", simulation, body, buffer, false);
}

corofem_status corofem_simulation_surface_normal_buffer(const corofem_simulation* simulation, int body,
                                                        corofem_gpu_buffer* buffer) {
  return surfaceBuffer("corofem_simulation_surface_normal_buffer", simulation, body, buffer, true);
}

corofem_status corofem_simulation_update_surface(const corofem_simulation* simulation, int body) {
  static constexpr const char* kFn = "corofem_simulation_update_surface";
  return call(kFn, [&] { return simulationOf(simulation, kFn).updateSurface(body); });
}

corofem_status corofem_simulation_backend_name(const corofem_simulation* simulation, char* text, size_t capacity,
                                               size_t* needed) {
  return readText("corofem_simulation_backend_name", simulation, text, capacity, needed,
                  [](const Simulation& s) { return s.backendName(); });
}

corofem_status corofem_simulation_device_name(const corofem_simulation* simulation, char* text, size_t capacity,
                                              size_t* needed) {
  return readText("corofem_simulation_device_name", simulation, text, capacity, needed,
                  [](const Simulation& s) { return s.deviceName(); });
}

corofem_status corofem_simulation_scheduler_report(const corofem_simulation* simulation, char* text, size_t capacity,
                                                   size_t* needed) {
  return readText("corofem_simulation_scheduler_report", simulation, text, capacity, needed,
                  [](const Simulation& s) { return s.schedulerReport(); });
}

corofem_status corofem_simulation_plan_report(const corofem_simulation* simulation, char* text, size_t capacity,
                                              size_t* needed) {
  return readText("corofem_simulation_plan_report", simulation, text, capacity, needed,
                  [](const Simulation& s) { return s.planReport(); });
}

}  // extern "C"
