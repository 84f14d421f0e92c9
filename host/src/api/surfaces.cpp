// The Simulation's render surfaces (paper Sec. 5): on a device that has them (device/device.hpp:
// DeviceSurfaces) each group's surfaces of one output layout are updated together from the device's
// own node positions, into buffers a renderer draws from; on a host device they are computed on
// request (deformSurface).
#include "api/simulation_impl.hpp"

#include "util/error.hpp"

namespace corofem {

void Simulation::Impl::ensureSurfaces(Group& g) {
  if (g.surfacesFor == g.slot->generation()) return;
  g.surfaces.clear();
  g.surfacesNotShared.clear();
  g.surfacesOnHost.clear();
  g.surfacesFor = g.slot->generation();
  // A device error here costs the surfaces their device buffers, never the simulation: the host
  // computes what the device cannot hold (deformSurface), and the plan says why.
  auto make = [&](const std::vector<std::size_t>& which, bool separate) -> std::unique_ptr<detail::DeviceSurfaces> {
    std::vector<detail::SurfaceMember> list;
    for (std::size_t i : which) list.push_back({bodies[i].index, bodies[i].binding.get()});
    return g.slot->device().createSurfaces(list, separate);
  };
  for (bool separate : {false, true}) {
    std::vector<std::size_t> members;  // scene indices
    for (std::size_t i : g.bodies)
      if (bodies[i].binding && bodies[i].separateStreams == separate) members.push_back(i);
    if (members.empty()) continue;
    try {
      SurfaceSet set;
      set.surfaces = make(members, separate);
      if (!set.surfaces) return;  // a host device: the surfaces are computed on the host
      set.bodies = members;
      g.surfaces.push_back(std::move(set));
      continue;
    } catch (const detail::Error& e) {
      if (e.code() != ErrorCode::DeviceError) throw;
      (members.size() > 1 ? g.surfacesNotShared : g.surfacesOnHost) = e.what();
      if (members.size() < 2) continue;
    }
    // The merged buffers hold every body's vertices and may exceed what the device allocates at
    // once: each body then gets surfaces of its own.
    for (std::size_t i : members) {
      SurfaceSet own;
      try {
        own.surfaces = make({i}, separate);
      } catch (const detail::Error& e) {
        if (e.code() != ErrorCode::DeviceError) throw;
        g.surfacesOnHost = e.what();
        continue;
      }
      if (!own.surfaces) return;
      own.bodies = {i};
      own.own = true;
      g.surfaces.push_back(std::move(own));
    }
  }
}

Simulation::Impl::SurfaceSet* Simulation::Impl::refreshSurface(Body& b, std::size_t* member) {
  Group& g = groups[b.group];
  const std::size_t self = static_cast<std::size_t>(&b - bodies.data());  // the body's scene index
  for (int attempt = 0; attempt < 2; ++attempt) {
    ensureSurfaces(g);
    SurfaceSet* found = nullptr;
    for (SurfaceSet& set : g.surfaces)
      for (std::size_t m = 0; m < set.bodies.size(); ++m)
        if (set.bodies[m] == self) {
          found = &set;
          *member = m;
        }
    if (!found) return nullptr;
    if (!found->dirty) return found;
    // The members' device positions made their committed ones first (a driver may have left
    // trial positions there); a device failure there moves the group to another device, whose
    // surfaces are made again.
    detail::BodySet slotBodies;
    for (std::size_t i : found->bodies) slotBodies.push_back(bodies[i].index);
    const std::size_t generation = g.slot->generation();
    g.driver->syncDevicePositions(slotBodies);
    if (g.slot->generation() != generation) continue;
    found->surfaces->update();
    found->dirty = false;
    return found;
  }
  return nullptr;
}

Status Simulation::readSurface(int body, std::vector<double>& positions, std::vector<float>* normals) const {
  const detail::TaskScope tasks(impl_->tasks);
  return detail::guard([&] {
    Impl::Body& b = impl_->bodyForSurface(body);
    const std::size_t n = b.binding->vertexCount();
    std::size_t member = 0;
    if (Impl::SurfaceSet* set = impl_->refreshSurface(b, &member)) {
      // Explicit read-back of the device buffer(s), as two streams of 3 floats per vertex.
      std::vector<float> p(3 * n), m(3 * n);
      set->surfaces->read(member, p.data(), m.data());
      positions.assign(p.begin(), p.end());
      if (normals) *normals = std::move(m);
      return;
    }
    const Eigen::VectorXd& x = impl_->driverOf(b).positions(b.index);
    SurfaceOutput out;
    positions.resize(3 * n);
    out.positionsDouble = positions.data();
    if (normals) {
      normals->resize(3 * n);
      out.normals = normals->data();
    }
    Status st = deformSurface(*b.binding, x.data(), b.mesh.nodeCount(), out);
    if (!st) throw detail::Error(st.code(), st.message());
  });
}

GpuBuffer Simulation::Impl::surfaceBufferOf(int body, bool normals) {
  GpuBuffer buffer;
  const detail::TaskScope scope(tasks);
  const Status st = detail::guard([&] {
    if (body < 0 || body >= static_cast<int>(bodies.size())) return;
    Body& b = bodies[static_cast<std::size_t>(body)];
    if (!b.binding || (normals && !b.separateStreams)) return;
    std::size_t member = 0;
    if (SurfaceSet* set = refreshSurface(b, &member))
      buffer = normals ? set->surfaces->normalBuffer(member) : set->surfaces->vertexBuffer(member);
  });
  return st ? buffer : GpuBuffer{};
}

GpuBuffer Simulation::surfaceBuffer(int body) const { return impl_->surfaceBufferOf(body, false); }
GpuBuffer Simulation::surfaceNormalBuffer(int body) const { return impl_->surfaceBufferOf(body, true); }

Status Simulation::updateSurface(int body) const {
  const detail::TaskScope tasks(impl_->tasks);
  return detail::guard([&] {
    Impl::Body& b = impl_->bodyForSurface(body);
    std::size_t member = 0;
    if (Impl::SurfaceSet* set = impl_->refreshSurface(b, &member)) set->surfaces->finish();
  });
}

nlohmann::json Simulation::Impl::surfacePlanJson(const Body& b) {
  nlohmann::json j;
  j["vertices"] = b.binding->vertexCount();
  j["triangles"] = b.surface->triangleCount();
  Group& g = groups[b.group];
  ensureSurfaces(g);
  const SurfaceSet* set = nullptr;
  for (const SurfaceSet& s : g.surfaces)
    for (std::size_t i : s.bodies)
      if (&bodies[i] == &b) set = &s;
  j["where"] = set ? "device" : "host";
  if (!set && !g.surfacesOnHost.empty()) j["not_on_device"] = g.surfacesOnHost;
  if (set) {
    const bool separate = set->surfaces->separateStreams();
    j["layout"] = separate ? "separate" : "interleaved";
    j["output"] = separate ? "two buffers of 3 float32 per vertex: positions (surfaceBuffer), normals "
                             "(surfaceNormalBuffer)"
                           : "one buffer of 6 float32 per vertex: position, normal (surfaceBuffer)";
    nlohmann::json buffers = nlohmann::json::array();
    std::size_t total = 0;
    for (const detail::DeviceBuffer& x : set->surfaces->buffers()) {
      buffers.push_back({{"name", x.name}, {"bytes", x.bytes}});
      total += x.bytes;
    }
    j["device_buffers_allocated"] = buffers;
    j["device_bytes_allocated"] = total;
    if (g.batch && !set->own) {  // one set of buffers and launches for the batch's surfaces of this layout
      nlohmann::json names = nlohmann::json::array();
      for (std::size_t i : set->bodies) names.push_back(scene.bodies[i].name);
      j["shared_by"] = names;
    } else if (!g.surfacesNotShared.empty()) {
      j["not_shared"] = g.surfacesNotShared;
    }
  } else {
    j["output"] = "host arrays on request (readSurface; the layout applies to device buffers only)";
  }
  return j;
}

}  // namespace corofem
