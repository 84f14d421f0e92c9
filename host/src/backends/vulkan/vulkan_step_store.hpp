// A StepStore (solve/step_store.hpp) whose vectors live in a Vulkan device's memory, in the
// device's numbering and precision, and whose five per-dof passes run there (kernels/vulkan/
// step.comp): the first step of the Vulkan issue's device-resident step. The host reads a body's
// sums, and a vector only when it asks for one (state(), scratch()).
//
// Where it stands: the passes, the state transfers, swaps and copies are the device's. The device
// calls (positions, forces, damping, the solve) still take their vectors through the host, so the
// dynamics driver keeps the host's store (createHostStepStore) until they read the store's buffers
// on the device and a failover can restart a step from a host copy of the committed state.
#pragma once

#include "device/body_layout.hpp"
#include "solve/step_store.hpp"

#include <memory>
#include <vector>

namespace corofem::detail {

namespace vk {
class Context;
}

/// A store on `ctx` for the slot's bodies laid out as `segments` (the device's: the same nodes, in
/// its order; `nodeTotal` padded nodes in all), in double where `isDouble`, else float. Throws
/// Error(DeviceError) for a failed Vulkan call.
std::unique_ptr<StepStore> createVulkanStepStore(std::shared_ptr<vk::Context> ctx, bool isDouble,
                                                 const std::vector<BodySegment>& segments, std::size_t nodeTotal,
                                                 const DeviceSlot& slot);

}  // namespace corofem::detail
