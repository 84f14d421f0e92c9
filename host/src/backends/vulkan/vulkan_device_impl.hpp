// The Vulkan compute backend's device (vulkan_device.cpp: element operations, surfaces, what it
// holds, the factories; vulkan_pcg.cpp: the PCG building blocks; vulkan_build.cpp: the set-up):
// a Device (device/device.hpp) over a set of bodies laid out end to end (device/body_layout.hpp:
// segments padded to whole work-groups of 64, a locality order per body), running the shaders of
// kernels/vulkan/ (the OpenCL kernels' GPU path: one element or node per invocation) in float or,
// where the device has shaderFloat64, in double. Each call records its commands into the context's
// open command buffer: small per-call tables (which bodies run, their coefficients, PCG
// tolerances) go in with vkCmdUpdateBuffer, vectors through a host-visible staging buffer. A call
// whose work nobody waits for yet (positions, the solve's set-up, a chunk of iterations) leaves it
// open; the next call that reads an answer, or queues work the host will wait on, submits it
// (vk::Context::begin). PCG iterations are recorded n at a time with the scalars and stop flags on
// the device (reduce.comp), and read back without blocking (pcgRead), as the PCG driver of
// solve/pcg.cpp expects.
//
// The device runs on a VkDevice of its own or on the application's (ExternalDevice), and updates
// the bodies' render surfaces there (vulkan_surfaces.cpp) into VkBuffers a renderer draws from.
//
// The "amg" preconditioner's V-cycle is vulkan_amg.cpp's, recorded between pcg.comp's pass and the
// product. The dynamics' vectors may live on the device too (createStepStore, vulkan_step_store.cpp:
// the store's calls below read and write its buffers). Not here yet (the Vulkan issue's last step):
// the whole step as one recorded command buffer replayed every frame.
#pragma once

#include "backends/vulkan/shaders.hpp"
#include "backends/vulkan/vk_runtime.hpp"
#include "backends/vulkan/vulkan_amg.hpp"
#include "backends/vulkan/vulkan_device.hpp"
#include "backends/vulkan/vulkan_step_store.hpp"
#include "backends/vulkan/vulkan_surfaces.hpp"
#include "device/body_layout.hpp"
#include "util/error.hpp"

#include "../../../../kernels/shared/corofem_layout.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <deque>
#include <functional>
#include <limits>

namespace corofem::detail::vkdevice {

/// The shaders' bindings (kernels/vulkan/common.glsl), in order.
enum Binding : std::uint32_t {
  kSegInfo, kSegCoef, kElemSeg, kNodeSeg, kCorners, kGeom, kRotGrad, kPos, kElemOut, kGatherStart, kGatherEntry,
  kMass, kFree, kBlocks, kMinv, kVecIn, kVecOut, kVecB, kVecX, kVecR, kVecU, kVecP, kVecS, kVecW, kPartials,
  kPartialsW, kScalars, kEnergy, kQuat, kRot, kSpring, kBindingCount
};

inline const char* const kBindingNames[kBindingCount] = {
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
constexpr std::uint32_t kFusedUpdateProduct = 0, kFusedProduct = 1;  // pcg_fused.comp
constexpr std::size_t kReadSlots = 8;  ///< scalar reads in flight before the oldest is taken to the host
constexpr std::size_t kChunk = 4096;   ///< dofs per host thread's chunk in the conversions

inline std::uint32_t rotationCode(RotationMethod m) {
  switch (m) {
    case RotationMethod::Polar: return 0;
    case RotationMethod::Svd: return 1;
    case RotationMethod::Quaternion: return 2;
    case RotationMethod::Qr: return 3;
  }
  return 0;
}

inline std::uint32_t preconditionerCode(PreconditionerKind k) {
  switch (k) {
    case PreconditionerKind::None: return 0;
    case PreconditionerKind::BlockDiagonal: return 2;
    case PreconditionerKind::Amg: return 2;  // pcg.comp forms the node blocks' inverses the V-cycle smooths with
    default: return 1;
  }
}

/// The mean of x's nodes (3N entries), subtracted from the positions the device holds.
inline void centroidOf(const Eigen::VectorXd& x, std::size_t nodes, double* c) {
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
               const VulkanTuning& tuning);

  ~VulkanDevice() override {
    try {
      // Commands left open read this device's buffers, which go now; the surfaces may keep the
      // context (and so its open command buffer) beyond it.
      if (ctx_) ctx_->discard();
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
                                                 bool separateStreams) override;

  // ---------------------------------------------------------------------------- element operations

  void setPositions(const BodySet& set, const ConstVectors& x) override;

  void internalForces(const BodySet& set, const Vectors& f) override;

  void apply(const BodySet& set, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& p,
             const Vectors& y) override;

  void elasticEnergy(const BodySet& set, std::vector<double>& energy) override;

  /// The active bodies' strain energies summed per element work-group on the device (reduce.comp's
  /// kReduceEnergy) and copied to down_; takeEnergies adds the set's once the submission is waited for.
  void recordEnergySums(VkCommandBuffer cb) const;
  void takeEnergies(const BodySet& set);

  void setConstraints(const BodySet& set, const std::vector<const std::vector<std::uint8_t>*>& constrained) override;

  void setMaterial(const BodySet& set, const std::vector<const Problem*>& problems) override;

  void setSprings(const BodySet& set, const std::vector<const Problem*>& problems) override;

  // ---------------------------------------------------------------------------- PCG building blocks

  std::vector<PcgStart> pcgBegin(const BodySet& set, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& b,
                                 const ConstVectors& x, double tolerance, int maxIterations) override;

  void pcgIterate(int n, const std::vector<char>&) override;

  PcgTicket pcgRead() override;

  void pcgTake(PcgTicket ticket, std::vector<PcgScalars>& scalars) override;

  void pcgResidual(const std::vector<char>& bodies) override;

  void pcgEnd(const std::vector<int>&, const Vectors& x, std::vector<PcgScalars>& residual) override;

  // ---------------------------------------------------------------------------- what it holds

  std::vector<DeviceCounter> counters() const override;

  std::vector<DeviceBuffer> buffers() const override;

  /// The store on this device's context, in its numbering and precision (vulkan_step_store.hpp),
  /// where VulkanTuning::deviceStore asks for one; else null (the host's).
  std::unique_ptr<StepStore> createStepStore(DeviceSlot& slot) override;

  // ---------------------------------------------------------------------------- a store's calls
  // The element operations on vectors a step store keeps in a buffer of this device's context, in
  // its numbering and precision: body set[i]'s entries at reals at[i] + its dofBegin().

  /// The positions of `set` from `from` (relative to origins[i], which becomes the body's
  /// centroid), then the rotations. `hostX`: the same positions on the host where
  /// positionsNeedHost() (the multigrid's warp is the host's), else null.
  void setPositionsFrom(const BodySet& set, const vk::Buffer& from, const std::vector<std::size_t>& at,
                        const std::vector<std::array<double, 3>>& origins, const ConstVectors* hostX);
  bool positionsNeedHost() const { return amg_ != nullptr; }
  /// f_int of `set` at the device's positions into `to`.
  void internalForcesInto(const BodySet& set, const vk::Buffer& to, const std::vector<std::size_t>& at);
  /// The right-hand sides of the next solve of `set` from `from`, and its starting x = 0: the solve
  /// then takes null vectors (PcgSolve::resident).
  void stageSolve(const BodySet& set, const vk::Buffer& from, const std::vector<std::size_t>& at);
  /// The last solve's x of `set` into `to`.
  void takeSolution(const BodySet& set, const vk::Buffer& to, const std::vector<std::size_t>& at);
  /// y = A p for `set` with p and y in `vectors` (p at from[i], y at to[i]).
  void applyIn(const BodySet& set, const std::vector<SystemCoeffs>& coeffs, const vk::Buffer& vectors,
               const std::vector<std::size_t>& from, const std::vector<std::size_t>& to);

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

  /// The rotations of the set's co-rotational bodies at the positions set, one pass per rotation
  /// method among them.
  void recordRotations(VkCommandBuffer cb, const BodySet& set) const;

  /// The forces' passes of `set` (into yout_) with their energies' work-group sums.
  void recordForces(VkCommandBuffer cb, const BodySet& set) const;

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
    vk::updateBuffer(cb, to, 0, data, bytes);
    vk::fullBarrier(cb);
  }

  void updateReals(VkCommandBuffer cb, const vk::Buffer& to, const std::vector<double>& values) const {
    const std::vector<unsigned char> bytes = realBytes(values, isDouble_);
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
    if (stagingUse_ == kOpenCommands) stagingUse_ = ctx_->flush();
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
  void stash(Read& r);

  void readScalars(const unsigned char* from, std::vector<double>& values) const;
  /// Records the copies of x of the solve's running bodies and of the scalars that pcgEnd reads.
  void recordEndReads(VkCommandBuffer cb);

  /// The solve's bodies' scalars from the device's (those that did not start: as they entered).
  void scalarsOf(const std::vector<double>& values, std::vector<PcgScalars>& out) const;

  // -- set-up

  void build();

  /// A descriptor set of every binding with a product's input `in` and output `out`.
  VkDescriptorSet productSet(const vk::Buffer& in, const vk::Buffer& out);


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
  std::size_t energyOffset_ = 0;   ///< bytes: where the element work-groups' energy sums are read to in down_
  std::vector<double> energyHost_;  ///< per body: its strain energy as last read
  std::vector<char> energyFresh_;   ///< per body: energyHost_ is at the positions and material set
  /// per body: its energy's sums are on their way to down_ in recorded work (internalForcesInto)
  std::vector<char> energyPending_;
  VkPipeline rotations_ = VK_NULL_HANDLE, element_ = VK_NULL_HANDLE, gather_ = VK_NULL_HANDLE, pcg_ = VK_NULL_HANDLE,
             reduce_ = VK_NULL_HANDLE, pcgGroup_ = VK_NULL_HANDLE, elementFused_ = VK_NULL_HANDLE,
             pcgFused_ = VK_NULL_HANDLE, surface_ = VK_NULL_HANDLE;
  VkDescriptorSet apply_ = VK_NULL_HANDLE, pcgSet_ = VK_NULL_HANDLE, setup_ = VK_NULL_HANDLE;

  std::vector<std::uint32_t> segInfo_;                    ///< the segment table, every body inactive
  std::vector<Lame> lame_;                                ///< per body
  std::vector<std::vector<std::uint8_t>> constrainedHost_;  ///< per body, in the problem's numbering
  std::vector<double> free_, spring_;                     ///< per device dof
  bool hasMass_ = false, hasSprings_ = false;
  bool groupPcg_ = false;  ///< PCG iterations in one dispatch, a work-group per body (pcg_group.comp)
  int groupIterationsPerDispatch_ = 1;                   ///< pcg_group's iterations in one dispatch
  bool fusedPcg_ = false;  ///< off pcg_group, two dispatches an iteration (VulkanTuning::fusedPcg)
  bool deviceStore_ = false;  ///< createStepStore makes one (VulkanTuning::deviceStore)
  long long stepStores_ = 0;  ///< stores made (the report's device_counters: where the vectors live)
  long long groupDispatches_ = 0, phaseDispatches_ = 0;  ///< PCG iteration dispatches of each path
  /// The last submission reading up_ (0: none pending; kOpenCommands: the open command buffer, or
  /// a submission since: Context::flush gives it).
  std::uint64_t stagingUse_ = 0;
  static constexpr std::uint64_t kOpenCommands = ~std::uint64_t{0};

  BodySet solve_;
  std::vector<SystemCoeffs> solveCoeffs_;  ///< per body of the device (the solve's; others unused)
  std::vector<PcgStart> started_;
  std::vector<char> resident_;  ///< per body of the solve: b and x are the device's (stageSolve)
  int cap_ = 0, enqueued_ = 0;
  std::deque<Read> reads_;
  PcgTicket nextTicket_ = 0;
  std::vector<char> residualFor_;
  /// The submission of the solve's last reads (x and the scalars after the true residual), made
  /// with the residual by pcgResidual; 0: pcgEnd makes them.
  std::uint64_t endReads_ = 0;
  std::unique_ptr<VulkanAmg> amg_;  ///< the "amg" preconditioner's levels and V-cycle (else null)
};

}  // namespace corofem::detail::vkdevice
