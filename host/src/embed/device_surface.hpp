// Internal: what DeviceSurface (device_surface.cpp) lays out on the device for a binding, so that the
// benchmark can count the bytes one frame moves (bench/bench_embed.cpp).
#pragma once

#include <corofem/embed.hpp>

#include <cstddef>

namespace corofem::detail {

/// The one-ring layout of DeviceSurface's normal pass (kernels/opencl/surface_update.cl).
struct DeviceSurfaceLayout {
  std::size_t slots = 0;             ///< K: ring slots per vertex (4 bytes each, read every frame)
  std::size_t overflowVertices = 0;  ///< vertices whose ring is longer than K (the third pass)
  std::size_t overflowEntries = 0;   ///< total length of those rings (4 bytes each)
};

/// The layout DeviceSurface::create builds for `binding` (the same function). Without OpenCL: zeros.
DeviceSurfaceLayout deviceSurfaceLayout(const SurfaceBinding& binding);

}  // namespace corofem::detail
