// A StepStore (solve/step_store.hpp) whose vectors live in a Vulkan device's memory, in the
// device's numbering and precision, and whose five per-dof passes run there (kernels/vulkan/
// step.comp): the first step of the Vulkan issue's device-resident step. The host reads a body's
// sums, and a vector only when it asks for one (state(), scratch()).
//
// The device calls (positions, forces, damping, the solve) read and write the store's buffers on
// the device. The dynamics driver takes this store where VulkanTuning::deviceStore asks for it. A
// device lost with the state loses it (no host copy is kept): the driver restarts those bodies at
// rest on the next device (DynamicsDriver::followDevice).
#pragma once

#include "device/body_layout.hpp"
#include "solve/step_store.hpp"

#include <memory>
#include <vector>

namespace corofem::detail {

namespace vk {
class Context;
}
namespace vkdevice {
class VulkanDevice;
}

/// A store on `device`'s context for the slot's bodies laid out as `segments` (the device's: the
/// same nodes, in its order; `nodeTotal` padded nodes in all), in double where `isDouble`, else
/// float. Its device calls read and write its buffers on the device while the slot holds `device`,
/// and go through the slot with host vectors after it moved to another device; a DeviceError in one
/// of them moves the slot to its next candidate (DeviceSlot::failover, the positions from the
/// store) and repeats the call there. Its owner drops the slot's position source (DeviceSlot::
/// dropPositionSource) before it replaces the store. Throws Error(DeviceError) for a failed Vulkan
/// call.
std::unique_ptr<StepStore> createVulkanStepStore(vkdevice::VulkanDevice& device, std::shared_ptr<vk::Context> ctx,
                                                 bool isDouble, const std::vector<BodySegment>& segments,
                                                 std::size_t nodeTotal, DeviceSlot& slot);

}  // namespace corofem::detail
