// The Vulkan backend's device (vulkan_device.cpp) and its registry entry (vulkan_backend.cpp).
#pragma once

#include "device/device.hpp"

#include <corofem/gpu.hpp>
#include <corofem/tuning.hpp>

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

/// A device on Vulkan physical device `index` (vk::Instance::devices()) holding `problems`.
/// Throws Error(BadInput) for what it refuses (vulkanRefusal), Error(DeviceError) for a device that
/// cannot be used (no shaderFloat64 for double, buffers beyond its limits, a failed Vulkan call).
std::unique_ptr<Device> createVulkanDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                           std::size_t index, const VulkanTuning& tuning);

/// A device on the application's Vulkan device (SimulationOptions::device). Throws as above, and
/// Error(BadInput) for handles that cannot be used (vk::Context).
std::unique_ptr<Device> createVulkanDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                           const ExternalDevice& external, const VulkanTuning& tuning);

/// Why the backend cannot run a body with these settings ("" where it can), naming the fix: the
/// registry entry's `refuses`, and the device's constructor.
std::string vulkanRefusal(const Problem& p, const SolverDesc& s);

}  // namespace corofem::detail
