// Internal: what DeviceSurface (device_surface.cpp) lays out on the device for a binding, so that the
// benchmark can count the bytes one frame moves (bench/bench_embed.cpp).
#pragma once

#include <corofem/embed.hpp>
#include <corofem/gpu.hpp>

#include <cstddef>
#include <memory>
#include <vector>

struct _cl_mem;  // cl_mem, as CL/cl.h declares it (this header is included without OpenCL too)

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
/// `requested` (DeviceSurfaceOptions::normalPassLanes: 1, 8 or 16; another value throws
/// Error(BadInput) naming the fix), or for 0 the device's: 1 on GPUs, 16 in float and 8 in double
/// on CPUs.
std::size_t surfaceLanes(bool gpu, bool doublePrecision, std::size_t requested = 0);

/// Many bodies' render surfaces updated in one set of launches: the bodies of a batch, whose node
/// positions share one device buffer (body m's nodes from node firstNode on, relative to its own
/// centroid). One DeviceSurface over the bodies' bindings laid end to end (each starting at a vector
/// block and at an address a sub-buffer may start at, the gaps filled with vertices of no triangle),
/// whose normal pass reads each block's body offset from a table (SURF_MULTI). Every body's output
/// is a sub-buffer of the shared output: what a renderer draws, as DeviceSurface::vertexBuffer. The
/// same bits as a DeviceSurface per body. Throws Error (BadInput, DeviceError, NotCompiledIn).
class DeviceSurfaceGroup {
 public:
  struct Member {
    const SurfaceBinding* binding = nullptr;
    std::size_t firstNode = 0;  ///< the body's first node in the position buffer
  };
  /// `positionNodes`: the nodes the position buffer holds; options: its context, queue and device,
  /// its precision, and the output layout.
  DeviceSurfaceGroup(const std::vector<Member>& members, std::size_t positionNodes, const DeviceSurfaceOptions& options);
  ~DeviceSurfaceGroup();
  std::size_t size() const;
  /// Enqueues every body's update from the shared position buffer, body m relative to centroids[m]
  /// (3 doubles). Does not wait, except for the previous update's write of the offsets (whose host
  /// bytes this one rewrites).
  void update(_cl_mem* positions, const std::vector<const double*>& centroids);
  GpuBuffer vertexBuffer(std::size_t m) const;  ///< body m's output (positions alone when separate)
  GpuBuffer normalBuffer(std::size_t m) const;  ///< body m's normals with separate streams, else empty
  bool separateStreams() const;
  /// Blocking read of body m's output as two streams of 3 floats per vertex.
  void read(std::size_t m, float* positions, float* normals) const;
  void finish() const;
  std::vector<DeviceSurfaceBuffer> buffers() const;  ///< the shared buffers, as allocated
  std::size_t allocatedBytes() const;

 private:
  struct State;
  std::unique_ptr<State> s_;
};

}  // namespace corofem::detail
