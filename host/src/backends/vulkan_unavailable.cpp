// The "vulkan" entry of a library built without the Vulkan backend: it lists no device, and asking
// for it gives a clear status, never a broken link.
#ifndef COROFEM_WITH_VULKAN

#include "device/registry.hpp"
#include "util/error.hpp"

namespace corofem::detail {

namespace {

[[noreturn]] void notCompiledIn() {
  fail(ErrorCode::NotCompiledIn,
       "the Vulkan backend is not compiled into this corofem build; install libvulkan-dev and glslc and "
       "reconfigure (-DCOROFEM_WITH_VULKAN=ON), or use \"backend\": \"opencl\" or \"reference\"");
}

}  // namespace

void registerVulkanBackend() {
  BackendEntry e;
  e.name = "vulkan";
  e.candidates = [] { return std::vector<Candidate>{}; };
  e.resolve = [](const std::string&) -> Candidate { notCompiledIn(); };
  e.refuses = [](const Problem&, const SolverDesc&) -> std::string { notCompiledIn(); };
  e.create = [](const std::vector<const Problem*>&, const SolverDesc&, const Candidate&,
                const DeviceOptions&) -> std::unique_ptr<Device> { notCompiledIn(); };
  registerBackend(std::move(e));
}

}  // namespace corofem::detail

#endif
