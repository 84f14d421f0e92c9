// DeviceSurface: the per-frame coupled-mesh update on an OpenCL device (kernels/opencl/surface_update.cl),
// the same mathematics as deformSurface (deform_surface.cpp): positions, then per vertex the normal from
// its one-ring (the ring layout is built here, once). A build without OpenCL has the stubs of
// backends/device_surface_unavailable.cpp instead, which report ErrorCode::NotCompiledIn.
#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/device_surface.hpp"

#include <corofem/embed.hpp>

#include "embed/one_ring.hpp"
#include "util/error.hpp"

#include "backends/opencl/cl_check.hpp"
#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/program_cache.hpp"

#include <algorithm>
#include <bitset>
#include <cstring>
#include <limits>
#include <numeric>
#include <vector>

#include <atomic>
#include <cstdlib>
#include <string>
#include <utility>

namespace corofem {

namespace detail {
std::size_t surfaceLanes(bool gpu, bool doublePrecision, std::size_t requested) {
  if (requested != 0) {
    if (requested != 1 && requested != 8 && requested != 16)
      fail(ErrorCode::BadInput, "DeviceSurfaceOptions::normalPassLanes = ", requested, ": give 1, 8 or 16 (vertices "
           "per work-item vector in the surface normal pass), or 0 for the device's default");
    return requested;
  }
  // CPUs: vectors of 16 floats or 8 doubles (one AVX-512 register, two AVX2 ones). GPUs: one vertex
  // per work-item (SURF_W = 1): a warp's loads of consecutive vertices coalesce, while 16-wide
  // vectors per work-item cost registers and leave 16x fewer work-items.
  return gpu ? 1 : doublePrecision ? 8 : 16;
}

}  // namespace detail

struct EmbeddedSource {
  const char* name;
  const char* text;
};
extern const EmbeddedSource corofem_opencl_sources[];
extern const std::size_t corofem_opencl_sources_count;

namespace {

using detail::fail;
using detail::oneRing;
using detail::cl::checkCl;

/// The surface program: the shared layout header(s), then surface_update.cl (the rest of the
/// corofem kernels are not needed).
std::string surfaceProgramSource() {
  std::string headers, kernel;
  for (std::size_t i = 0; i < corofem_opencl_sources_count; ++i) {
    const EmbeddedSource& s = corofem_opencl_sources[i];
    const std::string name = s.name;
    const std::string piece = "#line 1 \"" + name + "\"\n" + s.text + "\n";
    if (name.size() > 2 && name.compare(name.size() - 2, 2, ".h") == 0) headers += piece;
    else if (name == "surface_update.cl") kernel = piece;
  }
  if (kernel.empty())
    fail(ErrorCode::Internal, "DeviceSurface: kernels/opencl/surface_update.cl is not embedded in this build");
  return "#define COROFEM_EMBEDDED 1\n" + headers + kernel;
}

/// RAII for a cl_mem / cl_kernel.
struct MemRelease {
  void operator()(_cl_mem* m) const {
    if (m) clReleaseMemObject(m);
  }
};
struct KernelRelease {
  void operator()(_cl_kernel* k) const {
    if (k) clReleaseKernel(k);
  }
};
using Mem = std::unique_ptr<_cl_mem, MemRelease>;
using Kernel = std::unique_ptr<_cl_kernel, KernelRelease>;

/// The streams' stride: the vertex count rounded up to whole blocks of every vector width.
std::size_t paddedVertexCount(std::size_t n) { return (n + 63) / 64 * 64; }

/// The most ring slots per vertex (longer rings go to the overflow pass).
constexpr std::size_t kMaxRingSlots = 32;

/// The ring slots of every vertex (structure of arrays, stride `stride`), K = `slots` per vertex,
/// and the rings longer than K. K minimises the bytes read per frame: K per vertex (4 bytes each) plus
/// the overflow rings, counted 8 times over (their kernel runs one work-item per vertex, serially).
struct RingLayout {
  cl_uint slots = 1;
  std::vector<cl_uint> ring;  ///< slots * stride
  std::vector<cl_uint> overflowVertices, overflowOffsets{0}, overflowSequence;
};

RingLayout ringLayout(const SurfaceBinding& b, std::size_t stride) {
  const std::size_t n = b.vertexCount();
  std::vector<std::vector<std::uint32_t>> rings(n);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> pairs;
  std::vector<std::size_t> longer(kMaxRingSlots + 2, 0);  // longer[k]: sum of the lengths L > k
  for (std::size_t v = 0; v < n; ++v) {
    oneRing(b, static_cast<std::uint32_t>(v), pairs, rings[v]);
    const std::size_t length = rings[v].size();
    for (std::size_t k = 1; k <= kMaxRingSlots; ++k)
      if (length > k) longer[k] += length;
  }
  RingLayout layout;
  std::size_t best = std::numeric_limits<std::size_t>::max();
  for (std::size_t k = 1; k <= kMaxRingSlots; ++k) {
    const std::size_t cost = n * k + 8 * longer[k];
    if (cost < best) best = cost, layout.slots = static_cast<cl_uint>(k);
  }
  const std::size_t K = layout.slots;
  layout.ring.resize(K * stride);
  for (std::size_t v = 0; v < stride; ++v) {
    const cl_uint self = static_cast<cl_uint>(v);
    std::vector<std::uint32_t> empty;
    std::vector<std::uint32_t>& r = v < n ? rings[v] : empty;
    std::size_t used = 0;
    if (r.size() > K) {  // pass 3 computes this vertex's normal; pass 2 sees only v (normal 0)
      layout.overflowVertices.push_back(self);
      layout.overflowSequence.insert(layout.overflowSequence.end(), r.begin(), r.end());
      layout.overflowOffsets.push_back(static_cast<cl_uint>(layout.overflowSequence.size()));
    } else {
      for (; used < r.size(); ++used) layout.ring[used * stride + v] = r[used];
      // A closed single fan shorter than K: close it explicitly (r_{L-1}, r_0) before padding with v.
      if (used > 0 && used < K && r.back() != self) layout.ring[used++ * stride + v] = r.front();
    }
    for (; used < K; ++used) layout.ring[used * stride + v] = self;
  }
  return layout;
}

/// Per block of `lanes` vertices (the normal pass's vectors), slots + 1 words: bit i of the first set
/// when ring slot i of the block holds `lanes` consecutive vertices r, r + 1, ..., and word 1 + i = r
/// for such a slot (0 otherwise). The kernel then loads the neighbours as vectors from r without
/// reading the slot's ring entries (surface_update.cl, SURF_NEIGHBOUR). Empty with one lane (GPUs).
std::vector<cl_uint> blockRuns(const RingLayout& layout, std::size_t stride, std::size_t lanes) {
  std::vector<cl_uint> runs;
  if (lanes <= 1) return runs;
  static_assert(kMaxRingSlots <= 32, "one bit per slot in a 32-bit word");
  const std::size_t K = layout.slots, words = K + 1;
  runs.assign(stride / lanes * words, 0);
  for (std::size_t b = 0; b < stride / lanes; ++b)
    for (std::size_t i = 0; i < K; ++i) {
      const cl_uint* r = &layout.ring[i * stride + b * lanes];
      bool run = true;
      for (std::size_t l = 1; l < lanes && run; ++l) run = r[l] == r[0] + l;
      if (run) {
        runs[b * words] |= cl_uint{1} << i;
        runs[b * words + 1 + i] = r[0];
      }
    }
  return runs;
}

}  // namespace

namespace detail {
DeviceSurfaceLayout deviceSurfaceLayout(const SurfaceBinding& binding, std::size_t lanes) {
  const std::size_t stride = paddedVertexCount(binding.vertexCount());
  const RingLayout layout = ringLayout(binding, stride);
  const std::vector<cl_uint> runs = blockRuns(layout, stride, lanes);
  DeviceSurfaceLayout out{layout.slots, layout.overflowVertices.size(), layout.overflowSequence.size(),
                          layout.slots * stride, runs.size()};
  for (std::size_t b = 0; b < runs.size(); b += layout.slots + 1)  // a run slot's entries: not read
    out.ringEntriesRead -= std::bitset<32>(runs[b]).count() * lanes;
  return out;
}
}  // namespace detail

struct DeviceSurface::Impl {
  std::shared_ptr<detail::cl::Context> ctx;
  bool doublePrecision = false;
  std::size_t realSize = 4;
  cl_uint vertexCount = 0, stride = 0, overflowCount = 0;
  std::size_t nodeCount = 0;
  // Work per work-item and work-group sizes (create()): on a CPU several vertices per work-item
  // amortise PoCL's per-work-item cost; on a GPU one.
  std::size_t positionsPerItem = 1, blocksPerItem = 1, lanes = 16, positionsLocal = 64, normalsLocal = 64;
  Mem nodes, weights, ring, ringRuns, x, pos, out, normalsOut, overflowVertices, overflowOffsets, overflowSequence;
  std::size_t bodies = 0;  ///< many bodies (DeviceSurfaceGroup): their count; 0 for one
  Mem blockBody, bodyOffsets;
  bool separate = false;  ///< DeviceSurfaceOptions::separateStreams: out holds positions, normalsOut normals
  Kernel positions, normals, overflow;
  std::vector<unsigned char> staging;  // node positions converted to the device precision
  std::vector<DeviceSurfaceBuffer> allocated;  ///< every buffer() made, in order (buffers())

  const std::string& device() const { return ctx->deviceName(); }

  Mem buffer(cl_mem_flags flags, std::size_t bytes, const void* host, const char* what) {
    cl_int status = CL_SUCCESS;
    // Zero-sized buffers are invalid in OpenCL: allocate one element for empty streams.
    cl_mem m = clCreateBuffer(ctx->context(), flags | (host && bytes ? CL_MEM_COPY_HOST_PTR : 0),
                              bytes ? bytes : 16, bytes ? const_cast<void*>(host) : nullptr, &status);
    if (status != CL_SUCCESS)
      fail(ErrorCode::DeviceError, "DeviceSurface: allocating the ", what, " buffer (", bytes, " bytes) failed with ",
           detail::cl::errorString(status), " on device '", device(), "'");
    allocated.push_back({what, bytes ? bytes : 16});
    return Mem(m);
  }

  Kernel kernel(cl_program program, const char* name) {
    cl_int status = CL_SUCCESS;
    cl_kernel k = clCreateKernel(program, name, &status);
    checkCl(status, name, device());
    return Kernel(k);
  }

  template <class T>
  void arg(cl_kernel k, cl_uint index, const T& value) {
    checkCl(clSetKernelArg(k, index, sizeof(T), &value), "clSetKernelArg", device());
  }

  /// Copies 3 floats per vertex from src (every `from` floats) to dst (every `to` floats): the
  /// host-side change between the interleaved layout and separate streams.
  static void copyTriples(const float* src, std::size_t from, float* dst, std::size_t to, std::size_t n) {
    for (std::size_t v = 0; v < n; ++v)
      for (int c = 0; c < 3; ++c) dst[to * v + c] = src[from * v + c];
  }

  /// Blocking read of `floats` floats of `buffer`, from float `first` on, into `dst`.
  void readBuffer(cl_mem buffer, std::size_t floats, float* dst, const char* what, std::size_t first = 0) const {
    checkCl(clEnqueueReadBuffer(ctx->queue(), buffer, CL_TRUE, first * sizeof(float), floats * sizeof(float), dst, 0,
                                nullptr, nullptr),
            (std::string("clEnqueueReadBuffer (") + what + ")").c_str(), device());
  }

  /// `items` work-items in work-groups of `local` (clamped to the device's limit; the kernels skip
  /// the padding work-items): leaving the size to the runtime lets some (PoCL) pick tiny groups.
  void enqueue(cl_kernel k, std::size_t items, std::size_t local, const char* name) {
    if (items == 0) return;
    local = std::clamp<std::size_t>(ctx->info().maxWorkGroupSize, 1, local);
    const std::size_t global = (items + local - 1) / local * local;
    checkCl(clEnqueueNDRangeKernel(ctx->queue(), k, 1, nullptr, &global, &local, 0, nullptr, nullptr), name,
            device());
  }

  /// c = hi + lo in the real type R of the device: in float lo carries what float(c) drops, so the
  /// output rounds once (surface_update.cl); in double lo is 0.
  template <class R>
  static std::pair<R, R> splitOffset(double c) {
    const R hi = static_cast<R>(c);
    return {hi, static_cast<R>(c - static_cast<double>(hi))};
  }

  /// Sets the offset c added to the written positions (kernel arguments 5-7 and 8-10).
  void setOffset(const double* c) {
    for (cl_uint a = 0; a < 3; ++a) {
      const double value = c ? c[a] : 0.0;
      if (doublePrecision) {
        const auto [hi, lo] = splitOffset<double>(value);
        arg(normals.get(), 5 + a, hi);
        arg(normals.get(), 8 + a, lo);
      } else {
        const auto [hi, lo] = splitOffset<float>(value);
        arg(normals.get(), 5 + a, hi);
        arg(normals.get(), 8 + a, lo);
      }
    }
  }

  /// Blocking read of vertices first .. first + n - 1 as two streams of 3 floats per vertex, from
  /// either layout (an interleaved buffer is split on the host).
  void readStreams(std::size_t first, std::size_t n, float* positions, float* normals) const {
    if (separate) {
      readBuffer(out.get(), 3 * n, positions, "surface positions", 3 * first);
      readBuffer(normalsOut.get(), 3 * n, normals, "surface normals", 3 * first);
      return;
    }
    std::vector<float> interleaved(6 * n);
    readBuffer(out.get(), 6 * n, interleaved.data(), "surface vertices", 6 * first);
    copyTriples(interleaved.data(), 6, positions, 3, n);
    copyTriples(interleaved.data() + 3, 6, normals, 3, n);
  }

  /// Enqueues the passes reading node positions from `xBuffer`, the body's from node `firstNode` on
  /// (relative to `offset`, 3 doubles or nullptr for absolute positions).
  void run(cl_mem xBuffer, const double* offset = nullptr, std::size_t firstNode = 0) {
    setOffset(offset);
    arg(positions.get(), 4, xBuffer);
    arg(positions.get(), 6, static_cast<cl_uint>(firstNode));
    const std::size_t per = lanes * blocksPerItem;
    enqueue(positions.get(), (vertexCount + positionsPerItem - 1) / positionsPerItem, positionsLocal,
            "surface_positions");
    enqueue(normals.get(), (vertexCount + per - 1) / per, normalsLocal, "surface_normals");
    // A few vertices per body (a UV sphere's poles), many with a batch's bodies: work-groups of
    // several (the kernel skips the padding), not of one each.
    enqueue(overflow.get(), overflowCount, positionsLocal, "surface_normals_overflow");
  }
};

DeviceSurface::DeviceSurface(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
DeviceSurface::DeviceSurface(DeviceSurface&&) noexcept = default;
DeviceSurface& DeviceSurface::operator=(DeviceSurface&&) noexcept = default;
DeviceSurface::~DeviceSurface() = default;

Result<DeviceSurface> DeviceSurface::create(const SurfaceBinding& binding, const DeviceSurfaceOptions& options) {
  return detail::guardResult<DeviceSurface>([&] { return make(binding, options, 0, nullptr); });
}

DeviceSurface DeviceSurface::make(const SurfaceBinding& binding, const DeviceSurfaceOptions& options,
                                  std::size_t bodies, const std::vector<std::uint32_t>* blockBody) {
  const std::size_t n = binding.vertexCount();
  if (binding.nodes.size() != 4 * n || binding.weights.size() != 4 * n ||
      binding.vertexTriangleOffsets.size() != n + 1 || binding.triangles.size() % 3 != 0 ||
      binding.vertexTriangles.size() != binding.triangles.size())
    fail(ErrorCode::BadInput, "DeviceSurface::create: the SurfaceBinding is inconsistent (array sizes do not "
         "match its ", n, " vertices); make it with bindSurface");
  auto impl = std::make_unique<Impl>();
  impl->ctx = options.external ? detail::cl::Context::adopt(options.external, "DeviceSurfaceOptions::external")
                               : detail::cl::Context::shared(options.device);
  impl->doublePrecision = options.doublePrecision;
  if (impl->doublePrecision && !impl->ctx->info().fp64)
    fail(ErrorCode::BadInput, "DeviceSurfaceOptions::doublePrecision: device '", impl->device(),
         "' has no cl_khr_fp64; use float (doublePrecision = false) or another device");
  const std::size_t lanes = detail::surfaceLanes(impl->ctx->info().gpu, impl->doublePrecision, options.normalPassLanes);
  Impl& k = *impl;
  try {
    k.realSize = k.doublePrecision ? sizeof(double) : sizeof(float);
    const bool cpu = !k.ctx->info().gpu;
    k.lanes = lanes;
    k.positionsPerItem = cpu ? 16 : 1;
    k.blocksPerItem = cpu ? 4 : 1;
    k.positionsLocal = cpu ? 16 : 64;
    k.normalsLocal = cpu ? 16 : 64;
    // The kernels index with 32-bit integers: slot i of vertex v at i * S + v, 6 v floats per vertex.
    const std::size_t stride = paddedVertexCount(n);
    if (6 * stride + 64 > std::numeric_limits<cl_uint>::max())
      fail(ErrorCode::DeviceError, "the surface has ", n, " vertices, more than the device kernels' 32-bit "
           "indices allow (", std::numeric_limits<cl_uint>::max() / 6 - 64, ")");
    k.vertexCount = static_cast<cl_uint>(n);
    k.stride = static_cast<cl_uint>(stride);
    k.nodeCount = binding.tetNodeCount;
    const RingLayout layout = ringLayout(binding, stride);
    if (layout.slots * stride > std::numeric_limits<cl_uint>::max() ||
        layout.overflowSequence.size() > std::numeric_limits<cl_uint>::max())
      fail(ErrorCode::DeviceError, "the surface's one-rings (", layout.slots, " slots for ", n,
           " vertices) exceed the device kernels' 32-bit indices");
    k.overflowCount = static_cast<cl_uint>(layout.overflowVertices.size());

    // Weights in the device precision; node indices as uint4; the ring as uint.
    std::vector<unsigned char> w(k.realSize * 4 * n);
    for (std::size_t i = 0; i < 4 * n; ++i) {
      if (k.doublePrecision) std::memcpy(&w[8 * i], &binding.weights[i], 8);
      else {
        const float f = static_cast<float>(binding.weights[i]);
        std::memcpy(&w[4 * i], &f, 4);
      }
    }
    const cl_mem_flags ro = CL_MEM_READ_ONLY, rw = CL_MEM_READ_WRITE;
    k.nodes = k.buffer(ro, 4 * n * sizeof(cl_uint), binding.nodes.data(), "vertex node indices");
    k.weights = k.buffer(ro, w.size(), w.data(), "weights");
    k.ring = k.buffer(ro, layout.ring.size() * sizeof(cl_uint), layout.ring.data(), "one-ring");
    const std::vector<cl_uint> runs = blockRuns(layout, stride, k.lanes);
    k.ringRuns = k.buffer(ro, runs.size() * sizeof(cl_uint), runs.data(), "one-ring runs");
    k.overflowVertices = k.buffer(ro, layout.overflowVertices.size() * sizeof(cl_uint),
                                  layout.overflowVertices.data(), "long one-ring vertices");
    k.overflowOffsets = k.buffer(ro, layout.overflowOffsets.size() * sizeof(cl_uint), layout.overflowOffsets.data(),
                                 "long one-ring offsets");
    k.overflowSequence = k.buffer(ro, layout.overflowSequence.size() * sizeof(cl_uint),
                                  layout.overflowSequence.data(), "long one-rings");
    // k.x, the upload buffer of update()'s host positions, is made by the first update(): a
    // Simulation feeds the backend's own buffer (updateFromDevice) and never needs it.
    // The scratch's padding (vertices n..S-1) is read by the last vector block: zero, once.
    const std::vector<unsigned char> zeros(3 * stride * k.realSize, 0);
    k.pos = k.buffer(rw, zeros.size(), zeros.data(), "vertex positions");
    k.separate = options.separateStreams;
    k.out = k.buffer(rw, (k.separate ? 3 : 6) * n * sizeof(float), nullptr,
                     k.separate ? "output positions" : "output vertex");
    k.normalsOut = k.buffer(rw, k.separate ? 3 * n * sizeof(float) : 0, nullptr, "output normals");
    if (bodies > 0) {  // many bodies: each block's body, and every body's offset (written per frame)
      if (!blockBody || blockBody->size() != stride / k.lanes)
        fail(ErrorCode::Internal, "DeviceSurface: ", blockBody ? blockBody->size() : 0, " block bodies for ",
             stride / k.lanes, " blocks");
      k.bodies = bodies;
      k.blockBody = k.buffer(ro, blockBody->size() * sizeof(cl_uint), blockBody->data(), "block bodies");
      k.bodyOffsets = k.buffer(ro, 6 * bodies * k.realSize, nullptr, "body offsets");
    }

    std::string buildOptions = "-cl-std=CL1.2 -DCOROFEM_SURFACE -DSURF_K=" + std::to_string(layout.slots) +
                               " -DSURF_W=" + std::to_string(k.lanes) +
                               " -DSURF_VPW=" + std::to_string(k.positionsPerItem) +
                               " -DSURF_BPW=" + std::to_string(k.blocksPerItem);
    if (k.doublePrecision) buildOptions += " -DCOROFEM_DOUBLE";
    if (k.separate) buildOptions += " -DSURF_SEPARATE";
    if (k.bodies > 0) buildOptions += " -DSURF_MULTI";
    const detail::cl::ProgramBuild build =
        detail::cl::buildProgram(*k.ctx, "surface_update", surfaceProgramSource(), buildOptions);
    k.positions = k.kernel(build.program, "surface_positions");
    k.normals = k.kernel(build.program, "surface_normals");
    k.overflow = k.kernel(build.program, "surface_normals_overflow");

    k.arg(k.positions.get(), 0, k.vertexCount);
    k.arg(k.positions.get(), 1, k.stride);
    k.arg(k.positions.get(), 2, k.nodes.get());
    k.arg(k.positions.get(), 3, k.weights.get());
    k.arg(k.positions.get(), 5, k.pos.get());
    k.arg(k.normals.get(), 0, k.vertexCount);
    k.arg(k.normals.get(), 1, k.stride);
    k.arg(k.normals.get(), 2, k.ring.get());
    k.arg(k.normals.get(), 3, k.pos.get());
    k.arg(k.normals.get(), 4, k.out.get());
    k.arg(k.normals.get(), 11, k.ringRuns.get());
    k.arg(k.normals.get(), 12, k.normalsOut.get());
    k.arg(k.normals.get(), 13, k.blockBody.get());  // NULL unless SURF_MULTI (not read then)
    k.arg(k.normals.get(), 14, k.bodyOffsets.get());
    k.arg(k.overflow.get(), 0, k.overflowCount);
    k.arg(k.overflow.get(), 1, k.overflowVertices.get());
    k.arg(k.overflow.get(), 2, k.overflowOffsets.get());
    k.arg(k.overflow.get(), 3, k.overflowSequence.get());
    k.arg(k.overflow.get(), 4, k.stride);
    k.arg(k.overflow.get(), 5, k.pos.get());
    k.arg(k.overflow.get(), 6, k.out.get());
    k.arg(k.overflow.get(), 7, k.normalsOut.get());
    k.setOffset(nullptr);
  } catch (const detail::Error& e) {
    // Anything that fails from here on is the device's (memory, build, limits): one code, so that
    // a caller can fall back to deformSurface on the host.
    if (e.code() == ErrorCode::DeviceError) throw;
    fail(ErrorCode::DeviceError, "DeviceSurface::create on device '", k.device(), "': ", e.what(),
         "; update the surface on the host with deformSurface instead");
  } catch (const std::bad_alloc&) {
    fail(ErrorCode::DeviceError, "DeviceSurface::create on device '", k.device(), "': out of host memory while "
         "preparing the surface's ", n, " vertices; update the surface on the host with deformSurface instead");
  }
  return DeviceSurface(std::move(impl));
}

Status DeviceSurface::update(const double* tetNodePositions, std::size_t tetNodeCount) {
  return detail::guard([&] {
    Impl& k = *impl_;
    if (tetNodeCount != k.nodeCount)
      fail(ErrorCode::BadInput, "DeviceSurface::update: ", tetNodeCount, " node positions given but the surface "
           "was bound to a tet mesh of ", k.nodeCount, " nodes; pass that mesh's current positions");
    if (!tetNodePositions) fail(ErrorCode::BadInput, "DeviceSurface::update: tetNodePositions is null");
    const void* src = tetNodePositions;
    const std::size_t bytes = 3 * k.nodeCount * k.realSize;
    if (!k.doublePrecision) {
      // The previous frame's write may still read the staging memory: blocking write below, so the
      // conversion can reuse it.
      k.staging.resize(bytes);
      float* f = reinterpret_cast<float*>(k.staging.data());
      for (std::size_t i = 0; i < 3 * k.nodeCount; ++i) f[i] = static_cast<float>(tetNodePositions[i]);
      src = k.staging.data();
    }
    if (!k.x) k.x = k.buffer(CL_MEM_READ_ONLY, bytes, nullptr, "node positions");
    if (bytes)
      checkCl(clEnqueueWriteBuffer(k.ctx->queue(), k.x.get(), CL_TRUE, 0, bytes, src, 0, nullptr, nullptr),
              "clEnqueueWriteBuffer (node positions)", k.device());
    k.run(k.x.get());
  });
}

Status DeviceSurface::updateFromDevice(const GpuBuffer& positions, const double* offset, std::size_t firstNode) {
  return detail::guard([&] {
    const Impl& k = *impl_;
    cl_mem buffer = detail::cl::memOf(positions, "DeviceSurface::updateFromDevice");
    if (positions.offset % (3 * k.realSize) != 0)
      fail(ErrorCode::BadInput, "DeviceSurface::updateFromDevice: the positions start at byte ", positions.offset,
           ", not a whole number of nodes of 3 ", k.doublePrecision ? "doubles" : "floats", "; give the node with ",
           "firstNode instead");
    firstNode += positions.offset / (3 * k.realSize);
    // The kernels would read past the buffer: refuse (OpenCL does not check). In whole nodes, so
    // that nothing overflows; the kernel takes the first node as a 32-bit index.
    std::size_t bytes = 0;
    checkCl(clGetMemObjectInfo(buffer, CL_MEM_SIZE, sizeof(bytes), &bytes, nullptr), "clGetMemObjectInfo (node positions)",
            k.device());
    const std::size_t held = bytes / (3 * k.realSize);  // whole nodes in the buffer
    if (firstNode > std::numeric_limits<cl_uint>::max() || firstNode > held || k.nodeCount > held - firstNode)
      fail(ErrorCode::BadInput, "DeviceSurface::updateFromDevice: the node positions buffer holds ", bytes,
           " bytes (", held, " nodes of 3 ", k.doublePrecision ? "doubles" : "floats", "), but the surface reads ",
           k.nodeCount, " nodes from node ", firstNode, " on; pass the buffer of the tet mesh the surface was "
           "bound to in the surface's precision, and that mesh's first node in it");
    impl_->run(buffer, offset, firstNode);
  });
}

Status DeviceSurface::read(float* interleaved) const {
  return detail::guard([&] {
    if (!interleaved) fail(ErrorCode::BadInput, "DeviceSurface::read: the output pointer is null");
    const Impl& k = *impl_;
    if (k.vertexCount == 0) return;
    const std::size_t n = k.vertexCount;
    if (!k.separate) {
      k.readBuffer(k.out.get(), 6 * n, interleaved, "surface vertices");
      return;
    }
    std::vector<float> positions(3 * n), normals(3 * n);
    k.readBuffer(k.out.get(), 3 * n, positions.data(), "surface positions");
    k.readBuffer(k.normalsOut.get(), 3 * n, normals.data(), "surface normals");
    Impl::copyTriples(positions.data(), 3, interleaved, 6, n);
    Impl::copyTriples(normals.data(), 3, interleaved + 3, 6, n);
  });
}

Status DeviceSurface::read(float* positions, float* normals) const {
  return detail::guard([&] {
    if (!positions || !normals)
      fail(ErrorCode::BadInput, "DeviceSurface::read: the ", !positions ? "positions" : "normals",
           " pointer is null; give two arrays of 3 floats per vertex");
    if (impl_->vertexCount > 0) impl_->readStreams(0, impl_->vertexCount, positions, normals);
  });
}

Status DeviceSurface::finish() const {
  return detail::guard([&] { checkCl(clFinish(impl_->ctx->queue()), "clFinish", impl_->device()); });
}


// ------------------------------------------------------------------ many bodies
namespace detail {

struct DeviceSurfaceGroup::State {
  std::unique_ptr<DeviceSurface> merged;
  std::vector<std::size_t> base, count;  ///< per body: first vertex in the merged surface, vertex count
  std::vector<Mem> vertexSubs, normalSubs;
  std::vector<unsigned char> offsets;    ///< 6 reals per body (chi xyz, clo xyz), the last write's source
  cl_event written = nullptr;            ///< that write (its host bytes must live until it completes)
  void waitWritten() {
    if (!written) return;
    const cl_int status = clWaitForEvents(1, &written);
    clReleaseEvent(written);
    written = nullptr;
    checkCl(status, "clWaitForEvents (surface body offsets)", "the surfaces' device");
  }
  ~State() {
    if (written) {
      clWaitForEvents(1, &written);
      clReleaseEvent(written);
    }
  }
};

DeviceSurfaceGroup::DeviceSurfaceGroup(const std::vector<Member>& members, std::size_t positionNodes,
                                       const DeviceSurfaceOptions& options)
    : s_(std::make_unique<State>()) {
  if (members.empty()) fail(ErrorCode::Internal, "DeviceSurfaceGroup: no bodies");
  auto ctx = cl::Context::adopt(options.external, "DeviceSurfaceGroup (the position buffer's context)");
  const bool gpu = ctx->info().gpu;
  const std::size_t lanes = surfaceLanes(gpu, options.doublePrecision, options.normalPassLanes), blocksPerItem = gpu ? 1 : 4;
  // Each body starts at a work-item's first block (its blocks are its own) and at an address a
  // sub-buffer may start at (CL_DEVICE_MEM_BASE_ADDR_ALIGN, in bits).
  cl_uint alignBits = 0;
  checkCl(clGetDeviceInfo(ctx->device(), CL_DEVICE_MEM_BASE_ADDR_ALIGN, sizeof(alignBits), &alignBits, nullptr),
          "clGetDeviceInfo(CL_DEVICE_MEM_BASE_ADDR_ALIGN)", ctx->deviceName());
  const std::size_t alignBytes = std::max<std::size_t>(alignBits / 8, 1);
  const std::size_t streamBytes = (options.separateStreams ? 3 : 6) * sizeof(float);
  const std::size_t byAddress = alignBytes / std::gcd(alignBytes, streamBytes);
  const std::size_t step = std::lcm(lanes * blocksPerItem, byAddress);

  SurfaceBinding all;
  all.tetNodeCount = positionNodes;
  all.vertexTriangleOffsets.push_back(0);
  std::vector<std::uint32_t> vertexBody;  // per merged vertex: its body (the gaps: the next body)
  auto addVertex = [&](std::uint32_t element, const std::uint32_t* nodes, const double* weights, std::size_t m) {
    all.element.push_back(element);
    all.nodes.insert(all.nodes.end(), nodes, nodes + 4);
    all.weights.insert(all.weights.end(), weights, weights + 4);
    vertexBody.push_back(static_cast<std::uint32_t>(m));
  };
  for (std::size_t m = 0; m < members.size(); ++m) {
    const SurfaceBinding& b = *members[m].binding;
    if (b.tetNodeCount + members[m].firstNode > positionNodes)
      fail(ErrorCode::Internal, "DeviceSurfaceGroup: body ", m, "'s nodes ", members[m].firstNode, " + ",
           b.tetNodeCount, " exceed the buffer's ", positionNodes);
    const std::uint32_t zeroNodes[4] = {0, 0, 0, 0};
    const double zeroWeights[4] = {0, 0, 0, 0};
    while (all.vertexCount() % step != 0) {  // a gap vertex: position 0, no triangle (normal 0)
      addVertex(0, zeroNodes, zeroWeights, m);
      all.vertexTriangleOffsets.push_back(all.vertexTriangleOffsets.back());
    }
    const auto vbase = static_cast<std::uint32_t>(all.vertexCount());
    const auto tbase = static_cast<std::uint32_t>(all.triangles.size() / 3);
    s_->base.push_back(vbase);
    s_->count.push_back(b.vertexCount());
    for (std::size_t v = 0; v < b.vertexCount(); ++v) {
      std::uint32_t nodes[4];
      for (int k = 0; k < 4; ++k) nodes[k] = b.nodes[4 * v + k] + static_cast<std::uint32_t>(members[m].firstNode);
      addVertex(b.element[v], nodes, &b.weights[4 * v], m);
      all.vertexTriangleOffsets.push_back(all.vertexTriangleOffsets.back() +
                                          (b.vertexTriangleOffsets[v + 1] - b.vertexTriangleOffsets[v]));
    }
    for (std::uint32_t t : b.triangles) all.triangles.push_back(t + vbase);
    for (std::uint32_t t : b.vertexTriangles) all.vertexTriangles.push_back(t + tbase);
  }
  // The body of each block of the normal pass (the blocks past the last vertex: the last body).
  const std::size_t stride = paddedVertexCount(all.vertexCount());
  std::vector<std::uint32_t> blockBody(stride / lanes, static_cast<std::uint32_t>(members.size() - 1));
  for (std::size_t blk = 0; blk * lanes < all.vertexCount(); ++blk) blockBody[blk] = vertexBody[blk * lanes];
  s_->merged = std::make_unique<DeviceSurface>(DeviceSurface::make(all, options, members.size(), &blockBody));
  DeviceSurface::Impl& k = *s_->merged->impl_;
  if (k.lanes != lanes || k.blocksPerItem != blocksPerItem)
    fail(ErrorCode::Internal, "DeviceSurfaceGroup: the surface chose ", k.lanes, " lanes, not ", lanes);
  s_->offsets.assign(6 * members.size() * k.realSize, 0);
  // Every body's output as a sub-buffer of the shared one(s).
  auto sub = [&](cl_mem parent, std::size_t m, std::size_t floatsPerVertex, const char* what) {
    cl_buffer_region region{s_->base[m] * floatsPerVertex * sizeof(float), s_->count[m] * floatsPerVertex * sizeof(float)};
    cl_int status = CL_SUCCESS;
    cl_mem mem = clCreateSubBuffer(parent, CL_MEM_READ_WRITE, CL_BUFFER_CREATE_TYPE_REGION, &region, &status);
    checkCl(status, (std::string("clCreateSubBuffer (") + what + ")").c_str(), k.device());
    return Mem(mem);
  };
  for (std::size_t m = 0; m < members.size(); ++m) {
    s_->vertexSubs.push_back(sub(k.out.get(), m, k.separate ? 3 : 6, "a body's surface output"));
    if (k.separate) s_->normalSubs.push_back(sub(k.normalsOut.get(), m, 3, "a body's surface normals"));
  }
}

DeviceSurfaceGroup::~DeviceSurfaceGroup() = default;
std::size_t DeviceSurfaceGroup::size() const { return s_->base.size(); }
bool DeviceSurfaceGroup::separateStreams() const { return s_->merged->separateStreams(); }
GpuBuffer DeviceSurfaceGroup::vertexBuffer(std::size_t m) const {
  return cl::bufferOf(s_->vertexSubs.at(m).get(), 0, (separateStreams() ? 3 : 6) * sizeof(float), s_->count.at(m));
}
GpuBuffer DeviceSurfaceGroup::normalBuffer(std::size_t m) const {
  return separateStreams() ? cl::bufferOf(s_->normalSubs.at(m).get(), 0, 3 * sizeof(float), s_->count.at(m))
                           : GpuBuffer{};
}
std::vector<DeviceSurfaceBuffer> DeviceSurfaceGroup::buffers() const { return s_->merged->buffers(); }
std::size_t DeviceSurfaceGroup::allocatedBytes() const { return s_->merged->allocatedBytes(); }
void DeviceSurfaceGroup::finish() const {
  const Status st = s_->merged->finish();
  if (!st) fail(st.code(), st.message());
}

void DeviceSurfaceGroup::update(_cl_mem* positions, const std::vector<const double*>& centroids) {
  DeviceSurface::Impl& k = *s_->merged->impl_;
  if (centroids.size() != size())
    fail(ErrorCode::Internal, "DeviceSurfaceGroup::update: ", centroids.size(), " centroids for ", size(), " bodies");
  s_->waitWritten();
  // Per body chi xyz then clo xyz, split as DeviceSurface::Impl::setOffset splits its offset.
  auto put = [&](std::size_t m, std::size_t a, const auto& parts) {
    std::memcpy(&s_->offsets[(6 * m + a) * k.realSize], &parts.first, k.realSize);
    std::memcpy(&s_->offsets[(6 * m + 3 + a) * k.realSize], &parts.second, k.realSize);
  };
  for (std::size_t m = 0; m < size(); ++m)
    for (std::size_t a = 0; a < 3; ++a) {
      const double c = centroids[m] ? centroids[m][a] : 0.0;
      if (k.doublePrecision) put(m, a, DeviceSurface::Impl::splitOffset<double>(c));
      else put(m, a, DeviceSurface::Impl::splitOffset<float>(c));
    }
  // Not blocking (on an in-order queue that would wait for all the work queued before it): the
  // next update waits for this write before it rewrites the host bytes.
  checkCl(clEnqueueWriteBuffer(k.ctx->queue(), k.bodyOffsets.get(), CL_FALSE, 0, s_->offsets.size(), s_->offsets.data(),
                               0, nullptr, &s_->written),
          "clEnqueueWriteBuffer (surface body offsets)", k.device());
  const Status st = s_->merged->updateFromDevice(cl::bufferOf(positions), nullptr, 0);
  if (!st) fail(st.code(), st.message());
}

void DeviceSurfaceGroup::read(std::size_t m, float* positions, float* normals) const {
  s_->merged->impl_->readStreams(s_->base.at(m), s_->count.at(m), positions, normals);
}

}  // namespace detail

std::vector<DeviceSurfaceBuffer> DeviceSurface::buffers() const { return impl_->allocated; }
std::size_t DeviceSurface::allocatedBytes() const {
  std::size_t total = 0;
  for (const DeviceSurfaceBuffer& b : impl_->allocated) total += b.bytes;
  return total;
}
GpuBuffer DeviceSurface::vertexBuffer() const {
  return detail::cl::bufferOf(impl_->out.get(), 0, (impl_->separate ? 3 : 6) * sizeof(float), impl_->vertexCount);
}
GpuBuffer DeviceSurface::normalBuffer() const {
  return impl_->separate ? detail::cl::bufferOf(impl_->normalsOut.get(), 0, 3 * sizeof(float), impl_->vertexCount)
                         : GpuBuffer{};
}
bool DeviceSurface::separateStreams() const { return impl_->separate; }
std::size_t DeviceSurface::vertexCount() const { return impl_->vertexCount; }
std::string DeviceSurface::deviceName() const { return impl_->device(); }

}  // namespace corofem

#endif  // COROFEM_WITH_OPENCL
