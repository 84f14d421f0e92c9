// Adding a body to and removing one from a live Simulation (simulation.hpp). An added body runs in
// a group of its own, on the device the scheduler gives it, from its own rest state at its own
// time zero: it steps exactly as the same body does in a fresh Simulation, and the other bodies keep
// their state and their devices. A body is removed with its group when it runs alone; a body in a
// batch shares its device's buffers with the others, so the batch's device is made again without
// it (DeviceSlot::removeBody) and the others go on with their state.
#include "api/simulation_impl.hpp"

#include "util/error.hpp"

#include <algorithm>

namespace corofem {

Result<int> Simulation::addBody(const BodyDesc& desc) {
  const detail::TaskScope tasks(impl_->tasks);
  return detail::guardResult<int>([&] {
    Impl& s = *impl_;
    for (const BodyDesc& other : s.scene.bodies)
      if (other.name == desc.name)
        detail::fail(ErrorCode::BadInput, "addBody: the scene already has a body named '", desc.name,
                     "'; give the new body a name of its own");
    Impl::Body body = s.makeBody(desc);  // throws before anything changed
    s.scene.bodies.push_back(desc);
    s.bodies.push_back(std::move(body));
    const std::size_t index = s.bodies.size() - 1;
    try {
      s.makeGroup({index}, false);
      s.ensureSurfaces(s.groups.back());
    } catch (...) {
      if (!s.groups.empty() && s.groups.back().bodies == std::vector<std::size_t>{index}) s.groups.pop_back();
      s.bodies.pop_back();
      s.scene.bodies.pop_back();
      throw;
    }
    return static_cast<int>(index);
  });
}

Status Simulation::removeBody(int body) {
  const detail::TaskScope tasks(impl_->tasks);  // a batch's device made again runs on the application's tasks
  return detail::guard([&] {
    Impl& s = *impl_;
    const Impl::Body& b = s.body(body);
    const std::size_t gi = b.group;
    if (s.bodies.size() == 1)
      detail::fail(ErrorCode::BadInput, "removeBody: body '", s.scene.bodies.front().name,
                   "' is the scene's last; a Simulation keeps at least one body");
    const std::size_t removed = static_cast<std::size_t>(body);
    const bool alone = s.groups[gi].bodies.size() == 1;
    if (!alone) {
      // A batch: its device is made again for the others, which keep their state (the slot gives
      // the new device their positions; the driver keeps the rest). Nothing changed if it throws.
      Impl::Group& g = s.groups[gi];
      const std::size_t k = b.index;
      g.slot->removeBody(k);
      g.driver->removeBody(k);
      g.bodies.erase(g.bodies.begin() + static_cast<std::ptrdiff_t>(k));
      for (std::size_t j = k; j < g.bodies.size(); ++j) s.bodies[g.bodies[j]].index = j;
      g.surfaces.clear();  // made again for the new device (its generation moved on)
    }
    // Its handles go with it; the later bodies, groups and handles move down by one.
    for (auto it = s.handles.begin(); it != s.handles.end();)
      it = it->second.body == removed ? s.handles.erase(it) : std::next(it);
    for (auto& [id, handle] : s.handles)
      if (handle.body > removed) --handle.body;
    if (alone) s.groups.erase(s.groups.begin() + static_cast<std::ptrdiff_t>(gi));  // frees the device and its buffers
    s.bodies.erase(s.bodies.begin() + body);
    s.scene.bodies.erase(s.scene.bodies.begin() + body);
    if (alone)
      for (Impl::Body& other : s.bodies)
        if (other.group > gi) --other.group;
    const auto shift = [&](std::vector<std::size_t>& list) {
      for (std::size_t& i : list)
        if (i > removed) --i;
    };
    for (Impl::Group& g : s.groups) {
      shift(g.bodies);
      for (Impl::SurfaceSet& set : g.surfaces) shift(set.bodies);
    }
    for (Impl::Unbatched& u : s.unbatched) {
      u.bodies.erase(std::remove(u.bodies.begin(), u.bodies.end(), removed), u.bodies.end());
      shift(u.bodies);
    }
  });
}

}  // namespace corofem
