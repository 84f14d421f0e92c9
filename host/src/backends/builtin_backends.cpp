// The backends compiled into this library, registered at the registry's first use
// (device/registry.hpp). A new backend adds its line here and its folder beside these.
#include "device/registry.hpp"

namespace corofem::detail {

void registerReferenceBackend();  // backends/reference/reference_device.cpp
void registerOpenCLBackend();     // backends/opencl/opencl_device.cpp, or opencl_unavailable.cpp
void registerVulkanBackend();     // backends/vulkan/vulkan_device.cpp, or vulkan_unavailable.cpp

void registerBuiltinBackends() {
  registerReferenceBackend();
  registerOpenCLBackend();
  registerVulkanBackend();
}

}  // namespace corofem::detail
