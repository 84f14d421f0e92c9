// The "vulkan" entry of a library built without the Vulkan backend: it lists no device, and asking
// for it gives a clear status, never a broken link.
#ifndef COROFEM_WITH_VULKAN

#include "device/registry.hpp"

namespace corofem::detail {

void registerVulkanBackend() {
  registerBackend(unavailableBackend(
      "vulkan", "the Vulkan backend is not compiled into this corofem build; install libvulkan-dev and glslc "
                "and reconfigure (-DCOROFEM_WITH_VULKAN=ON), or use \"backend\": \"opencl\" or \"reference\""));
}

}  // namespace corofem::detail

#endif
