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
  /// Ring entries the normal pass reads per frame with its vectors of `lanes` vertices, over the
  /// padded vertex count (4 bytes each): none for a slot that holds consecutive vertices across its
  /// block, one per lane otherwise; and the blocks' run words (K + 1 per block, 4 bytes each; none
  /// with one lane).
  std::size_t ringEntriesRead = 0;
  std::size_t runWords = 0;
};

/// The layout DeviceSurface::create builds for `binding` with normal-pass vectors of `lanes` vertices
/// (the same functions). Without OpenCL: zeros.
DeviceSurfaceLayout deviceSurfaceLayout(const SurfaceBinding& binding, std::size_t lanes);

/// Vertices per work-item vector in the normal pass, as DeviceSurface::create chooses them:
/// COROFEM_SURFACE_LANES (1, 8 or 16; another value throws Error(BadInput) naming the fix), else 1 on
/// GPUs, 16 in float and 8 in double on CPUs.
std::size_t surfaceLanes(bool gpu, bool doublePrecision);

}  // namespace corofem::detail
