// The OpenCL device's render surfaces (opencl_surfaces.cpp).
#pragma once

#include "device/device.hpp"

#include <memory>
#include <vector>

namespace corofem::detail {

class SegmentEngine;

/// The surfaces of `members` over the engine's position buffer (null for no member). Throws
/// Error(DeviceError) where the device cannot allocate them together.
std::unique_ptr<DeviceSurfaces> createOpenCLSurfaces(SegmentEngine& engine, const std::vector<SurfaceMember>& members,
                                                     bool separateStreams);

}  // namespace corofem::detail
