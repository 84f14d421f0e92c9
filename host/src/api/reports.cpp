// The Simulation's JSON reports: where the bodies run and why (schedulerReport), and the plan of
// the scene with what the devices allocated (planReport).
#include "api/simulation_impl.hpp"

#include "util/error.hpp"

namespace corofem {

using nlohmann::json;

namespace {

/// [{"name", "bytes"}] of device buffers.
json buffersJson(const std::vector<detail::DeviceBuffer>& buffers) {
  json out = json::array();
  for (const detail::DeviceBuffer& d : buffers) out.push_back({{"name", d.name}, {"bytes", d.bytes}});
  return out;
}

/// {"name": value} of a device's counters.
json countersJson(const std::vector<detail::DeviceCounter>& counters) {
  json out = json::object();
  for (const detail::DeviceCounter& c : counters) out[c.name] = c.value;
  return out;
}

}  // namespace

json Simulation::Impl::batchJson(const Body& b) const {
  const Group& g = groups[b.group];
  if (!g.batch) return nullptr;
  json names = json::array();
  for (std::size_t i : g.bodies) names.push_back(scene.bodies[i].name);
  // Active: the body still runs on the batch's device (a failover moves the whole batch off it).
  return {{"group", b.group}, {"device", g.candidate}, {"bodies", names}, {"active", g.slot->failovers() == 0}};
}

json Simulation::Impl::batchesJson() const {
  json out = json::array();
  for (const Group& g : groups) {
    if (!g.batch) continue;
    json names = json::array(), active = json::array();
    for (std::size_t i : g.bodies) {
      names.push_back(scene.bodies[i].name);
      if (g.slot->failovers() == 0) active.push_back(scene.bodies[i].name);
    }
    const detail::SlotStats& st = g.slot->stats();
    json byCall = json::object();
    for (std::size_t i = 0; i < detail::SlotStats::kCalls; ++i)
      if (const detail::SlotCallStats& c = st.byCall[i]; c.calls > 0)
        byCall[detail::slotCallName(i)] = {{"rounds", c.calls}, {"requests", c.bodies},
                                           {"device_seconds", c.deviceSeconds}, {"wait_seconds", c.waitSeconds}};
    const std::vector<detail::DeviceBuffer> buffers = g.slot->device().buffers();
    std::size_t bytes = 0;
    for (const detail::DeviceBuffer& d : buffers) bytes += d.bytes;
    out.push_back({{"device", g.candidate}, {"backend", g.slot->device().name()}, {"bodies", names},
                   {"active_bodies", active}, {"rounds", st.calls}, {"requests", st.bodies},
                   {"largest_round", st.largestCall}, {"device_seconds", st.deviceSeconds},
                   {"rounds_by_call", byCall}, {"allocated_bytes", bytes}, {"buffers", buffersJson(buffers)},
                   {"device_counters", countersJson(g.slot->device().counters())}});
  }
  return out;
}

json Simulation::Impl::unbatchedJson() const {
  json out = json::array();
  for (const Unbatched& u : unbatched) {
    json names = json::array();
    for (std::size_t i : u.bodies) names.push_back(scene.bodies[i].name);
    out.push_back({{"device", u.candidate}, {"bodies", names}, {"reason", u.reason}});
  }
  return out;
}

std::string Simulation::schedulerReport() const {
  const Impl& s = *impl_;
  json j;
  json bodies = json::array(), fallbacks = json::array();
  for (std::size_t i = 0; i < s.bodies.size(); ++i) {
    const Impl::Body& b = s.bodies[i];
    const detail::DeviceSlot& slot = s.slotOf(b);
    json entry = json::parse(detail::scheduleJson(b.schedule));
    entry["current"] = slot.current().label();
    if (s.scene.analysis.dynamics.sleep.enabled && !s.isStatic())
      entry["sleep"] = {{"asleep", b.sleep.asleep}, {"slept_steps", b.sleep.sleptSteps}, {"wakes", b.sleep.wakes}};
    entry["batch"] = s.batchJson(b);
    bodies.push_back(entry);
    for (const detail::FallbackEvent& e : slot.events())
      if (e.body == s.scene.bodies[i].name) fallbacks.push_back(json::parse(detail::fallbackJson(e)));
  }
  // The top level repeats the first body's decision (the whole scene for a one-body scene).
  const json& first = bodies.front();
  j["choice"] = first["choice"];
  j["reason"] = first["reason"];
  j["candidates"] = first["candidates"];
  j["from_cache"] = first["from_cache"];
  j["bodies"] = bodies;
  j["fallbacks"] = fallbacks;
  // What the devices in use did that the answers do not show, summed over them (a device that
  // failed over took its counts with it).
  json counters = json::object();
  for (const Impl::Group& g : s.groups)
    for (const detail::DeviceCounter& c : g.slot->device().counters())
      counters[c.name] = counters.value(c.name, 0LL) + c.value;
  j["device_counters"] = counters;
  // Bodies that share a device's buffers and launches, and those that could have but run alone.
  j["batches"] = s.batchesJson();
  j["unbatched"] = s.unbatchedJson();
  return j.dump();
}

std::string Simulation::planReport() const {
  Impl& s = *impl_;
  const detail::TaskScope tasks(s.tasks);
  json j;
  j["scene"] = s.scene.name;
  j["analysis"] = s.isStatic() ? "static" : "dynamic";
  j["steps"] = s.stepCount();
  json bodies = json::array();
  for (std::size_t i = 0; i < s.bodies.size(); ++i) {
    const Impl::Body& b = s.bodies[i];
    const Impl::Group& g = s.groups[b.group];
    detail::BodySchedule now = b.schedule;  // after a fallback, the device in use
    now.order.insert(now.order.begin(), g.slot->current());
    std::vector<std::string> mates;
    if (g.batch && g.slot->failovers() == 0)
      for (std::size_t k : g.bodies) mates.push_back(s.scene.bodies[k].name);
    json body = json::parse(detail::planJson(s.scene.bodies[i], *b.problem, s.scene, now, mates));
    // What the body's own device allocated, buffer by buffer (the estimate above is the model; a
    // batched body's buffers are the batch's, listed under "batches").
    if (!g.batch) {
      const std::vector<detail::DeviceBuffer> allocated = g.slot->device().buffers();
      if (!allocated.empty()) {
        body["device_buffers_allocated"] = buffersJson(allocated);
        std::size_t total = 0;
        for (const detail::DeviceBuffer& d : allocated) total += d.bytes;
        body["device_bytes_allocated"] = total;
      }
    }
    // Where the body's node positions live on a device: in the mesh's numbering, or in the
    // device's own locality order (mesh/locality_order.hpp; the host's vectors keep the mesh's).
    detail::DevicePositions where;
    if (g.slot->device().devicePositions(b.index, where)) body["device_numbering"] = where.deviceNode ? "morton" : "mesh";
    if (b.binding) {
      try {
        body["surface"] = s.surfacePlanJson(b);
      } catch (const std::exception& e) {  // a report describes; it does not fail
        body["surface"] = {{"error", e.what()}};
      }
    }
    bodies.push_back(body);
  }
  j["bodies"] = bodies;
  j["batches"] = s.batchesJson();
  j["unbatched"] = s.unbatchedJson();
  return j.dump();
}

}  // namespace corofem
