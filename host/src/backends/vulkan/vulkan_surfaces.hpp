// The Vulkan device's render surfaces (the coupled mesh, paper Sec. 5): kernels/vulkan/surface.comp
// over the device's own positions, into a VkBuffer a renderer draws from (vertex-buffer usage).
#pragma once

#include "backends/vulkan/vk_runtime.hpp"
#include "device/device.hpp"

#include <cstdint>
#include <memory>
#include <vector>

namespace corofem::detail {

/// Where one member's tet nodes are in the device's positions.
struct VulkanSurfaceBody {
  std::size_t nodeBegin = 0;                             ///< its first device node
  const std::vector<std::uint32_t>* deviceNode = nullptr;  ///< problem node -> segment node (empty: the same)
  const double* centroid = nullptr;  ///< 3 doubles, subtracted from its positions (read at each update)
};

/// What the device lends its surfaces; the positions buffer and the bodies' tables must outlive
/// every update() (the Simulation makes the surfaces again after a device changes).
struct VulkanSurfaceSource {
  std::shared_ptr<vk::Context> ctx;
  const vk::Buffer* positions = nullptr;  ///< 3 reals per device node, relative to the centroid
  VkPipeline pipeline = VK_NULL_HANDLE;   ///< surface.comp in the device's precision
  bool isDouble = false;
};

/// The surfaces of `members` (bodies[i] the place of members[i]'s body) in one buffer set and two
/// dispatches per update. Throws Error(DeviceError) where the buffers cannot be allocated.
std::unique_ptr<DeviceSurfaces> createVulkanSurfaces(const VulkanSurfaceSource& source,
                                                     const std::vector<SurfaceMember>& members,
                                                     const std::vector<VulkanSurfaceBody>& bodies, bool separateStreams);

}  // namespace corofem::detail
