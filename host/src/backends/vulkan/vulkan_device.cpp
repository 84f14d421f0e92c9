// The Vulkan device (vulkan_device_impl.hpp): element operations, render surfaces, what it holds,
// and the factories.
#include "backends/vulkan/vulkan_device_impl.hpp"

namespace corofem::detail {

namespace vkdevice {

std::unique_ptr<DeviceSurfaces> VulkanDevice::createSurfaces(const std::vector<SurfaceMember>& members,
                                                             bool separateStreams) {
  if (!surface_) {
    const vk::Spirv code = vk::shaderCode(vk::Shader::Surface, isDouble_);
    surface_ = ctx_->pipeline(code.words, code.bytes, "surface.comp");
  }
  std::vector<VulkanSurfaceBody> bodies;
  for (const SurfaceMember& m : members) {
    const BodySegment& sg = segment(m.body);
    bodies.push_back({sg.nodeBegin, &sg.deviceNode, sg.centroid});
  }
  return createVulkanSurfaces({ctx_, &owned_[kPos], surface_, isDouble_}, members, bodies, separateStreams);
}

void VulkanDevice::setPositions(const BodySet& set, const ConstVectors& x) {
  checkSet(set, x.size(), "positions");
  for (std::size_t i = 0; i < set.size(); ++i) checkSize(segment(set[i]), *x[i], "positions");
  waitStaging();
  VkCommandBuffer cb = ctx_->begin();
  for (std::size_t i = 0; i < set.size(); ++i) {
    BodySegment& sg = layout_.segments[set[i]];
    energyFresh_[set[i]] = energyPending_[set[i]] = 0;
    const Eigen::VectorXd& xi = *x[i];
    centroidOf(xi, sg.nodes, sg.centroid);  // keeps float's x - c small (the forces read differences only)
    putReals(up_.mapped(), isDouble_, sg.dofBegin(), sg.dofs(), kChunk,
             [&](std::size_t d) { return xi[static_cast<Eigen::Index>(sg.hostDof(d))] - sg.centroid[d % 3]; });
    copy(cb, up_, sg.dofBegin() * rs_, buffer(kPos), sg.dofBegin() * rs_, sg.dofs() * rs_);
  }
  if (amg_) amg_->positionsSet(set, x);
  vk::fullBarrier(cb);
  recordRotations(cb, set);
  stagingUse_ = kOpenCommands;  // left open: the forces' read, or the next read, submits it
}

void VulkanDevice::recordRotations(VkCommandBuffer cb, const BodySet& set) const {
  for (RotationMethod m : {RotationMethod::Polar, RotationMethod::Svd, RotationMethod::Quaternion, RotationMethod::Qr}) {
    std::vector<char> active(bodyCount(), 0);
    bool any = false;
    for (std::size_t b : set)
      if (segment(b).corotational && segment(b).problem->rotation == m) active[b] = any = true;
    if (!any) continue;
    recordActive(cb, active);
    Push push = basePush();
    push.rotation = rotationCode(m);
    dispatch(cb, rotations_, apply_, push, elementGroups());
  }
}

void VulkanDevice::internalForces(const BodySet& set, const Vectors& f) {
  checkSet(set, f.size(), "forces");
  VkCommandBuffer cb = ctx_->begin();
  recordForces(cb, set);
  readOutputs(cb, set, f);
  takeEnergies(set);
}

void VulkanDevice::recordForces(VkCommandBuffer cb, const BodySet& set) const {
  recordActive(cb, activeOf(set));
  recordCoefficients(cb, std::vector<SystemCoeffs>(bodyCount()));
  recordPasses(cb, kElementForces, kGatherSum);
  // The forces' element pass wrote each element's strain energy too: summed per 64 elements on the
  // device and read with the forces (a real per element work-group), it answers an elasticEnergy at
  // these positions (the drivers ask for it after the step's last forces) with no round trip of its
  // own.
  recordEnergySums(cb);
}

void VulkanDevice::setPositionsFrom(const BodySet& set, const vk::Buffer& from, const std::vector<std::size_t>& at,
                                    const std::vector<std::array<double, 3>>& origins, const ConstVectors* hostX) {
  checkSet(set, at.size(), "positions");
  checkSet(set, origins.size(), "origins");
  if (amg_ && (!hostX || hostX->size() != set.size()))
    fail(ErrorCode::Internal, "vulkan backend: the multigrid's warp needs the positions on the host");
  VkCommandBuffer cb = ctx_->begin();
  for (std::size_t i = 0; i < set.size(); ++i) {
    BodySegment& sg = layout_.segments[set[i]];
    energyFresh_[set[i]] = energyPending_[set[i]] = 0;
    std::copy(origins[i].begin(), origins[i].end(), sg.centroid);
    copy(cb, from, (at[i] + sg.dofBegin()) * rs_, buffer(kPos), sg.dofBegin() * rs_, sg.dofs() * rs_);
  }
  if (amg_) amg_->positionsSet(set, *hostX);
  vk::fullBarrier(cb);
  recordRotations(cb, set);
}

void VulkanDevice::internalForcesInto(const BodySet& set, const vk::Buffer& to, const std::vector<std::size_t>& at) {
  checkSet(set, at.size(), "forces");
  VkCommandBuffer cb = ctx_->begin();
  recordForces(cb, set);
  for (std::size_t i = 0; i < set.size(); ++i) {
    const BodySegment& sg = segment(set[i]);
    copy(cb, yout_, sg.dofBegin() * rs_, to, (at[i] + sg.dofBegin()) * rs_, sg.dofs() * rs_);
    energyPending_[set[i]] = 1;
  }
  vk::hostReadBarrier(cb);  // left open: the energies' sums are taken by elasticEnergy, if it comes
}

void VulkanDevice::applyIn(const BodySet& set, const std::vector<SystemCoeffs>& coeffs, const vk::Buffer& vectors,
                           const std::vector<std::size_t>& from, const std::vector<std::size_t>& to) {
  checkSet(set, coeffs.size(), "products");
  checkSet(set, from.size(), "products");
  checkSet(set, to.size(), "products");
  VkCommandBuffer cb = ctx_->begin();
  std::vector<SystemCoeffs> all(bodyCount());
  for (std::size_t i = 0; i < set.size(); ++i) {
    const BodySegment& sg = segment(set[i]);
    copy(cb, vectors, (from[i] + sg.dofBegin()) * rs_, pin_, sg.dofBegin() * rs_, sg.dofs() * rs_);
    all[set[i]] = coeffs[i];
  }
  vk::fullBarrier(cb);
  recordActive(cb, activeOf(set));
  recordCoefficients(cb, all);
  recordPasses(cb, kElementProduct, kGatherProduct);
  for (std::size_t i = 0; i < set.size(); ++i) {
    const BodySegment& sg = segment(set[i]);
    copy(cb, yout_, sg.dofBegin() * rs_, vectors, (to[i] + sg.dofBegin()) * rs_, sg.dofs() * rs_);
  }
  vk::fullBarrier(cb);  // left open: the store's next pass reads y after it
}

void VulkanDevice::apply(const BodySet& set, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& p,
                         const Vectors& y) {
  checkSet(set, p.size(), "products");
  checkSet(set, y.size(), "products");
  checkSet(set, coeffs.size(), "products");
  for (std::size_t i = 0; i < set.size(); ++i) checkSize(segment(set[i]), *p[i], "a product's input");
  waitStaging();
  VkCommandBuffer cb = ctx_->begin();
  std::vector<SystemCoeffs> all(bodyCount());
  for (std::size_t i = 0; i < set.size(); ++i) {
    const BodySegment& sg = segment(set[i]);
    putReals(up_.mapped(), isDouble_, sg.dofBegin(), sg.dofs(), kChunk,
             [&](std::size_t d) { return (*p[i])[static_cast<Eigen::Index>(sg.hostDof(d))]; });
    copy(cb, up_, sg.dofBegin() * rs_, pin_, sg.dofBegin() * rs_, sg.dofs() * rs_);
    all[set[i]] = coeffs[i];
  }
  recordActive(cb, activeOf(set));
  recordCoefficients(cb, all);
  recordPasses(cb, kElementProduct, kGatherProduct);
  readOutputs(cb, set, y);  // waits: the staging buffer is free again
}

void VulkanDevice::elasticEnergy(const BodySet& set, std::vector<double>& energy) {
  checkSet(set, set.size(), "energies");
  energy.assign(set.size(), 0.0);
  if (std::all_of(set.begin(), set.end(), [&](std::size_t b) { return energyFresh_[b] != 0 || energyPending_[b] != 0; })) {
    BodySet pending;
    for (std::size_t b : set)
      if (!energyFresh_[b]) pending.push_back(b);
    if (!pending.empty()) {
      ctx_->wait(ctx_->flush());  // the sums internalForcesInto left on their way to down_
      takeEnergies(pending);
    }
  } else {
    VkCommandBuffer cb = ctx_->begin();
    recordActive(cb, activeOf(set));
    recordCoefficients(cb, std::vector<SystemCoeffs>(bodyCount()));
    Push push = basePush();
    push.mode = kElementForces;
    dispatch(cb, element_, apply_, push, elementGroups());
    recordEnergySums(cb);
    vk::hostReadBarrier(cb);
    ctx_->wait(ctx_->submit());
    takeEnergies(set);
  }
  for (std::size_t i = 0; i < set.size(); ++i) energy[i] = energyHost_[set[i]];
}

/// The active bodies' energies summed per element work-group (reduce.comp's kReduceEnergy: one
/// dispatch over the element work-groups, in parallel on a GPU, where a work-group per body walking
/// a million-element body's energies would take milliseconds), and those sums copied to down_; the
/// caller submits with a host-read barrier and waits.
void VulkanDevice::recordEnergySums(VkCommandBuffer cb) const {
  Push push = basePush();
  push.mode = kReduceEnergy;
  dispatch(cb, reduce_, apply_, push, elementGroups());
  copy(cb, buffer(kEnergy), layout_.elementTotal * rs_, down_, energyOffset_, elementGroups() * rs_);
}

/// The set's energies from the work-group sums recordEnergySums read (each body's added in order,
/// in double), now fresh.
void VulkanDevice::takeEnergies(const BodySet& set) {
  for (std::size_t b : set) {
    const BodySegment& sg = segment(b);
    double sum = 0;
    withReals(down_.mapped() + energyOffset_, isDouble_, 0, [&](const auto* g) {
      for (std::size_t k = sg.elemBegin / kWg; k < (sg.elemBegin + sg.elemSpan) / kWg; ++k) sum += static_cast<double>(g[k]);
    });
    energyHost_[b] = sum;
    energyFresh_[b] = 1;
    energyPending_[b] = 0;
  }
}

void VulkanDevice::setConstraints(const BodySet& set, const std::vector<const std::vector<std::uint8_t>*>& constrained) {
  checkSet(set, constrained.size(), "constraints");
  for (std::size_t i = 0; i < set.size(); ++i) {
    BodySegment& sg = layout_.segments[set[i]];
    const std::vector<std::uint8_t>& c = *constrained[i];
    if (c.size() != sg.dofs())
      fail(ErrorCode::Internal, "vulkan backend: ", c.size(), " constraint flags for body '", sg.problem->name,
           "' of ", sg.dofs(), " dofs");
    constrainedHost_[set[i]] = c;
    for (std::size_t d = 0; d < sg.dofs(); ++d) sg.constrained[d] = c[sg.hostDof(d)];
    for (std::size_t d = 0; d < sg.dofs(); ++d) free_[sg.dofBegin() + d] = sg.constrained[d] ? 0.0 : 1.0;
    if (amg_) amg_->constraintsChanged(set[i]);
  }
  uploadReals(buffer(kFree), free_);
}

void VulkanDevice::setMaterial(const BodySet& set, const std::vector<const Problem*>& problems) {
  checkSet(set, problems.size(), "materials");
  for (std::size_t i = 0; i < set.size(); ++i) {
    BodySegment& sg = layout_.segments[set[i]];
    lame_[set[i]] = problems[i]->lame;
    energyFresh_[set[i]] = energyPending_[set[i]] = 0;  // the energy is the Lame parameters' too
    sg.rayleighMass = problems[i]->rayleighMass;
    sg.rayleighStiffness = problems[i]->rayleighStiffness;
    if (amg_) amg_->invalidate(set[i]);
  }
}

void VulkanDevice::setSprings(const BodySet& set, const std::vector<const Problem*>& problems) {
  checkSet(set, problems.size(), "springs");
  for (std::size_t i = 0; i < set.size(); ++i) {
    const BodySegment& sg = segment(set[i]);
    const Eigen::VectorXd& k = problems[i]->springStiffness;
    const bool has = static_cast<std::size_t>(k.size()) == sg.dofs();
    for (std::size_t d = 0; d < sg.dofs(); ++d)
      spring_[sg.dofBegin() + d] = has ? k[static_cast<Eigen::Index>(sg.hostDof(d))] : 0.0;
  }
  hasSprings_ = std::any_of(spring_.begin(), spring_.end(), [](double v) { return v != 0.0; });
  uploadReals(buffer(kSpring), spring_);
}

std::vector<DeviceCounter> VulkanDevice::counters() const {
  // Submissions and the host waits that stalled on them: the host round trips of the steps so far.
  return {{"pcg_group_dispatches", groupDispatches_},
          {"pcg_phase_dispatches", phaseDispatches_},
          {"submissions", static_cast<long long>(ctx_->lastSubmission())},
          {"blocking_waits", static_cast<long long>(ctx_->blockingWaits())},
          {"amg_hierarchies_made", amg_ ? amg_->builds() : 0},
          {"step_stores_made", stepStores_}};
}

std::vector<DeviceBuffer> VulkanDevice::buffers() const {
  std::vector<DeviceBuffer> out;
  for (std::uint32_t i = 0; i < kBindingCount; ++i)
    if (i != kVecIn && i != kVecOut) out.push_back({kBindingNames[i], owned_[i].bytes()});
  out.push_back({"product input", pin_.bytes()});
  out.push_back({"product output", yout_.bytes()});
  out.push_back({"staging (host to device)", up_.bytes()});
  out.push_back({"staging (device to host)", down_.bytes()});
  if (amg_)
    for (DeviceBuffer& b : amg_->buffers()) out.push_back(std::move(b));
  return out;
}

std::unique_ptr<StepStore> VulkanDevice::createStepStore(DeviceSlot& slot) {
  if (!deviceStore_) return nullptr;
  // Its largest buffer (28 vectors of every dof, or the load patterns) within what a binding may
  // span, and what step.comp indexes in 32 bits; else the host keeps the vectors.
  std::size_t vectors = 28;
  for (const BodySegment& sg : layout_.segments) vectors = std::max(vectors, sg.problem->forces.size() + 1);
  const std::size_t dofs = 3 * layout_.nodeTotal;
  if (vectors * dofs * rs_ > ctx_->physical().limits.maxStorageBufferRange || vectors * dofs > 0xFFFFFFFFu)
    return nullptr;
  std::unique_ptr<StepStore> store = createVulkanStepStore(*this, ctx_, isDouble_, layout_.segments, layout_.nodeTotal, slot);
  ++stepStores_;
  return store;
}

}  // namespace vkdevice

using vkdevice::VulkanDevice;
using vkdevice::kBindingCount;
using vkdevice::Push;
std::unique_ptr<Device> createVulkanDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                           std::size_t index, const VulkanTuning& tuning) {
  auto make = [index](bool float64) {
    auto instance = vk::Instance::shared();
    if (index >= instance->devices().size())
      fail(ErrorCode::DeviceError, "Vulkan: device ", index, " does not exist (", instance->devices().size(),
           " usable here)");
    const vk::PhysicalDevice& pd = instance->devices()[index];
    if (float64 && !pd.float64)
      fail(ErrorCode::DeviceError, "Vulkan: '", pd.name, "' has no shaderFloat64 (double in shaders); set "
           "solver.precision to \"float\"");
    return std::make_shared<vk::Context>(instance, index, float64, kBindingCount, sizeof(Push));
  };
  return std::make_unique<VulkanDevice>(problems, solver, make, tuning);
}

std::unique_ptr<Device> createVulkanDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                           const ExternalDevice& external, const VulkanTuning& tuning) {
  auto make = [&external](bool float64) {
    return std::make_shared<vk::Context>(external, float64, kBindingCount, sizeof(Push));
  };
  return std::make_unique<VulkanDevice>(problems, solver, make, tuning);
}

}  // namespace corofem::detail
