// The Vulkan device's set-up (vulkan_device_impl.hpp): the PCG path, the host tables in the device
// numbering, the buffers and their uploads, the pipelines and descriptor sets, the multigrid.
#include "backends/vulkan/vulkan_device_impl.hpp"

namespace corofem::detail::vkdevice {

VulkanDevice::VulkanDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                           const std::function<std::shared_ptr<vk::Context>(bool float64)>& makeContext,
                           const VulkanTuning& tuning)
    : solver_(resolvedSolver(solver, problems)), layout_(problems, tuning.localityOrder, kWg, kWg, 12) {
  for (const Problem* p : problems)
    if (const std::string why = vulkanRefusal(*p, solver_); !why.empty()) fail(ErrorCode::BadInput, "body '", p->name, "': ", why);
  isDouble_ = solver_.precision == Precision::Double;
  rs_ = isDouble_ ? sizeof(double) : sizeof(float);
  ctx_ = makeContext(isDouble_);
  // The PCG path for every body of the device (VulkanTuning::groupPcgNodes, from its largest body).
  // A dispatch of pcg_group runs at most kGroupChunkBudget passes over 64 nodes per work-group
  // (two an iteration per 64 nodes of its body, and one for the sums): lavapipe (Mesa 22.3)
  // silently ended work-groups after about 3,000 such passes in one dispatch (a body of 1,331
  // nodes after 72 iterations, of 3,751 after 26: test_vulkan_paths), and a GPU driver's watchdog
  // ends long dispatches too. A body whose one iteration exceeds it takes the per-phase path.
  constexpr std::size_t kGroupChunkBudget = 256;
  // The default: one dispatch on a CPU device (lavapipe), whose dispatches are costly and whose
  // cores a work-group per body keeps busy; never on a GPU, where one work-group holds a body to
  // one of its multiprocessors (an H200, 2026-11-28: the 270-node box's step 2.5 ms in one
  // dispatch against 1.7 ms per phase, the 2,100-node box's 14.2 against 2.6 ms).
  const long long groupNodes = tuning.groupPcgNodes != 0 ? tuning.groupPcgNodes : ctx_->physical().gpu ? -1 : 2048;
  std::size_t largest = 0;
  for (const BodySegment& sg : layout_.segments) largest = std::max(largest, sg.nodes);
  const std::size_t chunks = 2 * ((largest + kWg - 1) / kWg) + 1;
  // The multigrid's V-cycle runs between an iteration's passes: no whole iterations in one dispatch.
  groupPcg_ = groupNodes > 0 && largest <= static_cast<std::size_t>(groupNodes) && chunks <= kGroupChunkBudget &&
              solver_.preconditioner != PreconditionerKind::Amg;
  groupIterationsPerDispatch_ = static_cast<int>(std::max<std::size_t>(1, kGroupChunkBudget / chunks));
  fusedPcg_ = tuning.fusedPcg < 0 ? ctx_->physical().gpu : tuning.fusedPcg > 0;
  deviceStore_ = tuning.deviceStore < 0 ? ctx_->physical().gpu : tuning.deviceStore > 0;
  build();
  if (solver_.preconditioner == PreconditionerKind::Amg) {
    VulkanAmgHost host;
    host.ctx = ctx_;
    host.isDouble = isDouble_;
    host.segments = &layout_.segments;
    host.nodeTotal = layout_.nodeTotal;
    host.shared = &owned_;
    host.u = &owned_[kVecU];
    host.productSet = [this](const vk::Buffer& in, const vk::Buffer& out) { return productSet(in, out); };
    host.product = [this](VkCommandBuffer cb, VkDescriptorSet set) { recordProduct(cb, basePush(), set); };
    host.dispatch = [this](VkCommandBuffer cb, VkPipeline p, VkDescriptorSet set, const Push& push,
                           std::uint32_t groups) { dispatch(cb, p, set, push, groups); };
    amg_ = std::make_unique<VulkanAmg>(std::move(host));
  }
}

void VulkanDevice::build() {
  const std::size_t E = layout_.elementTotal, N = layout_.nodeTotal, B = bodyCount();
  const VkPhysicalDeviceLimits& lim = ctx_->physical().limits;
  const std::size_t largest = std::max({12 * E * rs_, 10 * E * rs_, 9 * N * rs_, 4 * E * sizeof(std::uint32_t)});
  if (largest > lim.maxStorageBufferRange)
    fail(ErrorCode::DeviceError, "Vulkan: these bodies (", E, " elements, ", N, " nodes with padding) need a ",
         largest, "-byte buffer; '", ctx_->physical().name, "' binds at most ", lim.maxStorageBufferRange,
         " bytes (maxStorageBufferRange): use float, fewer elements per device, or the opencl backend");
  if (std::max(E, N) / kWg > lim.maxComputeWorkGroupCount[0])
    fail(ErrorCode::DeviceError, "Vulkan: ", std::max(E, N) / kWg, " work-groups exceed '", ctx_->physical().name,
         "''s limit of ", lim.maxComputeWorkGroupCount[0], " per dispatch");

  // Host tables in the device numbering.
  std::vector<std::uint32_t> elemSeg(E / kWg), nodeSeg(N / kWg), corners(4 * E), start(N + 1, 0), entries;
  std::vector<double> geom(10 * E, 0.0), grads(9 * E, 0.0), quat, mass(3 * N, 0.0), rest(3 * N, 0.0);
  free_.assign(3 * N, 0.0);
  spring_.assign(3 * N, 0.0);
  segInfo_.assign(kSegInfoCount * B, 0u);
  lame_.resize(B);
  constrainedHost_.resize(B);
  bool quaternions = false;
  for (std::size_t b = 0; b < B; ++b) {
    const BodySegment& sg = layout_.segments[b];
    const Problem& p = layout_.deviceProblem(b);
    quaternions = quaternions || (sg.corotational && p.rotation == RotationMethod::Quaternion);
    lame_[b] = p.lame;
    constrainedHost_[b] = sg.problem->constrained;
    constrainedHost_[b].resize(sg.dofs(), 0);
    std::uint32_t* info = &segInfo_[kSegInfoCount * b];
    info[kSegElemEnd] = static_cast<std::uint32_t>(sg.elemBegin + sg.elems);
    info[kSegNodeEnd] = static_cast<std::uint32_t>(sg.nodeBegin + sg.nodes);
    info[kSegPartialBegin] = static_cast<std::uint32_t>(sg.nodeBegin / kWg);
    info[kSegPartialCount] = static_cast<std::uint32_t>(sg.nodeSpan / kWg);
    info[kSegElemBegin] = static_cast<std::uint32_t>(sg.elemBegin);
    info[kSegElemSpan] = static_cast<std::uint32_t>(sg.elemSpan);
    info[kSegNodeBegin] = static_cast<std::uint32_t>(sg.nodeBegin);
    for (std::size_t g = sg.elemBegin / kWg; g < (sg.elemBegin + sg.elemSpan) / kWg; ++g) elemSeg[g] = static_cast<std::uint32_t>(b);
    for (std::size_t g = sg.nodeBegin / kWg; g < (sg.nodeBegin + sg.nodeSpan) / kWg; ++g) nodeSeg[g] = static_cast<std::uint32_t>(b);
    for (std::size_t e = 0; e < sg.elemSpan; ++e) {
      const std::size_t ge = sg.elemBegin + e;
      for (std::size_t c = 0; c < 4; ++c)
        corners[c * E + ge] = static_cast<std::uint32_t>(
            sg.nodeBegin + (e < sg.elems ? p.mesh.tets[4 * e + c] : 0));  // padding: the segment's first node
      if (e >= sg.elems) continue;
      const ElementRest& rest = p.elements[e];
      for (std::size_t i = 1; i < 4; ++i)
        for (std::size_t k = 0; k < 3; ++k) {
          const double g = rest.grad(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k));
          geom[(3 * (i - 1) + k) * E + ge] = g;
          grads[(3 * (i - 1) + k) * E + ge] = g;
        }
      geom[kGeomVolume * E + ge] = rest.volume;
    }
    for (std::size_t e = 0; e < sg.elems; ++e)
      for (std::size_t c = 0; c < 4; ++c) ++start[sg.nodeBegin + p.mesh.tets[4 * e + c] + 1];
    const bool hasMass = static_cast<std::size_t>(p.lumpedMass.size()) == sg.dofs();
    hasMass_ = hasMass_ || hasMass;
    // Until the first setPositions the body is at rest (R = I: the rotated gradients are the gradients).
    centroidOf(p.restPositions, sg.nodes, layout_.segments[b].centroid);
    for (std::size_t d = 0; d < sg.dofs(); ++d) {
      rest[sg.dofBegin() + d] = p.restPositions[static_cast<Eigen::Index>(d)] - sg.centroid[d % 3];
      mass[sg.dofBegin() + d] = hasMass ? p.lumpedMass[static_cast<Eigen::Index>(d)] : 0.0;
      free_[sg.dofBegin() + d] = sg.constrained[d] ? 0.0 : 1.0;
    }
    const Eigen::VectorXd& k = sg.problem->springStiffness;
    if (static_cast<std::size_t>(k.size()) == sg.dofs())
      for (std::size_t d = 0; d < sg.dofs(); ++d) spring_[sg.dofBegin() + d] = k[static_cast<Eigen::Index>(sg.hostDof(d))];
  }
  hasSprings_ = std::any_of(spring_.begin(), spring_.end(), [](double v) { return v != 0.0; });
  // The gather lists: each node's (element, corner) pairs in element order, as 12 e + 3 c.
  for (std::size_t n = 0; n < N; ++n) start[n + 1] += start[n];
  entries.resize(start[N]);
  {
    std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
    for (std::size_t b = 0; b < B; ++b) {
      const BodySegment& sg = layout_.segments[b];
      const Problem& p = layout_.deviceProblem(b);
      for (std::size_t e = 0; e < sg.elems; ++e)
        for (std::size_t c = 0; c < 4; ++c)
          entries[fill[sg.nodeBegin + p.mesh.tets[4 * e + c]]++] =
              static_cast<std::uint32_t>(12 * (sg.elemBegin + e) + 3 * c);
    }
  }
  if (quaternions) {
    quat.assign(4 * E, 0.0);
    for (std::size_t e = 0; e < E; ++e) quat[3 * E + e] = 1.0;  // the identity (x, y, z, w)
  }

  // Buffers (a 16-byte one where a binding is unused), the staging buffers and the uploads.
  auto reals = [&](std::size_t n) { return vk::Buffer(*ctx_, n * rs_, false); };
  auto uints = [&](std::size_t n) { return vk::Buffer(*ctx_, n * sizeof(std::uint32_t), false); };
  owned_.resize(kBindingCount);
  owned_[kSegInfo] = uints(segInfo_.size());
  owned_[kSegCoef] = reals(kSegCoefCount * B);
  owned_[kElemSeg] = uints(elemSeg.size());
  owned_[kNodeSeg] = uints(nodeSeg.size());
  owned_[kCorners] = uints(corners.size());
  owned_[kGeom] = reals(geom.size());
  owned_[kRotGrad] = reals(grads.size());
  owned_[kPos] = reals(3 * N);
  owned_[kElemOut] = reals(12 * E);
  owned_[kGatherStart] = uints(start.size());
  owned_[kGatherEntry] = uints(entries.size());
  owned_[kMass] = reals(3 * N);
  owned_[kFree] = reals(3 * N);
  owned_[kBlocks] = reals(6 * N);
  owned_[kMinv] = reals(9 * N);
  owned_[kVecIn] = reals(0);
  owned_[kVecOut] = reals(0);
  for (Binding v : {kVecB, kVecX, kVecR, kVecU, kVecP, kVecS, kVecW}) owned_[v] = reals(3 * N);
  owned_[kPartials] = reals(3 * (N / kWg));
  owned_[kPartialsW] = reals(3 * (N / kWg));
  owned_[kScalars] = reals(kScalarCount * B);
  owned_[kEnergy] = reals(E + E / kWg);  // per element, then per element work-group (reduce.comp)
  owned_[kQuat] = reals(quat.size());
  owned_[kRot] = reals(0);
  owned_[kSpring] = reals(3 * N);
  pin_ = reals(3 * N);
  yout_ = reals(3 * N);
  up_ = vk::Buffer(*ctx_, 2 * 3 * N * rs_, true);
  scalarsOffset_ = 3 * N * rs_;  // after the node vectors read back (forces, x)
  energyOffset_ = scalarsOffset_ + (kReadSlots + 1) * scalarsBytes();
  down_ = vk::Buffer(*ctx_, energyOffset_ + E / kWg * rs_, true);
  energyHost_.assign(B, 0.0);
  energyFresh_.assign(B, 0);
  energyPending_.assign(B, 0);

  uploadVector(owned_[kSegInfo], segInfo_);
  uploadVector(owned_[kElemSeg], elemSeg);
  uploadVector(owned_[kNodeSeg], nodeSeg);
  uploadVector(owned_[kCorners], corners);
  uploadVector(owned_[kGatherStart], start);
  uploadVector(owned_[kGatherEntry], entries);
  uploadReals(owned_[kGeom], geom);
  uploadReals(owned_[kRotGrad], grads);
  uploadReals(owned_[kMass], mass);
  uploadReals(owned_[kPos], rest);
  uploadReals(owned_[kFree], free_);
  uploadReals(owned_[kSpring], spring_);
  if (quaternions) uploadReals(owned_[kQuat], quat);
  // Every vector the shaders may read before writing starts finite (0): a padding dof is never
  // read, but a zero start of PCG reads no x.
  for (Binding v : {kVecB, kVecX, kVecR, kVecU, kVecP, kVecS, kVecW, kBlocks, kMinv, kEnergy})
    vk::zeroBuffer(*ctx_, owned_[v]);
  vk::zeroBuffer(*ctx_, pin_);
  vk::zeroBuffer(*ctx_, yout_);
  layout_.releaseReordered();

  auto pipeline = [&](vk::Shader s, const char* name) {
    const vk::Spirv code = vk::shaderCode(s, isDouble_);
    return ctx_->pipeline(code.words, code.bytes, name);
  };
  rotations_ = pipeline(vk::Shader::Rotations, "rotations.comp");
  element_ = pipeline(vk::Shader::Element, "element.comp");
  gather_ = pipeline(vk::Shader::Gather, "gather.comp");
  pcg_ = pipeline(vk::Shader::Pcg, "pcg.comp");
  reduce_ = pipeline(vk::Shader::Reduce, "reduce.comp");
  pcgGroup_ = pipeline(vk::Shader::PcgGroup, "pcg_group.comp");
  elementFused_ = pipeline(vk::Shader::ElementFused, "element_fused.comp");
  pcgFused_ = pipeline(vk::Shader::PcgFused, "pcg_fused.comp");
  apply_ = productSet(pin_, yout_);
  pcgSet_ = productSet(owned_[kVecU], owned_[kVecW]);
  setup_ = productSet(owned_[kVecX], owned_[kVecS]);
}

/// A descriptor set of every binding with a product's input `in` and output `out`.
VkDescriptorSet VulkanDevice::productSet(const vk::Buffer& in, const vk::Buffer& out) {
  std::vector<const vk::Buffer*> b(kBindingCount);
  for (std::uint32_t i = 0; i < kBindingCount; ++i) b[i] = &owned_[i];
  b[kVecIn] = &in;
  b[kVecOut] = &out;
  return ctx_->descriptorSet(b);
}

}  // namespace corofem::detail::vkdevice
