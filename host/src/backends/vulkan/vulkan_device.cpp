// The Vulkan compute backend: a Device (device/device.hpp) over a set of bodies laid out end to end
// (device/body_layout.hpp: segments padded to whole work-groups of 64, a locality order per body),
// running the shaders of kernels/vulkan/ (the OpenCL kernels' GPU path: one element or node per
// invocation) in float or, where the device has shaderFloat64, in double. Each call records one
// command buffer: small per-call tables (which bodies run, their coefficients, PCG tolerances) go
// in with vkCmdUpdateBuffer, vectors through a host-visible staging buffer. PCG iterations are
// recorded n at a time with the scalars and stop flags on the device (reduce.comp), and read back
// without blocking (pcgRead), as the PCG driver of solve/pcg.cpp expects.
//
// The device runs on a VkDevice of its own or on the application's (ExternalDevice), and updates
// the bodies' render surfaces there (vulkan_surfaces.cpp) into VkBuffers a renderer draws from.
//
// The "amg" preconditioner's V-cycle is vulkan_amg.cpp's, recorded between pcg.comp's pass and the
// product. Not here yet (the Vulkan issue's later step): the whole step as one recorded command
// buffer replayed every frame.
#include "backends/vulkan/shaders.hpp"
#include "backends/vulkan/vk_runtime.hpp"
#include "backends/vulkan/vulkan_amg.hpp"
#include "backends/vulkan/vulkan_device.hpp"
#include "backends/vulkan/vulkan_surfaces.hpp"
#include "device/body_layout.hpp"
#include "device/registry.hpp"
#include "util/error.hpp"

#include "../../../../kernels/shared/corofem_layout.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <deque>
#include <functional>
#include <limits>

namespace corofem::detail {

namespace {

/// The shaders' bindings (kernels/vulkan/common.glsl), in order.
enum Binding : std::uint32_t {
  kSegInfo, kSegCoef, kElemSeg, kNodeSeg, kCorners, kGeom, kRotGrad, kPos, kElemOut, kGatherStart, kGatherEntry,
  kMass, kFree, kBlocks, kMinv, kVecIn, kVecOut, kVecB, kVecX, kVecR, kVecU, kVecP, kVecS, kVecW, kPartials,
  kPartialsW, kScalars, kEnergy, kQuat, kRot, kSpring, kBindingCount
};

const char* const kBindingNames[kBindingCount] = {
    "segment table", "segment coefficients", "element segments", "node segments", "element corners",
    "rest gradients and volumes", "rotated gradients", "positions", "element outputs", "gather starts",
    "gather entries", "lumped mass", "free dofs", "node stiffness blocks", "preconditioner inverse",
    "product input", "product output", "PCG b", "PCG x", "PCG r", "PCG u", "PCG p", "PCG s", "PCG w",
    "PCG partial sums", "PCG partial sums (u.w)", "PCG scalars", "element energies", "quaternions",
    "rotations", "spring stiffness"};

/// common.glsl's push constants (and amg.comp's after them).
using Push = VulkanPush;

constexpr std::uint32_t kFlagProject = 1, kFlagMass = 2, kFlagZeroStart = 4, kFlagSprings = 32, kFlagCapLast = 64;
constexpr std::uint32_t kWg = 64;
constexpr std::uint32_t kElementForces = 0, kElementProduct = 1, kElementCorners = 2;
constexpr std::uint32_t kGatherSum = 0, kGatherProduct = 1, kGatherResidual = 2, kGatherBlocks = 3;
constexpr std::uint32_t kPcgInit = 0, kPcgUpdate = 1;
constexpr std::size_t kReadSlots = 8;  ///< scalar reads in flight before the oldest is taken to the host
constexpr std::size_t kChunk = 4096;   ///< dofs per host thread's chunk in the conversions

std::uint32_t rotationCode(RotationMethod m) {
  switch (m) {
    case RotationMethod::Polar: return 0;
    case RotationMethod::Svd: return 1;
    case RotationMethod::Quaternion: return 2;
    case RotationMethod::Qr: return 3;
  }
  return 0;
}

std::uint32_t preconditionerCode(PreconditionerKind k) {
  switch (k) {
    case PreconditionerKind::None: return 0;
    case PreconditionerKind::BlockDiagonal: return 2;
    case PreconditionerKind::Amg: return 2;  // pcg.comp forms the node blocks' inverses the V-cycle smooths with
    default: return 1;
  }
}

/// The mean of x's nodes (3N entries), subtracted from the positions the device holds.
void centroidOf(const Eigen::VectorXd& x, std::size_t nodes, double* c) {
  for (int k = 0; k < 3; ++k) {
    double sum = 0;
    for (std::size_t n = 0; n < nodes; ++n) sum += x[static_cast<Eigen::Index>(3 * n + k)];
    c[k] = nodes ? sum / static_cast<double>(nodes) : 0.0;
  }
}

class VulkanDevice final : public Device {
 public:
  /// `makeContext(float64)`: the Vulkan device the bodies run on (its own or an application's).
  VulkanDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
               const std::function<std::shared_ptr<vk::Context>(bool float64)>& makeContext,
               const VulkanTuning& tuning)
      : solver_(resolvedSolver(solver, problems)), layout_(problems, tuning.localityOrder, kWg, kWg, 12) {
    for (const Problem* p : problems)
      if (const std::string why = vulkanRefusal(*p, solver_); !why.empty()) fail(ErrorCode::BadInput, "body '", p->name, "': ", why);
    isDouble_ = solver_.precision == Precision::Double;
    rs_ = isDouble_ ? sizeof(double) : sizeof(float);
    ctx_ = makeContext(isDouble_);
    // The PCG path (VulkanTuning::groupPcgNodes): whole iterations in one dispatch where every body is
    // small enough.
    // The PCG path for every body of the device (VulkanTuning::groupPcgNodes, from its largest body).
    // A dispatch of pcg_group runs at most kGroupChunkBudget passes over 64 nodes per work-group
    // (two an iteration per 64 nodes of its body, and one for the sums): lavapipe (Mesa 22.3)
    // silently ended work-groups after about 3,000 such passes in one dispatch (a body of 1,331
    // nodes after 72 iterations, of 3,751 after 26: test_vulkan_paths), and a GPU driver's watchdog
    // ends long dispatches too. A body whose one iteration exceeds it takes the per-phase path.
    constexpr std::size_t kGroupChunkBudget = 256;
    const long long groupNodes = tuning.groupPcgNodes != 0 ? tuning.groupPcgNodes : 2048;
    std::size_t largest = 0;
    for (const BodySegment& sg : layout_.segments) largest = std::max(largest, sg.nodes);
    const std::size_t chunks = 2 * ((largest + kWg - 1) / kWg) + 1;
    // The multigrid's V-cycle runs between an iteration's passes: no whole iterations in one dispatch.
    groupPcg_ = groupNodes > 0 && largest <= static_cast<std::size_t>(groupNodes) && chunks <= kGroupChunkBudget &&
                solver_.preconditioner != PreconditionerKind::Amg;
    groupIterationsPerDispatch_ = static_cast<int>(std::max<std::size_t>(1, kGroupChunkBudget / chunks));
    build();
    if (solver_.preconditioner == PreconditionerKind::Amg) {
      VulkanAmgHost host;
      host.ctx = ctx_;
      host.isDouble = isDouble_;
      host.segments = &layout_.segments;
      host.nodeTotal = layout_.nodeTotal;
      host.shared = &owned_;
      host.productSet = [this](const vk::Buffer& in, const vk::Buffer& out) { return productSet(in, out); };
      host.product = [this](VkCommandBuffer cb, VkDescriptorSet set) { recordProduct(cb, basePush(), set); };
      host.dispatch = [this](VkCommandBuffer cb, VkPipeline p, VkDescriptorSet set, const Push& push,
                             std::uint32_t groups) { dispatch(cb, p, set, push, groups); };
      amg_ = std::make_unique<VulkanAmg>(std::move(host));
    }
  }

  ~VulkanDevice() override {
    try {
      if (ctx_) ctx_->waitAll();
    } catch (...) {
    }
  }

  std::string name() const override { return "vulkan"; }
  std::string deviceName() const override { return ctx_->physical().name; }
  std::size_t bodyCount() const override { return layout_.segments.size(); }
  const Problem& problem(std::size_t body) const override { return *segment(body).problem; }

  // ---------------------------------------------------------------------------- render surfaces

  std::unique_ptr<DeviceSurfaces> createSurfaces(const std::vector<SurfaceMember>& members,
                                                 bool separateStreams) override {
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

  // ---------------------------------------------------------------------------- element operations

  void setPositions(const BodySet& set, const ConstVectors& x) override {
    checkSet(set, x.size(), "positions");
    for (std::size_t i = 0; i < set.size(); ++i) checkSize(segment(set[i]), *x[i], "positions");
    waitStaging();
    VkCommandBuffer cb = ctx_->begin();
    for (std::size_t i = 0; i < set.size(); ++i) {
      BodySegment& sg = layout_.segments[set[i]];
      energyFresh_[set[i]] = 0;
      const Eigen::VectorXd& xi = *x[i];
      centroidOf(xi, sg.nodes, sg.centroid);  // keeps float's x - c small (the forces read differences only)
      putReals(up_.mapped(), isDouble_, sg.dofBegin(), sg.dofs(), kChunk,
               [&](std::size_t d) { return xi[static_cast<Eigen::Index>(sg.hostDof(d))] - sg.centroid[d % 3]; });
      copy(cb, up_, sg.dofBegin() * rs_, buffer(kPos), sg.dofBegin() * rs_, sg.dofs() * rs_);
    }
    if (amg_) amg_->positionsSet(set, x);
    vk::fullBarrier(cb);
    // The rotations, one pass per rotation method among the set's co-rotational bodies.
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
    stagingUse_ = ctx_->submit();
  }

  void internalForces(const BodySet& set, const Vectors& f) override {
    checkSet(set, f.size(), "forces");
    VkCommandBuffer cb = ctx_->begin();
    recordActive(cb, activeOf(set));
    recordCoefficients(cb, std::vector<SystemCoeffs>(bodyCount()));
    recordPasses(cb, kElementForces, kGatherSum);
    // The forces' element pass wrote each element's strain energy too. On a CPU device (lavapipe)
    // they are read with the forces, which answers an elasticEnergy at these positions (the drivers
    // ask for it after the step's last forces) with no further round trip; on a GPU, whose host
    // round trip is cheaper than E reals over the bus every Newton iteration, they are read only
    // when asked for (as the OpenCL backend decides, segment_engine.cpp's energyWithForces_).
    const bool withEnergies = !ctx_->physical().gpu;
    if (withEnergies) {
      std::vector<VkBufferCopy> regions;
      for (std::size_t b : set) {
        const std::size_t at = segment(b).elemBegin * rs_;
        if (segment(b).elems) regions.push_back({at, energyOffset_ + at, segment(b).elems * rs_});
      }
      if (!regions.empty())
        vkCmdCopyBuffer(cb, buffer(kEnergy).handle(), down_.handle(), static_cast<std::uint32_t>(regions.size()),
                        regions.data());
    }
    readOutputs(cb, set, f);
    if (withEnergies)
      for (std::size_t b : set) {
        energyHost_[b] = energySum(down_.mapped() + energyOffset_, segment(b));
        energyFresh_[b] = 1;
      }
  }

  void apply(const BodySet& set, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& p,
             const Vectors& y) override {
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

  void elasticEnergy(const BodySet& set, std::vector<double>& energy) override {
    checkSet(set, set.size(), "energies");
    energy.assign(set.size(), 0.0);
    if (std::all_of(set.begin(), set.end(), [&](std::size_t b) { return energyFresh_[b] != 0; })) {
      for (std::size_t i = 0; i < set.size(); ++i) energy[i] = energyHost_[set[i]];
      return;
    }
    VkCommandBuffer cb = ctx_->begin();
    recordActive(cb, activeOf(set));
    recordCoefficients(cb, std::vector<SystemCoeffs>(bodyCount()));
    Push push = basePush();
    push.mode = kElementForces;
    dispatch(cb, element_, apply_, push, elementGroups());
    copy(cb, buffer(kEnergy), 0, down_, energyOffset_, layout_.elementTotal * rs_);
    vk::hostReadBarrier(cb);
    ctx_->wait(ctx_->submit());
    for (std::size_t i = 0; i < set.size(); ++i) {
      energyHost_[set[i]] = energy[i] = energySum(down_.mapped() + energyOffset_, segment(set[i]));
      energyFresh_[set[i]] = 1;
    }
  }

  /// A body's strain energy: the sum of its elements' in `elements` (every element of the device,
  /// as the energy buffer holds them), in element order.
  double energySum(const unsigned char* elements, const BodySegment& sg) const {
    double sum = 0;
    withReals(elements, isDouble_, sg.elemBegin, [&](const auto* e) {
      for (std::size_t k = 0; k < sg.elems; ++k) sum += static_cast<double>(e[k]);
    });
    return sum;
  }

  void setConstraints(const BodySet& set, const std::vector<const std::vector<std::uint8_t>*>& constrained) override {
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

  void setMaterial(const BodySet& set, const std::vector<const Problem*>& problems) override {
    checkSet(set, problems.size(), "materials");
    for (std::size_t i = 0; i < set.size(); ++i) {
      BodySegment& sg = layout_.segments[set[i]];
      lame_[set[i]] = problems[i]->lame;
      energyFresh_[set[i]] = 0;  // the energy is the Lame parameters' too
      sg.rayleighMass = problems[i]->rayleighMass;
      sg.rayleighStiffness = problems[i]->rayleighStiffness;
      if (amg_) amg_->invalidate(set[i]);
    }
  }

  void setSprings(const BodySet& set, const std::vector<const Problem*>& problems) override {
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

  // ---------------------------------------------------------------------------- PCG building blocks

  std::vector<PcgStart> pcgBegin(const BodySet& set, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& b,
                                 const ConstVectors& x, double tolerance, int maxIterations) override {
    checkSet(set, b.size(), "right-hand sides");
    checkSet(set, x.size(), "starting vectors");
    checkSet(set, coeffs.size(), "coefficients");
    for (std::size_t i = 0; i < set.size(); ++i) checkSize(segment(set[i]), *b[i], "a right-hand side");
    solve_ = set;
    cap_ = std::max(0, maxIterations);
    enqueued_ = 0;
    reads_.clear();
    residualFor_.clear();
    started_.assign(set.size(), PcgStart::Running);
    waitStaging();
    const std::size_t xOffset = 3 * layout_.nodeTotal;  // reals: b first, then x
    std::vector<SystemCoeffs> all(bodyCount());
    std::vector<char> active(bodyCount(), 0);
    bool zeroStart = true, any = false;
    const double maxReal = isDouble_ ? std::numeric_limits<double>::max() : std::numeric_limits<float>::max();
    std::vector<VkBufferCopy> toB, toX;  // from the staging buffer
    BodySet running;
    std::vector<std::pair<double, double>> amgCoefficients;  // (mass, stiffness) of each running body's A
    for (std::size_t i = 0; i < set.size(); ++i) {
      const BodySegment& sg = segment(set[i]);
      const Eigen::VectorXd& bi = *b[i];
      const Eigen::VectorXd& xi = *x[i];
      const std::vector<std::uint8_t>& fixed = constrainedHost_[set[i]];
      double bb = 0;  // of b as the device holds it (in float, entries below its range are 0)
      bool inRange = true;
      for (std::size_t d = 0; d < sg.dofs(); ++d)
        if (!fixed[d]) {
          const double given = bi[static_cast<Eigen::Index>(d)];
          const double v = isDouble_ ? given : static_cast<double>(static_cast<float>(given));
          bb += v * v;
          inRange = inRange && std::abs(given) <= maxReal;
        }
      if (!std::isfinite(bb) || !inRange) {
        started_[i] = PcgStart::NonFiniteRhs;
        continue;
      }
      if (bb == 0.0) {
        started_[i] = PcgStart::ZeroRhs;
        continue;
      }
      const bool haveX = static_cast<std::size_t>(xi.size()) == sg.dofs();
      auto start = [&](std::size_t hostDof) {
        if (!haveX || fixed[hostDof]) return 0.0;
        const double v = xi[static_cast<Eigen::Index>(hostDof)];
        return std::isfinite(v) && std::abs(v) <= maxReal ? v : 0.0;  // a non-finite start is useless, not fatal
      };
      for (std::size_t d = 0; d < sg.dofs() && zeroStart; ++d) zeroStart = start(d) == 0.0;
      putReals(up_.mapped(), isDouble_, sg.dofBegin(), sg.dofs(), kChunk, [&](std::size_t d) {
        const std::size_t h = sg.hostDof(d);
        return fixed[h] ? 0.0 : bi[static_cast<Eigen::Index>(h)];  // what a constrained dof holds is not read
      });
      putReals(up_.mapped(), isDouble_, xOffset + sg.dofBegin(), sg.dofs(), kChunk,
               [&](std::size_t d) { return start(sg.hostDof(d)); });
      toB.push_back({sg.dofBegin() * rs_, sg.dofBegin() * rs_, sg.dofs() * rs_});
      toX.push_back({(xOffset + sg.dofBegin()) * rs_, sg.dofBegin() * rs_, sg.dofs() * rs_});
      active[set[i]] = any = true;
      all[set[i]] = coeffs[i];
      running.push_back(set[i]);
      amgCoefficients.emplace_back(coeffs[i].mass + coeffs[i].damping * sg.rayleighMass,
                                   coeffs[i].stiffness + coeffs[i].damping * sg.rayleighStiffness);
    }
    solveCoeffs_ = all;
    if (!any) return started_;
    if (amg_) amg_->prepare(running, amgCoefficients);  // the hierarchies (host work, uploads) before recording
    VkCommandBuffer cb = ctx_->begin();
    vkCmdCopyBuffer(cb, up_.handle(), buffer(kVecB).handle(), static_cast<std::uint32_t>(toB.size()), toB.data());
    vkCmdCopyBuffer(cb, up_.handle(), buffer(kVecX).handle(), static_cast<std::uint32_t>(toX.size()), toX.data());
    if (amg_) amg_->recordWarps(cb, running);
    std::vector<double> sc(kScalarCount * bodyCount(), 0.0);
    for (std::size_t body = 0; body < bodyCount(); ++body) sc[kScalarCount * body + kScalarTol2] = tolerance * tolerance;
    updateReals(cb, buffer(kScalars), sc);
    recordActive(cb, active);
    recordCoefficients(cb, all);
    Push push = basePush();
    if (!zeroStart) {  // q = A x into s
      push.mode = kElementProduct;
      dispatch(cb, element_, setup_, push, elementGroups());
      push.mode = kGatherProduct;
      dispatch(cb, gather_, setup_, push, nodeGroups());
    }
    if (push.precond != 0) {  // the node blocks of R K R^T at the current rotations
      push.mode = kElementCorners;
      dispatch(cb, element_, apply_, push, elementGroups());
      push.mode = kGatherBlocks;
      dispatch(cb, gather_, apply_, push, nodeGroups());
    }
    push.mode = kPcgInit;
    if (zeroStart) push.flags |= kFlagZeroStart;
    dispatch(cb, pcg_, pcgSet_, push, nodeGroups());
    push.flags &= ~kFlagZeroStart;
    if (amg_) amg_->recordCycle(cb, true);  // u = M^-1 r by the V-cycle, over pcg.comp's node-block one
    recordProduct(cb, push, pcgSet_);
    push.mode = kReduceInit;
    dispatch(cb, reduce_, pcgSet_, push, static_cast<std::uint32_t>(bodyCount()));
    stagingUse_ = ctx_->submit();
    return started_;
  }

  void pcgIterate(int n, const std::vector<char>&) override {
    if (std::none_of(started_.begin(), started_.end(), [](PcgStart s) { return s == PcgStart::Running; })) return;
    const int k = std::min(n, cap_ - enqueued_);
    if (k <= 0) return;
    VkCommandBuffer cb = ctx_->begin();
    Push push = basePush();
    if (groupPcg_) {  // k iterations of every body, in as few dispatches as the work bound allows
      for (int done = 0; done < k;) {
        const int now = std::min(k - done, groupIterationsPerDispatch_);
        done += now;
        enqueued_ += now;
        Push p = push;
        p.mode = static_cast<std::uint32_t>(now);
        p.flags |= kFlagProject | (enqueued_ == cap_ ? kFlagCapLast : 0u);
        dispatch(cb, pcgGroup_, pcgSet_, p, static_cast<std::uint32_t>(bodyCount()));
        ++groupDispatches_;
      }
    } else {
      const int last = enqueued_ + k == cap_ ? 1 : 0;  // the cap's last iteration: an update and the scalars
      phaseDispatches_ += 4LL * (k - last) + 2LL * last;
      for (int it = 0; it < k; ++it) {
        ++enqueued_;
        const bool last = enqueued_ == cap_;
        push.mode = kPcgUpdate;
        dispatch(cb, pcg_, pcgSet_, push, nodeGroups());
        // The cap's last iteration needs r . r alone (the stop test), not u: no V-cycle.
        if (!last && amg_) amg_->recordCycle(cb, false);
        if (!last) recordProduct(cb, push, pcgSet_);
        push.mode = last ? kReduceLast : kReduceStep;
        dispatch(cb, reduce_, pcgSet_, push, static_cast<std::uint32_t>(bodyCount()));
      }
    }
    ctx_->submit();
  }

  PcgTicket pcgRead() override {
    if (reads_.size() >= kReadSlots) stash(reads_[reads_.size() - kReadSlots]);
    const PcgTicket ticket = nextTicket_++;
    const std::size_t slot = ticket % kReadSlots;
    VkCommandBuffer cb = ctx_->begin();
    copy(cb, buffer(kScalars), 0, down_, scalarsOffset_ + slot * scalarsBytes(), scalarsBytes());
    vk::hostReadBarrier(cb);
    Read r;
    r.ticket = ticket;
    r.submission = ctx_->submit();
    r.slot = slot;
    reads_.push_back(std::move(r));
    return ticket;
  }

  void pcgTake(PcgTicket ticket, std::vector<PcgScalars>& scalars) override {
    if (reads_.empty() || reads_.front().ticket != ticket)
      fail(ErrorCode::Internal, "vulkan backend: PCG reads taken out of order");
    stash(reads_.front());
    scalarsOf(reads_.front().values, scalars);
    reads_.pop_front();
  }

  void pcgResidual(const std::vector<char>& bodies) override {
    residualFor_ = bodies;
    std::vector<char> active(bodyCount(), 0);
    bool any = false;
    for (std::size_t i = 0; i < solve_.size() && i < bodies.size(); ++i)
      if (bodies[i] && started_[i] == PcgStart::Running) active[solve_[i]] = any = true;
    if (!any) return;
    VkCommandBuffer cb = ctx_->begin();
    recordActive(cb, active);
    recordCoefficients(cb, solveCoeffs_);
    Push push = basePush();
    push.mode = kElementProduct;
    dispatch(cb, element_, setup_, push, elementGroups());
    push.mode = kGatherResidual;
    dispatch(cb, gather_, setup_, push, nodeGroups());
    push.mode = kReduceResidual;
    dispatch(cb, reduce_, setup_, push, static_cast<std::uint32_t>(bodyCount()));
    ctx_->submit();
  }

  void pcgEnd(const std::vector<int>&, const Vectors& x, std::vector<PcgScalars>& residual) override {
    checkSet(solve_, x.size(), "solutions");
    residual.assign(solve_.size(), PcgScalars{});
    reads_.clear();
    const bool any = std::any_of(started_.begin(), started_.end(), [](PcgStart s) { return s == PcgStart::Running; });
    if (any) {
      VkCommandBuffer cb = ctx_->begin();
      for (std::size_t i = 0; i < solve_.size(); ++i)
        if (started_[i] == PcgStart::Running) {
          const BodySegment& sg = segment(solve_[i]);
          copy(cb, buffer(kVecX), sg.dofBegin() * rs_, down_, sg.dofBegin() * rs_, sg.dofs() * rs_);
        }
      const std::size_t finalSlot = scalarsOffset_ + kReadSlots * scalarsBytes();
      copy(cb, buffer(kScalars), 0, down_, finalSlot, scalarsBytes());
      vk::hostReadBarrier(cb);
      ctx_->wait(ctx_->submit());
      std::vector<double> values;
      readScalars(down_.mapped() + finalSlot, values);
      std::vector<PcgScalars> all;
      scalarsOf(values, all);
      for (std::size_t i = 0; i < solve_.size(); ++i) {
        if (started_[i] != PcgStart::Running) continue;
        getReals(down_.mapped(), isDouble_, segment(solve_[i]), kChunk, *x[i]);
        if (i < residualFor_.size() && residualFor_[i]) residual[i] = all[i];
      }
    }
    residualFor_.clear();
  }

  // ---------------------------------------------------------------------------- what it holds

  std::vector<DeviceCounter> counters() const override {
    // Submissions and the host waits that stalled on them: the host round trips of the steps so far.
    return {{"pcg_group_dispatches", groupDispatches_},
            {"pcg_phase_dispatches", phaseDispatches_},
            {"submissions", static_cast<long long>(ctx_->lastSubmission())},
            {"blocking_waits", static_cast<long long>(ctx_->blockingWaits())},
            {"amg_hierarchies_made", amg_ ? amg_->builds() : 0}};
  }

  std::vector<DeviceBuffer> buffers() const override {
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

 private:
  struct Read {
    PcgTicket ticket = 0;
    std::uint64_t submission = 0;
    std::size_t slot = 0;
    bool stashed = false;
    std::vector<double> values;  ///< the scalars once taken to the host
  };

  const BodySegment& segment(std::size_t body) const {
    if (body >= layout_.segments.size())
      fail(ErrorCode::Internal, "vulkan backend: body ", body, " of ", layout_.segments.size());
    return layout_.segments[body];
  }
  void checkSet(const BodySet& set, std::size_t n, const char* what) const {
    if (set.size() != n) fail(ErrorCode::Internal, "vulkan backend: ", n, " ", what, " for ", set.size(), " bodies");
    for (std::size_t b : set) segment(b);
  }
  static void checkSize(const BodySegment& sg, const Eigen::VectorXd& v, const char* what) {
    if (static_cast<std::size_t>(v.size()) != sg.dofs())
      fail(ErrorCode::Internal, "vulkan backend: ", what, " of ", v.size(), " entries for body '", sg.problem->name,
           "' of ", sg.dofs(), " dofs");
  }

  const vk::Buffer& buffer(Binding b) const { return owned_[b]; }
  std::uint32_t elementGroups() const { return static_cast<std::uint32_t>(layout_.elementTotal / kWg); }
  std::uint32_t nodeGroups() const { return static_cast<std::uint32_t>(layout_.nodeTotal / kWg); }
  std::size_t scalarsBytes() const { return kScalarCount * bodyCount() * rs_; }

  Push basePush() const {
    Push p;
    p.S = static_cast<std::uint32_t>(layout_.elementTotal);
    p.precond = preconditionerCode(solver_.preconditioner);
    p.flags = (hasMass_ ? kFlagMass : 0u) | (hasSprings_ ? kFlagSprings : 0u);
    return p;
  }

  std::vector<char> activeOf(const BodySet& set) const {
    std::vector<char> active(bodyCount(), 0);
    for (std::size_t b : set) active[b] = 1;
    return active;
  }

  // -- recording

  void dispatch(VkCommandBuffer cb, VkPipeline pipeline, VkDescriptorSet set, const Push& push,
                std::uint32_t groups) const {
    if (groups == 0) return;
    vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline);
    vkCmdBindDescriptorSets(cb, VK_PIPELINE_BIND_POINT_COMPUTE, ctx_->pipelineLayout(), 0, 1, &set, 0, nullptr);
    vkCmdPushConstants(cb, ctx_->pipelineLayout(), VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(Push), &push);
    vkCmdDispatch(cb, groups, 1, 1);
    vk::fullBarrier(cb);
  }

  /// An element pass and a node pass on the apply set (the product's input pin_, output yout_).
  void recordPasses(VkCommandBuffer cb, std::uint32_t elementMode, std::uint32_t gatherMode) const {
    Push push = basePush();
    push.mode = elementMode;
    dispatch(cb, element_, apply_, push, elementGroups());
    push.mode = gatherMode;
    dispatch(cb, gather_, apply_, push, nodeGroups());
  }

  /// Submits cb with the copies of yout_'s entries of the set's bodies, waits, and converts them
  /// into `out` (one vector per body of the set, in the problem's numbering).
  void readOutputs(VkCommandBuffer cb, const BodySet& set, const Vectors& out) {
    for (std::size_t b : set) {
      const std::size_t at = segment(b).dofBegin() * rs_;
      copy(cb, yout_, at, down_, at, segment(b).dofs() * rs_);
    }
    vk::hostReadBarrier(cb);
    ctx_->wait(ctx_->submit());
    for (std::size_t i = 0; i < set.size(); ++i) getReals(down_.mapped(), isDouble_, segment(set[i]), kChunk, *out[i]);
  }

  /// y = A p (projected) and its partial sums p . y, p and y the product input and output of `set`
  /// (pcgSet_: w = A u).
  void recordProduct(VkCommandBuffer cb, Push push, VkDescriptorSet set) const {
    push.flags |= kFlagProject;
    push.mode = kElementProduct;
    dispatch(cb, element_, set, push, elementGroups());
    push.mode = kGatherProduct;
    dispatch(cb, gather_, set, push, nodeGroups());
  }

  static void copy(VkCommandBuffer cb, const vk::Buffer& from, std::size_t fromOffset, const vk::Buffer& to,
                   std::size_t toOffset, std::size_t bytes) {
    if (bytes == 0) return;
    VkBufferCopy region{fromOffset, toOffset, bytes};
    vkCmdCopyBuffer(cb, from.handle(), to.handle(), 1, &region);
  }

  /// Small tables into a device buffer through the command buffer itself (no staging to wait for).
  static void update(VkCommandBuffer cb, const vk::Buffer& to, const void* data, std::size_t bytes) {
    const unsigned char* p = static_cast<const unsigned char*>(data);
    for (std::size_t at = 0; at < bytes; at += 65536)
      vkCmdUpdateBuffer(cb, to.handle(), at, std::min<std::size_t>(65536, bytes - at), p + at);
    vk::fullBarrier(cb);
  }

  void updateReals(VkCommandBuffer cb, const vk::Buffer& to, const std::vector<double>& values) const {
    std::vector<unsigned char> bytes(values.size() * rs_);
    putReals(bytes.data(), isDouble_, 0, values.size(), values.size() + 1,
             [&](std::size_t i) { return values[i]; });
    update(cb, to, bytes.data(), bytes.size());
  }

  /// The segment table with the bodies of `active` running and the others skipped by every shader.
  void recordActive(VkCommandBuffer cb, const std::vector<char>& active) const {
    std::vector<std::uint32_t> info = segInfo_;
    for (std::size_t b = 0; b < bodyCount(); ++b) info[kSegInfoCount * b + kSegActive] = active[b] ? kSegRunning : 0u;
    update(cb, buffer(kSegInfo), info.data(), info.size() * sizeof(std::uint32_t));
  }

  /// Every body's material and the coefficients of A = m M + c C + s (K + S), C = alpha M + beta K.
  void recordCoefficients(VkCommandBuffer cb, const std::vector<SystemCoeffs>& coeffs) const {
    std::vector<double> c(kSegCoefCount * bodyCount(), 0.0);
    for (std::size_t b = 0; b < bodyCount(); ++b) {
      const BodySegment& sg = segment(b);
      const SystemCoeffs& k = coeffs[b];
      const double stiff = k.stiffness + k.damping * sg.rayleighStiffness;
      double* out = &c[kSegCoefCount * b];
      out[kCoefLambda] = lame_[b].lambda;
      out[kCoefMu] = lame_[b].mu;
      out[kCoefProdLambda] = stiff * lame_[b].lambda;
      out[kCoefProdMu] = stiff * lame_[b].mu;
      out[kCoefMass] = k.mass + k.damping * sg.rayleighMass;
      out[kCoefStiff] = stiff;
      out[kCoefSpring] = k.stiffness;
    }
    updateReals(cb, buffer(kSegCoef), c);
  }

  // -- transfers

  void waitStaging() {
    if (stagingUse_) ctx_->wait(stagingUse_);
    stagingUse_ = 0;
  }

  /// A whole buffer of reals from the host (double), in the device precision.
  void uploadReals(const vk::Buffer& to, const std::vector<double>& values) {
    uploadBytes(to, [&](unsigned char* dst) {
      putReals(dst, isDouble_, 0, values.size(), kChunk, [&](std::size_t i) { return values[i]; });
    }, values.size() * rs_);
  }

  template <class Fill>
  void uploadBytes(const vk::Buffer& to, Fill&& fill, std::size_t bytes) {
    if (bytes == 0) return;
    waitStaging();
    vk::Buffer temporary;
    const vk::Buffer* staging = &up_;
    if (bytes > up_.bytes()) {
      temporary = vk::Buffer(*ctx_, bytes, true);
      staging = &temporary;
    }
    fill(staging->mapped());
    VkCommandBuffer cb = ctx_->begin();
    copy(cb, *staging, 0, to, 0, bytes);
    ctx_->wait(ctx_->submit());
  }

  template <class T>
  void uploadVector(const vk::Buffer& to, const std::vector<T>& values) {
    uploadBytes(to, [&](unsigned char* dst) { std::memcpy(dst, values.data(), values.size() * sizeof(T)); },
                values.size() * sizeof(T));
  }

  /// Takes a read's scalars to the host (waiting for it).
  void stash(Read& r) {
    if (r.stashed) return;
    ctx_->wait(r.submission);
    readScalars(down_.mapped() + scalarsOffset_ + r.slot * scalarsBytes(), r.values);
    r.stashed = true;
  }

  void readScalars(const unsigned char* from, std::vector<double>& values) const {
    values.resize(kScalarCount * bodyCount());
    withReals(from, isDouble_, 0, [&](const auto* in) {
      for (std::size_t i = 0; i < values.size(); ++i) values[i] = static_cast<double>(in[i]);
    });
  }

  /// The solve's bodies' scalars from the device's (those that did not start: as they entered).
  void scalarsOf(const std::vector<double>& values, std::vector<PcgScalars>& out) const {
    out.assign(solve_.size(), PcgScalars{});
    for (std::size_t i = 0; i < solve_.size(); ++i) {
      PcgScalars& s = out[i];
      if (started_[i] == PcgStart::ZeroRhs) {
        s.stop = PcgStop::Converged;
        continue;
      }
      if (started_[i] == PcgStart::NonFiniteRhs) {
        s.bb = std::numeric_limits<double>::infinity();
        s.stop = PcgStop::NonFinite;
        continue;
      }
      const double* v = &values[kScalarCount * solve_[i]];
      s.iterations = static_cast<int>(v[kScalarIterations]);
      s.rr = v[kScalarRr];
      s.bb = v[kScalarBb];
      const double stop = v[kScalarStop];
      s.stop = stop == kStopConverged ? PcgStop::Converged
               : stop == kStopBreakdown ? PcgStop::Breakdown
               : stop == kStopNonFinite ? PcgStop::NonFinite
                                        : PcgStop::Running;
    }
  }

  // -- set-up

  void build() {
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
    owned_[kEnergy] = reals(E);
    owned_[kQuat] = reals(quat.size());
    owned_[kRot] = reals(0);
    owned_[kSpring] = reals(3 * N);
    pin_ = reals(3 * N);
    yout_ = reals(3 * N);
    up_ = vk::Buffer(*ctx_, 2 * 3 * N * rs_, true);
    scalarsOffset_ = 3 * N * rs_;  // after the node vectors read back (forces, x)
    energyOffset_ = scalarsOffset_ + (kReadSlots + 1) * scalarsBytes();
    down_ = vk::Buffer(*ctx_, energyOffset_ + E * rs_, true);
    energyHost_.assign(B, 0.0);
    energyFresh_.assign(B, 0);

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
      zero(owned_[v]);
    zero(pin_);
    zero(yout_);
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
    apply_ = productSet(pin_, yout_);
    pcgSet_ = productSet(owned_[kVecU], owned_[kVecW]);
    setup_ = productSet(owned_[kVecX], owned_[kVecS]);
  }

  /// A descriptor set of every binding with a product's input `in` and output `out`.
  VkDescriptorSet productSet(const vk::Buffer& in, const vk::Buffer& out) {
    std::vector<const vk::Buffer*> b(kBindingCount);
    for (std::uint32_t i = 0; i < kBindingCount; ++i) b[i] = &owned_[i];
    b[kVecIn] = &in;
    b[kVecOut] = &out;
    return ctx_->descriptorSet(b);
  }

  void zero(const vk::Buffer& b) {
    VkCommandBuffer cb = ctx_->begin();
    vkCmdFillBuffer(cb, b.handle(), 0, VK_WHOLE_SIZE, 0u);
    ctx_->wait(ctx_->submit());
  }

  SolverDesc solver_;
  BodyLayout layout_;
  bool isDouble_ = true;
  std::size_t rs_ = sizeof(double);
  /// First member with Vulkan objects: released after the buffers (the surfaces share it, so it
  /// outlives a device whose surfaces are still held).
  std::shared_ptr<vk::Context> ctx_;
  std::vector<vk::Buffer> owned_;
  vk::Buffer pin_, yout_, up_, down_;
  std::size_t scalarsOffset_ = 0;  ///< bytes: where the scalar reads start in down_
  std::size_t energyOffset_ = 0;   ///< bytes: where the element energies are read to in down_
  std::vector<double> energyHost_;  ///< per body: its strain energy as last read
  std::vector<char> energyFresh_;   ///< per body: energyHost_ is at the positions and material set
  VkPipeline rotations_ = VK_NULL_HANDLE, element_ = VK_NULL_HANDLE, gather_ = VK_NULL_HANDLE, pcg_ = VK_NULL_HANDLE,
             reduce_ = VK_NULL_HANDLE, pcgGroup_ = VK_NULL_HANDLE, surface_ = VK_NULL_HANDLE;
  VkDescriptorSet apply_ = VK_NULL_HANDLE, pcgSet_ = VK_NULL_HANDLE, setup_ = VK_NULL_HANDLE;

  std::vector<std::uint32_t> segInfo_;                    ///< the segment table, every body inactive
  std::vector<Lame> lame_;                                ///< per body
  std::vector<std::vector<std::uint8_t>> constrainedHost_;  ///< per body, in the problem's numbering
  std::vector<double> free_, spring_;                     ///< per device dof
  bool hasMass_ = false, hasSprings_ = false;
  bool groupPcg_ = false;  ///< PCG iterations in one dispatch, a work-group per body (pcg_group.comp)
  int groupIterationsPerDispatch_ = 1;                   ///< pcg_group's iterations in one dispatch
  long long groupDispatches_ = 0, phaseDispatches_ = 0;  ///< PCG iteration dispatches of each path
  std::uint64_t stagingUse_ = 0;  ///< the last submission reading up_ (0: none pending)

  BodySet solve_;
  std::vector<SystemCoeffs> solveCoeffs_;  ///< per body of the device (the solve's; others unused)
  std::vector<PcgStart> started_;
  int cap_ = 0, enqueued_ = 0;
  std::deque<Read> reads_;
  PcgTicket nextTicket_ = 0;
  std::vector<char> residualFor_;
  std::unique_ptr<VulkanAmg> amg_;  ///< the "amg" preconditioner's levels and V-cycle (else null)
};

}  // namespace

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
