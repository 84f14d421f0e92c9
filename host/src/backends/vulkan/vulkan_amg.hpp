// The "amg" preconditioner on the Vulkan device: the bodies' hierarchies and their layout from
// device/device_amg.hpp (the OpenCL engine's, written once), packed into four buffers, and the
// V-cycle of kernels/vulkan/amg.comp recorded between pcg.comp's pass (which forms r and the node
// blocks' inverses) and the product w = A u, as the OpenCL engine runs amg.cl.
//
// Per PCG iteration: 5 products of the current operator (the PCG's own and 4 in level 0's
// smoothing), and per coarser level 6 sparse products and 5 vector passes; the host reads nothing.
// Host work per solve: a body's hierarchy where it has none for the solve's ratio of mass to
// stiffness, its upload, and the warp (one rotation per level-0 aggregate, recorded with
// vkCmdUpdateBuffer) where its positions changed.
#pragma once

#include "backends/vulkan/vk_runtime.hpp"
#include "device/device_amg.hpp"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <utility>
#include <vector>

namespace corofem::detail {

/// The push constants of every corofem shader: common.glsl's five words, and amg.comp's row count
/// and offsets. The pipeline layout's push range is its size.
struct VulkanPush {
  std::uint32_t S = 0, mode = 0, flags = 0, precond = 0, rotation = 0;
  std::uint32_t rows = 0;
  std::uint32_t o[6] = {0, 0, 0, 0, 0, 0};
};

/// What the Vulkan device lends its multigrid.
struct VulkanAmgHost {
  std::shared_ptr<vk::Context> ctx;
  bool isDouble = false;
  const std::vector<BodySegment>* segments = nullptr;
  std::size_t nodeTotal = 0;
  /// The device's buffers by binding (common.glsl); the multigrid's descriptor set replaces some.
  const std::vector<vk::Buffer>* shared = nullptr;
  /// The PCG's u (M^-1 r, the V-cycle's output), one of `shared`.
  const vk::Buffer* u = nullptr;
  /// A descriptor set of the device's bindings with a product's input and output.
  std::function<VkDescriptorSet(const vk::Buffer& in, const vk::Buffer& out)> productSet;
  /// Records y = A p (projected) on a set of productSet, with the solve's coefficients.
  std::function<void(VkCommandBuffer, VkDescriptorSet)> product;
  /// Records a compute dispatch of `groups` work-groups with a full barrier after it.
  std::function<void(VkCommandBuffer, VkPipeline, VkDescriptorSet, const VulkanPush&, std::uint32_t groups)> dispatch;
};

class VulkanAmg {
 public:
  explicit VulkanAmg(VulkanAmgHost host);
  ~VulkanAmg();
  VulkanAmg(const VulkanAmg&) = delete;
  VulkanAmg& operator=(const VulkanAmg&) = delete;

  void positionsSet(const BodySet& bodies, const ConstVectors& x) { amg_.positionsSet(bodies, x); }
  void invalidate(std::size_t segment) { amg_.invalidate(segment); }
  void constraintsChanged(std::size_t segment) { amg_.constraintsChanged(segment); }
  long long builds() const { return amg_.builds(); }

  /// Before recording a solve of `running` (coefficients: (mass, stiffness) per running body):
  /// their hierarchies, and the device's copy of the layout where it changed (waits for its upload).
  void prepare(const BodySet& running, const std::vector<std::pair<double, double>>& coefficients);
  /// Records the warps of the running bodies whose positions changed.
  void recordWarps(VkCommandBuffer cb, const BodySet& running);
  /// Records u = M^-1 r on the active segments with the partial sums pcg.comp leaves (r . u, r . r,
  /// and |free b|^2 with `setup`). The coarse levels run over every body's rows (a stopped body's
  /// are scratch no active segment reads).
  void recordCycle(VkCommandBuffer cb, bool setup);
  std::vector<DeviceBuffer> buffers() const;

 private:
  /// A sliced-ELLPACK matrix (or the CSR of a coarsest inverse) in the packed buffers.
  struct Matrix {
    std::size_t rows = 0;
    std::uint32_t start = 0, cols = 0, values = 0;  ///< offsets: amgIdx, amgIdx, amgVal (or amgInv)
  };
  struct Level {
    std::size_t rows = 0;
    Matrix A, P, Pt, inverse;
    std::size_t inverseEntries = 0;
    bool smooths = false;
    std::uint32_t dinv = 0;                 ///< amgVal offset
    std::uint32_t b = 0, x = 0, res = 0, d = 0, t = 0;  ///< amgVec offsets
  };
  void upload();
  void spmv(VkCommandBuffer cb, const Matrix& m, std::uint32_t x, std::uint32_t b, bool residual, std::uint32_t y) const;
  void coarse(VkCommandBuffer cb, std::size_t k) const;
  void fine(VkCommandBuffer cb, std::uint32_t mode, std::uint32_t flags) const;
  void rows(VkCommandBuffer cb, std::uint32_t mode, std::size_t rows, std::uint32_t flags,
            std::initializer_list<std::uint32_t> offsets) const;

  VulkanAmgHost host_;
  DeviceAmg amg_;
  std::size_t rs_ = sizeof(float);
  VkPipeline pipeline_ = VK_NULL_HANDLE;
  vk::Buffer res0_, d0_, ad0_;           ///< level 0's Chebyshev residual, step and A d
  vk::Buffer idx_, val_, vec_, inv_;     ///< the packed buffers of amg.comp
  VkDescriptorSet set_ = VK_NULL_HANDLE;               ///< amg.comp's
  VkDescriptorSet productD_ = VK_NULL_HANDLE, productU_ = VK_NULL_HANDLE;  ///< A d0, A u into ad0
  Matrix P0_, Pt0_;
  std::vector<Level> levels_;
  std::uint32_t scale_ = 0, rotations_ = 0, nodeAggregate_ = 0;  ///< amgVal, amgVal, amgIdx offsets
};

}  // namespace corofem::detail
