// The C API's run-time control of a live simulation (corofem.h, "run-time control"): each call
// checks the caller's pointers, then hands the values to its counterpart of corofem/simulation.hpp,
// which checks the rest (bodies, nodes, handles, finite values, rotations) and says what is wrong.
#include "capi/capi_support.hpp"

namespace corofem::capi {
namespace {

/// `count` doubles, 3 per node (set_positions, set_velocities).
std::vector<double> stateOf(const double* values, std::size_t count, const char* function, const char* name) {
  require(values, function, name, "pass 3 doubles per node of the body (corofem_simulation_node_count)");
  return std::vector<double>(values, values + count);
}

}  // namespace
}  // namespace corofem::capi

using namespace corofem;
using namespace corofem::capi;

extern "C" {

corofem_status corofem_simulation_add_handle_nodes(corofem_simulation* simulation, int body, const uint32_t* nodes,
                                                   size_t count, int* handle) {
  static constexpr const char* kFn = "corofem_simulation_add_handle_nodes";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    require(handle, kFn, "handle", "pass the address of an int to receive the handle's id");
    if (count == 0)
      detail::fail(ErrorCode::BadInput, kFn, ": a handle needs at least one node (count is 0); "
                   "corofem_simulation_add_handle_point grabs the nodes near a point");
    HandleDesc desc;
    desc.body = body;
    desc.nodes = nodeList(nodes, count, kFn);
    Result<int> id = sim.addHandle(desc);
    if (!id) return id.status();
    *handle = id.value();
    return Status::ok();
  });
}

corofem_status corofem_simulation_add_handle_point(corofem_simulation* simulation, int body, const double point[3],
                                                   double radius, int* handle) {
  static constexpr const char* kFn = "corofem_simulation_add_handle_point";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    require(point, kFn, "point", "pass 3 coordinates (m)");
    require(handle, kFn, "handle", "pass the address of an int to receive the handle's id");
    HandleDesc desc;
    desc.body = body;
    for (int a = 0; a < 3; ++a) desc.point[a] = point[a];
    desc.radius = radius;
    Result<int> id = sim.addHandle(desc);
    if (!id) return id.status();
    *handle = id.value();
    return Status::ok();
  });
}

corofem_status corofem_simulation_add_handle_surface_vertex(corofem_simulation* simulation, int body, int vertex,
                                                            int* handle) {
  static constexpr const char* kFn = "corofem_simulation_add_handle_surface_vertex";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    require(handle, kFn, "handle", "pass the address of an int to receive the handle's id");
    if (vertex < 0)
      detail::fail(ErrorCode::BadInput, kFn, ": vertex ", vertex, " is negative; give a render-surface vertex index >= 0");
    HandleDesc desc;
    desc.body = body;
    desc.surfaceVertex = vertex;
    Result<int> id = sim.addHandle(desc);
    if (!id) return id.status();
    *handle = id.value();
    return Status::ok();
  });
}

corofem_status corofem_simulation_move_handle(corofem_simulation* simulation, int handle, const double target[3],
                                              const double* rotation) {
  static constexpr const char* kFn = "corofem_simulation_move_handle";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    require(target, kFn, "target", "pass 3 coordinates (m)");
    return sim.moveHandle(handle, target, rotation);
  });
}

corofem_status corofem_simulation_remove_handle(corofem_simulation* simulation, int handle) {
  static constexpr const char* kFn = "corofem_simulation_remove_handle";
  return call(kFn, [&] { return simulationOf(simulation, kFn).removeHandle(handle); });
}

corofem_status corofem_simulation_set_handle_stiffness(corofem_simulation* simulation, int handle, double stiffness) {
  static constexpr const char* kFn = "corofem_simulation_set_handle_stiffness";
  return call(kFn, [&] { return simulationOf(simulation, kFn).setHandleStiffness(handle, stiffness); });
}

corofem_status corofem_simulation_pin_nodes(corofem_simulation* simulation, int body, const uint32_t* nodes,
                                            size_t count) {
  static constexpr const char* kFn = "corofem_simulation_pin_nodes";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    return sim.pinNodes(body, nodeList(nodes, count, kFn));
  });
}

corofem_status corofem_simulation_unpin_nodes(corofem_simulation* simulation, int body, const uint32_t* nodes,
                                              size_t count) {
  static constexpr const char* kFn = "corofem_simulation_unpin_nodes";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    return sim.unpinNodes(body, nodeList(nodes, count, kFn));
  });
}

corofem_status corofem_simulation_set_forces(corofem_simulation* simulation, int body, const corofem_force* forces,
                                             size_t count) {
  static constexpr const char* kFn = "corofem_simulation_set_forces";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    if (count > 0) require(forces, kFn, "forces", "pass an array of `count` corofem_force, or NULL with a count of 0");
    std::vector<AppliedForce> applied(count);
    for (std::size_t i = 0; i < count; ++i) {
      applied[i].node = forces[i].node;
      for (int a = 0; a < 3; ++a) {
        applied[i].point[a] = forces[i].point[a];
        applied[i].force[a] = forces[i].force[a];
      }
    }
    return sim.setForces(body, applied);
  });
}

corofem_status corofem_simulation_set_gravity(corofem_simulation* simulation, const double gravity[3]) {
  static constexpr const char* kFn = "corofem_simulation_set_gravity";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    require(gravity, kFn, "gravity", "pass 3 components (m/s^2)");
    return sim.setGravity(gravity);
  });
}

corofem_status corofem_simulation_add_body(corofem_simulation* simulation, const corofem_scene* scene, int body,
                                           int* index) {
  static constexpr const char* kFn = "corofem_simulation_add_body";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    require(scene, kFn, "scene", "pass a scene handle (corofem_scene_parse) holding the body to add");
    require(index, kFn, "index", "pass the address of an int to receive the new body's index");
    const std::vector<BodyDesc>& bodies = scene->scene.bodies;
    if (body < 0 || static_cast<std::size_t>(body) >= bodies.size())
      detail::fail(ErrorCode::BadInput, kFn, ": body ", body, " is out of range: the scene handle has ", bodies.size(),
                   " body(ies), numbered from 0");
    Result<int> added = sim.addBody(bodies[static_cast<std::size_t>(body)]);
    if (!added) return added.status();
    *index = added.value();
    return Status::ok();
  });
}

corofem_status corofem_simulation_remove_body(corofem_simulation* simulation, int body) {
  static constexpr const char* kFn = "corofem_simulation_remove_body";
  return call(kFn, [&] { return simulationOf(simulation, kFn).removeBody(body); });
}

corofem_status corofem_simulation_set_material(corofem_simulation* simulation, int body, double youngs_modulus,
                                               double poisson_ratio, double rayleigh_mass, double rayleigh_stiffness) {
  static constexpr const char* kFn = "corofem_simulation_set_material";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    return sim.setMaterial(body, youngs_modulus, poisson_ratio, rayleigh_mass, rayleigh_stiffness);
  });
}

corofem_status corofem_simulation_set_positions(corofem_simulation* simulation, int body, const double* positions,
                                                size_t count) {
  static constexpr const char* kFn = "corofem_simulation_set_positions";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    return sim.setPositions(body, stateOf(positions, count, kFn, "positions"));
  });
}

corofem_status corofem_simulation_set_velocities(corofem_simulation* simulation, int body, const double* velocities,
                                                 size_t count) {
  static constexpr const char* kFn = "corofem_simulation_set_velocities";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    return sim.setVelocities(body, stateOf(velocities, count, kFn, "velocities"));
  });
}

corofem_status corofem_simulation_reset_body(corofem_simulation* simulation, int body) {
  static constexpr const char* kFn = "corofem_simulation_reset_body";
  return call(kFn, [&] { return simulationOf(simulation, kFn).resetBody(body); });
}

corofem_status corofem_simulation_teleport(corofem_simulation* simulation, int body, const double* rotation,
                                           const double translation[3]) {
  static constexpr const char* kFn = "corofem_simulation_teleport";
  return call(kFn, [&] {
    Simulation& sim = simulationOf(simulation, kFn);
    require(translation, kFn, "translation", "pass 3 components (m)");
    static const double kIdentity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    return sim.teleport(body, rotation ? rotation : kIdentity, translation);
  });
}

}  // extern "C"
