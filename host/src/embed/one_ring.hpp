// The one-ring of a surface vertex, written once for every device's surface pass (OpenCL:
// kernels/opencl/surface_update.cl, Vulkan: kernels/vulkan/surface.comp).
#pragma once

#include <corofem/embed.hpp>

#include <cstdint>
#include <utility>
#include <vector>

namespace corofem::detail {

/// The one-ring of vertex v: a sequence r_0..r_{L-1} such that
///   n_v = sum_i (x_{r_i} - x_v) x (x_{r_{i+1 mod L}} - x_v)
/// is the sum of the face vectors of v's triangles (the area-weighted normal of deformSurface, to
/// the rounding). Each triangle (a, b, c) at v gives the pair (p, q) that follows v in its cyclic
/// order ((b, c) at a, (c, a) at b, (a, b) at c). Pairs are chained where one's q is the next one's
/// p (a fan); a vertex whose pairs form one closed fan gets just the fan, rotated to start at its
/// smallest index (so that on a mesh numbered row by row the slots of consecutive vertices are
/// consecutive vertices: one vector load in the OpenCL kernel); otherwise each fan is followed by v
/// itself (terms with v are exactly 0), a closed one after repeating its first vertex. Degenerate
/// triangles (a repeated index, face vector exactly 0 on the host too) are left out; a vertex
/// without a triangle gets an empty ring. Deterministic: fans are started at open ends first, then
/// in the binding's (ascending) triangle order. `pairs` is scratch.
void oneRing(const SurfaceBinding& b, std::uint32_t v, std::vector<std::pair<std::uint32_t, std::uint32_t>>& pairs,
             std::vector<std::uint32_t>& out);

}  // namespace corofem::detail
