// Coupled mesh (paper Section 5): a fine triangle surface bound to a coarse tetrahedral mesh.
//
// Once, before the simulation: every surface vertex is bound to one tetrahedron by its barycentric
// coordinates (the element that contains it; for a vertex outside the tet mesh, the nearest element,
// with extrapolated coordinates). Every frame: the vertices are recomputed from the deformed nodes,
//   x_v = sum_k w_vk x_{n_vk}      (k = 0..3, the nodes of the vertex's element),
// and smooth vertex normals are rebuilt from the deformed triangles, into a buffer a renderer draws.
//
//   auto binding = corofem::bindSurface(tetMesh, surface);           // Result<SurfaceBinding>
//   std::vector<float> vbo(6 * surface.vertexCount());                // px py pz nx ny nz per vertex
//   corofem::SurfaceOutput out;  out.interleaved = vbo.data();
//   corofem::deformSurface(*binding, positions.data(), tetMesh.nodeCount(), out);   // every frame
#pragma once

#include <corofem/gpu.hpp>
#include <corofem/mesh.hpp>
#include <corofem/status.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace corofem {

/// How bindSurface binds vertices.
struct BindingOptions {
  /// Largest distance (scene units, m by convention) from a vertex outside the tet mesh to its
  /// nearest element. Farther vertices make binding fail with ErrorCode::BadInput. Negative (the
  /// default): 5% of the diagonal of the tet mesh's bounding box. 0: every vertex must be inside
  /// (within insideTolerance). +infinity: no limit.
  double maxDistance = -1.0;
  /// A vertex is inside an element when all four barycentric coordinates are >= -insideTolerance
  /// (dimensionless, >= 0, typically 1e-12..1e-6). It absorbs rounding for vertices on element
  /// faces and on the tet mesh's boundary; such vertices count as inside with distance 0.
  double insideTolerance = 1e-10;
  /// Worker threads for the search (std::thread). 0: automatic (one per 20000 vertices, at most the
  /// hardware concurrency). The result does not depend on the thread count.
  int threads = 0;
};

/// Summary of a binding.
struct BindingStatistics {
  std::size_t insideCount = 0;    ///< vertices contained in an element (within insideTolerance)
  std::size_t outsideCount = 0;   ///< vertices bound to their nearest element by extrapolation
  double largestDistance = 0.0;   ///< largest vertex-to-tet-mesh distance (m), 0 when all are inside
  double maxDistanceUsed = 0.0;   ///< the effective BindingOptions::maxDistance (m)
  double boundingBoxDiagonal = 0.0;  ///< diagonal of the tet mesh's bounding box (m)
  std::vector<std::uint32_t> outsideVertices;  ///< indices of the outside vertices, ascending
  std::vector<double> outsideDistances;        ///< per outside vertex: its distance to its element (m)
};

/// A surface mesh bound to a tet mesh. Self-contained: deformSurface needs only this and the node
/// positions (the element's node indices and the surface triangles are copied in).
struct SurfaceBinding {
  std::size_t tetNodeCount = 0;          ///< node count of the tet mesh bound to (checked each frame)
  std::vector<std::uint32_t> element;    ///< per vertex: its element (0-based index into TetMesh::tets)
  std::vector<std::uint32_t> nodes;      ///< 4 per vertex: the element's node indices, in element order
  /// 4 per vertex: barycentric coordinates w_k of the vertex in its element's rest shape, in the order
  /// of `nodes`; they sum to 1. Each >= -insideTolerance for inside vertices; some are negative
  /// (extrapolation) for outside vertices.
  std::vector<double> weights;
  std::vector<std::uint32_t> triangles;  ///< 3 per triangle: the surface triangles (for normals)
  /// Vertex -> incident triangles (CSR): the triangles of vertex v are
  /// vertexTriangles[vertexTriangleOffsets[v] .. vertexTriangleOffsets[v+1]), ascending. Normals are
  /// gathered per vertex in this fixed order, so they do not depend on the thread count.
  std::vector<std::uint32_t> vertexTriangleOffsets;
  std::vector<std::uint32_t> vertexTriangles;
  BindingStatistics statistics;          ///< what the binding found

  std::size_t vertexCount() const { return element.size(); }
};

/// Binds every vertex of `surface` to an element of `tets` (spatial grid search; seconds for a
/// million vertices and 100k elements). A vertex contained in several elements (on a shared face,
/// edge or node) takes the lowest element index; a vertex outside takes the element at the smallest
/// true point-to-tetrahedron distance (ties: lowest index). Errors (ErrorCode::BadInput): empty
/// meshes, non-finite coordinates, indices out of range, flat elements, vertices farther than
/// maxDistance (the message counts and locates them).
Result<SurfaceBinding> bindSurface(const TetMesh& tets, const SurfaceMesh& surface,
                                   const BindingOptions& options = {});

/// Where deformSurface writes. Any pointer may be null (that stream is skipped); at least one must be
/// set. Buffers hold vertexCount() entries of the stated width.
struct SurfaceOutput {
  /// 6 floats per vertex: position x y z (m), then unit normal x y z; stride 24 bytes. The layout of an
  /// interleaved vertex buffer (position at offset 0, normal at offset 12).
  float* interleaved = nullptr;
  float* positions = nullptr;         ///< 3 floats per vertex (m)
  float* normals = nullptr;           ///< 3 floats per vertex, unit length (0 0 0 for a vertex with no
                                      ///< triangle or only degenerate ones)
  double* positionsDouble = nullptr;  ///< 3 doubles per vertex (m): full precision positions
  /// Worker threads. 0: automatic (hardware concurrency, one thread per 100k vertices at most). The
  /// output is bitwise identical for every thread count.
  int threads = 0;
};

/// Per-frame update of the coupled mesh. Positions x_v = sum_k w_vk x_{n_vk} (double arithmetic);
/// normals: n_v = normalise(sum over triangles t at v of (b-a) x (c-a)), the area-weighted mean of
/// the incident face normals, from the double positions. `tetNodePositions` holds 3 doubles per node
/// of the tet mesh (current positions), `tetNodeCount` nodes. Errors (ErrorCode::BadInput): node count
/// differs from the bound mesh's, no output set. Non-finite node positions propagate (no check per
/// frame). With normals, double scratch buffers (positions unless positionsDouble is given, face
/// vectors) are kept per calling thread, so frames do not reallocate. Deterministic: the same bits for
/// every thread count.
Status deformSurface(const SurfaceBinding& binding, const double* tetNodePositions,
                     std::size_t tetNodeCount, const SurfaceOutput& output);

namespace detail {
class DeviceSurfaceGroup;
}

/// Options of the per-frame update on an OpenCL device (DeviceSurface).
struct DeviceSurfaceOptions {
  /// Device selector, as for the OpenCL backend: "" = the first GPU, else the first device; a number
  /// = index in the list of all devices of all platforms; other text = a case-insensitive substring of
  /// the device name. Ignored when `context` is set.
  std::string device;
  /// Positions, weights and face vectors in double on the device (needs cl_khr_fp64); float when false.
  /// The output buffer is float either way. Node positions given to updateFromDevice() must be of this
  /// precision.
  bool doublePrecision = false;
  /// The application's own OpenCL context, queue and device (GpuApi::OpenCL, all three): the
  /// buffers and kernels live there (e.g. where a cl_mem shared with the renderer was created).
  /// Retained, not owned. None (the default): corofem's own, from `device`.
  ExternalDevice external;
  /// Output layout on the device: false (the default), one buffer of 6 floats per vertex (position,
  /// normal: SurfaceOutput::interleaved); true, two separate streams of 3 floats per vertex, the
  /// positions in vertexBuffer() and the normals in normalBuffer(), for renderers that bind them as
  /// separate vertex buffers. The same values either way, bit for bit.
  bool separateStreams = false;
  /// Vertices per work-item vector of the normal pass: 1, 8 or 16 (the same values, bit for bit,
  /// at any width); 0 = the device's (1 on GPUs, whose warps coalesce one vertex per work-item;
  /// 16 in float and 8 in double on CPU devices, one AVX-512 register).
  std::size_t normalPassLanes = 0;
};

/// One device buffer of a DeviceSurface: what it holds and its size as allocated.
struct DeviceSurfaceBuffer {
  std::string name;
  std::size_t bytes = 0;
};

/// The per-frame coupled-mesh update on an OpenCL device (kernels/opencl/surface_update.cl): the same
/// mathematics as deformSurface, into a device buffer of 6 floats per vertex (position, unit normal;
/// the SurfaceOutput::interleaved layout), or two buffers of 3 floats per vertex
/// (DeviceSurfaceOptions::separateStreams), that a renderer can draw from. Built only with
/// COROFEM_WITH_OPENCL; otherwise create() returns ErrorCode::NotCompiledIn.
///
///   auto gpu = corofem::DeviceSurface::create(binding);              // Result<DeviceSurface>
///   gpu->update(nodePositions, nodeCount);                            // every frame (enqueues)
///   gpu->read(vbo);                                                   // or draw from gpu->vertexBuffer()
class DeviceSurface {
 public:
  /// Uploads the binding (node indices, weights, triangles, adjacency) and builds the kernels.
  /// Errors: NotCompiledIn, DeviceError (no device, build or allocation failure), BadInput (double
  /// precision on a device without cl_khr_fp64, an inconsistent binding).
  static Result<DeviceSurface> create(const SurfaceBinding& binding, const DeviceSurfaceOptions& options = {});

  DeviceSurface(DeviceSurface&&) noexcept;
  DeviceSurface& operator=(DeviceSurface&&) noexcept;
  ~DeviceSurface();

  /// Copies the tet node positions (3 doubles per node, converted to the device precision) to the
  /// device and enqueues the update. Errors: BadInput (node count differs from the binding's),
  /// DeviceError.
  Status update(const double* tetNodePositions, std::size_t tetNodeCount);
  /// Enqueues the update from node positions already on the device (GpuApi::OpenCL: a cl_mem in
  /// this surface's context): 3 reals per node (float or double as
  /// DeviceSurfaceOptions::doublePrecision) from byte `positions.offset`, e.g. the simulation's
  /// own buffer. `offset` (3 doubles; nullptr = 0): the positions are relative to this point c, as
  /// the OpenCL backend keeps them relative to the body's centroid; the weights sum to 1, so the
  /// kernel writes x_v = sum_k w_vk (x_{n_vk} - c) + c (the normals do not depend on c).
  /// `firstNode`: node n of the tet mesh is node firstNode + n of the buffer (one buffer holding
  /// many bodies' nodes, as a batch does). Errors: BadInput for an empty handle, another API, an
  /// offset that is not a whole number of nodes, or a buffer too small for the nodes read (checked
  /// against its CL_MEM_SIZE); DeviceError.
  Status updateFromDevice(const GpuBuffer& positions, const double* offset = nullptr, std::size_t firstNode = 0);
  /// Blocking read of the output, 6 floats per vertex (waits for the enqueued update), in either
  /// layout (separate streams are interleaved on the host).
  Status read(float* interleaved) const;
  /// Blocking read of the output as two streams of 3 floats per vertex, positions and normals, in
  /// either layout (an interleaved buffer is split on the host). Errors: BadInput for a null pointer.
  Status read(float* positions, float* normals) const;
  /// The output buffer (GpuApi::OpenCL), owned by this object and valid for its lifetime: 6 *
  /// vertexCount() floats (interleaved, a 24-byte stride), or with separateStreams the 3 *
  /// vertexCount() floats of the positions (a 12-byte stride).
  GpuBuffer vertexBuffer() const;
  /// With separateStreams, the normals' buffer (3 * vertexCount() floats); empty otherwise.
  GpuBuffer normalBuffer() const;
  /// Whether the output is two streams (DeviceSurfaceOptions::separateStreams).
  bool separateStreams() const;
  /// Blocks until all enqueued work is done.
  Status finish() const;
  /// The device buffers it holds now, as allocated (an empty stream still takes a 16-byte buffer:
  /// OpenCL has no empty ones). The node positions' upload buffer appears after the first update()
  /// (updateFromDevice reads the caller's buffer and needs none).
  std::vector<DeviceSurfaceBuffer> buffers() const;
  std::size_t allocatedBytes() const;  ///< the sum of buffers()

  std::size_t vertexCount() const;
  std::string deviceName() const;  ///< the device the kernels run on

 private:
  friend class detail::DeviceSurfaceGroup;  // many bodies' surfaces in one set of launches (internal)
  struct Impl;
  explicit DeviceSurface(std::unique_ptr<Impl> impl);
  /// create() without the Result: `bodies` > 0 builds the many-body kernels (blockBody: the body of
  /// each block of the normal pass's vectors). Throws Error.
  static DeviceSurface make(const SurfaceBinding& binding, const DeviceSurfaceOptions& options, std::size_t bodies,
                            const std::vector<std::uint32_t>* blockBody);
  std::unique_ptr<Impl> impl_;
};

}  // namespace corofem
