// The Vulkan device's render surfaces (vulkan_surfaces.hpp): every member's vertices end to end in
// one set of buffers, updated by two dispatches of kernels/vulkan/surface.comp (positions, then
// normals from each vertex's one-ring, embed/one_ring.hpp) and read back or drawn from.
#include "backends/vulkan/vulkan_surfaces.hpp"

#include "device/body_layout.hpp"
#include "embed/one_ring.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <cstring>

namespace corofem::detail {

namespace {

/// surface.comp's bindings (the first ten of the shared layout; 7 is the device's positions).
enum SurfaceSlot : std::uint32_t {
  kNodes, kWeights, kRingStart, kRingEntry, kVertexMember, kMemberOffsets, kScratch, kPositions, kOut, kNormalOut,
  kSurfaceBindings
};

/// The push constants' layout of every shader (common.glsl's and surface.comp's: five words).
struct SurfacePush {
  std::uint32_t vertices = 0, mode = 0, flags = 0, unused0 = 0, unused1 = 0;
};

class VulkanSurfaces final : public DeviceSurfaces {
 public:
  VulkanSurfaces(const VulkanSurfaceSource& source, const std::vector<SurfaceMember>& members,
                 const std::vector<VulkanSurfaceBody>& bodies, bool separate)
      : src_(source), bodies_(bodies), separate_(separate) {
    vk::Context& ctx = *src_.ctx;
    const std::size_t rs = src_.isDouble ? sizeof(double) : sizeof(float);
    // Host tables: every member's vertices end to end, nodes in the device's numbering, rings in
    // the shared vertex numbering.
    std::vector<std::uint32_t> nodes, ringStart{0}, ringEntry, vertexMember, ring;
    std::vector<double> weights;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> pairs;
    for (std::size_t m = 0; m < members.size(); ++m) {
      const SurfaceBinding& b = *members[m].binding;
      const VulkanSurfaceBody& body = bodies_[m];
      const std::size_t first = vertices_;
      first_.push_back(first);
      count_.push_back(b.vertexCount());
      for (std::size_t v = 0; v < b.vertexCount(); ++v) {
        for (std::size_t k = 0; k < 4; ++k) {
          const std::uint32_t n = b.nodes[4 * v + k];
          const std::uint32_t local = body.deviceNode && !body.deviceNode->empty() ? (*body.deviceNode)[n] : n;
          nodes.push_back(static_cast<std::uint32_t>(body.nodeBegin + local));
          weights.push_back(b.weights[4 * v + k]);
        }
        oneRing(b, static_cast<std::uint32_t>(v), pairs, ring);
        for (std::uint32_t r : ring) ringEntry.push_back(static_cast<std::uint32_t>(first + r));
        ringStart.push_back(static_cast<std::uint32_t>(ringEntry.size()));
        vertexMember.push_back(static_cast<std::uint32_t>(m));
      }
      vertices_ += b.vertexCount();
    }
    // What the device cannot bind or dispatch is a DeviceError: the Simulation then computes these
    // surfaces on the host (or each body's on its own).
    const VkPhysicalDeviceLimits& limits = ctx.physical().limits;
    const std::size_t outBytes = vertices_ * (separate_ ? 3 : 6) * sizeof(float);
    const std::size_t largest = std::max({outBytes, 4 * vertices_ * rs, 4 * vertices_ * sizeof(std::uint32_t),
                                          ringEntry.size() * sizeof(std::uint32_t), 6 * members.size() * rs});
    if (largest > limits.maxStorageBufferRange || vertices_ >= (std::size_t{1} << 31) || ringEntry.size() >= (std::size_t{1} << 32))
      fail(ErrorCode::DeviceError, "Vulkan: ", vertices_, " surface vertices need a ", largest, "-byte buffer; '",
           ctx.physical().name, "' binds at most ", limits.maxStorageBufferRange, " bytes (maxStorageBufferRange)");
    if ((vertices_ + 63) / 64 > limits.maxComputeWorkGroupCount[0])
      fail(ErrorCode::DeviceError, "Vulkan: ", vertices_, " surface vertices need ", (vertices_ + 63) / 64,
           " work-groups; '", ctx.physical().name, "' dispatches at most ", limits.maxComputeWorkGroupCount[0]);
    auto uints = [&](const std::vector<std::uint32_t>& v) {
      vk::Buffer b(ctx, v.size() * sizeof(std::uint32_t), false);
      vk::uploadOnce(ctx, b, v.data(), v.size() * sizeof(std::uint32_t));
      return b;
    };
    buffers_.resize(kSurfaceBindings);
    buffers_[kNodes] = uints(nodes);
    {
      std::vector<unsigned char> bytes(weights.size() * rs);
      putReals(bytes.data(), src_.isDouble, 0, weights.size(), weights.size() + 1, [&](std::size_t i) { return weights[i]; });
      buffers_[kWeights] = vk::Buffer(ctx, bytes.size(), false);
      vk::uploadOnce(ctx, buffers_[kWeights], bytes.data(), bytes.size());
    }
    buffers_[kRingStart] = uints(ringStart);
    buffers_[kRingEntry] = uints(ringEntry);
    buffers_[kVertexMember] = uints(vertexMember);
    buffers_[kMemberOffsets] = vk::Buffer(ctx, 6 * members.size() * rs, false);
    buffers_[kScratch] = vk::Buffer(ctx, 3 * vertices_ * rs, false);
    const VkBufferUsageFlags vertexUsage = VK_BUFFER_USAGE_VERTEX_BUFFER_BIT;
    buffers_[kOut] = vk::Buffer(ctx, outBytes, false, vertexUsage);
    buffers_[kNormalOut] = vk::Buffer(ctx, separate_ ? 3 * vertices_ * sizeof(float) : 0, false, vertexUsage);
    placeholder_ = vk::Buffer(ctx, 0, false);
    down_ = vk::Buffer(ctx, 6 * vertices_ * sizeof(float), true);
    std::vector<const vk::Buffer*> set(31, &placeholder_);
    for (std::uint32_t i = 0; i < kSurfaceBindings; ++i) set[i] = &buffers_[i];
    set[kPositions] = src_.positions;
    set_ = ctx.descriptorSet(set);
  }

  ~VulkanSurfaces() override {
    try {
      src_.ctx->wait(submission_);
      src_.ctx->freeDescriptorSet(set_);
    } catch (...) {
    }
  }

  void update() override {
    vk::Context& ctx = *src_.ctx;
    // Each member's centroid c as chi + clo in the shader's precision (surface.comp).
    std::vector<double> offsets(6 * bodies_.size());
    for (std::size_t m = 0; m < bodies_.size(); ++m)
      for (int k = 0; k < 3; ++k) {
        const double c = bodies_[m].centroid ? bodies_[m].centroid[k] : 0.0;
        const double hi = src_.isDouble ? c : static_cast<double>(static_cast<float>(c));
        offsets[6 * m + k] = hi;
        offsets[6 * m + 3 + k] = c - hi;
      }
    const std::vector<unsigned char> bytes = realBytes(offsets, src_.isDouble);
    VkCommandBuffer cb = ctx.begin();
    vk::updateBuffer(cb, buffers_[kMemberOffsets], 0, bytes.data(), bytes.size());
    vk::fullBarrier(cb);
    SurfacePush push;
    push.vertices = static_cast<std::uint32_t>(vertices_);
    push.flags = separate_ ? 1u : 0u;
    vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, src_.pipeline);
    vkCmdBindDescriptorSets(cb, VK_PIPELINE_BIND_POINT_COMPUTE, ctx.pipelineLayout(), 0, 1, &set_, 0, nullptr);
    const std::uint32_t groups = static_cast<std::uint32_t>((vertices_ + 63) / 64);
    for (std::uint32_t mode : {0u, 1u}) {
      push.mode = mode;
      vkCmdPushConstants(cb, ctx.pipelineLayout(), VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(push), &push);
      vkCmdDispatch(cb, groups, 1, 1);
      if (mode == 0) vk::fullBarrier(cb);
    }
    vk::renderBarrier(cb);
    submission_ = ctx.submit();
  }

  void read(std::size_t member, float* positions, float* normals) override {
    vk::Context& ctx = *src_.ctx;
    const std::size_t first = first_.at(member), n = count_.at(member);
    VkCommandBuffer cb = ctx.begin();
    auto copy = [&](const vk::Buffer& from, std::size_t at, std::size_t to, std::size_t bytes) {
      if (bytes == 0) return;
      VkBufferCopy region{at, to, bytes};
      vkCmdCopyBuffer(cb, from.handle(), down_.handle(), 1, &region);
    };
    if (separate_) {
      copy(buffers_[kOut], 12 * first, 0, 12 * n);
      copy(buffers_[kNormalOut], 12 * first, 12 * n, 12 * n);
    } else {
      copy(buffers_[kOut], 24 * first, 0, 24 * n);
    }
    vk::hostReadBarrier(cb);
    ctx.wait(ctx.submit());
    const float* f = reinterpret_cast<const float*>(down_.mapped());
    for (std::size_t v = 0; v < n; ++v)
      for (std::size_t k = 0; k < 3; ++k) {
        positions[3 * v + k] = separate_ ? f[3 * v + k] : f[6 * v + k];
        normals[3 * v + k] = separate_ ? f[3 * n + 3 * v + k] : f[6 * v + 3 + k];
      }
  }

  GpuBuffer vertexBuffer(std::size_t member) const override { return region(buffers_[kOut], member, separate_ ? 12 : 24); }
  GpuBuffer normalBuffer(std::size_t member) const override {
    return separate_ ? region(buffers_[kNormalOut], member, 12) : GpuBuffer{};
  }
  bool separateStreams() const override { return separate_; }
  void finish() override { src_.ctx->wait(submission_); }

  std::vector<DeviceBuffer> buffers() const override {
    static const char* const names[kSurfaceBindings] = {
        "surface nodes", "surface weights", "surface ring starts", "surface ring entries", "surface vertex bodies",
        "surface body offsets", "surface positions (scratch)", "", "surface output", "surface normals"};
    std::vector<DeviceBuffer> out;
    for (std::uint32_t i = 0; i < kSurfaceBindings; ++i)
      if (i != kPositions && (i != kNormalOut || separate_)) out.push_back({names[i], buffers_[i].bytes()});
    out.push_back({"surface read-back (host)", down_.bytes()});
    return out;
  }

 private:
  GpuBuffer region(const vk::Buffer& b, std::size_t member, std::size_t stride) const {
    GpuBuffer g;
    g.api = GpuApi::Vulkan;
    g.handle = reinterpret_cast<std::uint64_t>(b.handle());
    g.offset = first_.at(member) * stride;
    g.stride = stride;
    g.bytes = count_.at(member) * stride;
    return g;
  }

  VulkanSurfaceSource src_;
  std::vector<VulkanSurfaceBody> bodies_;
  bool separate_ = false;
  std::size_t vertices_ = 0;
  std::vector<std::size_t> first_, count_;  ///< per member: its first vertex, its vertex count
  std::vector<vk::Buffer> buffers_;         ///< by SurfaceSlot (kPositions: empty, the device's)
  vk::Buffer placeholder_, down_;
  VkDescriptorSet set_ = VK_NULL_HANDLE;
  std::uint64_t submission_ = 0;  ///< the last update's (0: none)
};

}  // namespace

std::unique_ptr<DeviceSurfaces> createVulkanSurfaces(const VulkanSurfaceSource& source,
                                                     const std::vector<SurfaceMember>& members,
                                                     const std::vector<VulkanSurfaceBody>& bodies, bool separateStreams) {
  if (members.empty()) return nullptr;
  return std::make_unique<VulkanSurfaces>(source, members, bodies, separateStreams);
}

}  // namespace corofem::detail
