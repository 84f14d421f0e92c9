// DeviceSurface: the per-frame coupled-mesh update on an OpenCL device (kernels/opencl/surface_update.cl),
// the same passes as deformSurface (deform_surface.cpp). Without COROFEM_WITH_OPENCL every entry point
// reports ErrorCode::NotCompiledIn.
#include <corofem/embed.hpp>

#include "util/error.hpp"

#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/cl_check.hpp"
#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/program_cache.hpp"

#include <algorithm>
#include <cstring>
#endif

#include <utility>

namespace corofem {

#ifdef COROFEM_WITH_OPENCL

struct EmbeddedSource {
  const char* name;
  const char* text;
};
extern const EmbeddedSource corofem_opencl_sources[];
extern const std::size_t corofem_opencl_sources_count;

namespace {

using detail::fail;
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

}  // namespace

struct DeviceSurface::Impl {
  std::shared_ptr<detail::cl::Context> ctx;
  bool doublePrecision = false;
  std::size_t realSize = 4;
  cl_uint vertexCount = 0, triangleCount = 0;
  std::size_t nodeCount = 0;
  Mem nodes, weights, triangles, offsets, incident, x, pos, faces, out;
  Kernel positions, faceVectors, normals;
  std::vector<unsigned char> staging;  // node positions converted to the device precision

  const std::string& device() const { return ctx->deviceName(); }

  Mem buffer(cl_mem_flags flags, std::size_t bytes, const void* host, const char* what) {
    cl_int status = CL_SUCCESS;
    // Zero-sized buffers are invalid in OpenCL: allocate one element for empty streams.
    cl_mem m = clCreateBuffer(ctx->context(), flags | (host && bytes ? CL_MEM_COPY_HOST_PTR : 0),
                              bytes ? bytes : 16, bytes ? const_cast<void*>(host) : nullptr, &status);
    if (status != CL_SUCCESS)
      fail(ErrorCode::DeviceError, "DeviceSurface: allocating the ", what, " buffer (", bytes, " bytes) failed with ",
           detail::cl::errorString(status), " on device '", device(), "'");
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

  /// One work-item per entry, in work-groups of 64 (the kernels skip the padding work-items):
  /// leaving the size to the runtime lets some (PoCL) pick tiny groups.
  void enqueue(cl_kernel k, std::size_t count, const char* name) {
    if (count == 0) return;
    const std::size_t local = std::clamp<std::size_t>(ctx->info().maxWorkGroupSize, 1, 64);
    const std::size_t global = (count + local - 1) / local * local;
    checkCl(clEnqueueNDRangeKernel(ctx->queue(), k, 1, nullptr, &global, &local, 0, nullptr, nullptr), name,
            device());
  }

  /// Sets the offset c added to the written positions: c = hi + lo in the device precision (in float
  /// lo carries what float(c) drops, so the output rounds once; surface_update.cl).
  void setOffset(const double* c) {
    for (cl_uint a = 0; a < 3; ++a) {
      const double value = c ? c[a] : 0.0;
      if (doublePrecision) {
        arg(normals.get(), 6 + a, value);
        arg(normals.get(), 9 + a, 0.0);
      } else {
        const float hi = static_cast<float>(value);
        arg(normals.get(), 6 + a, hi);
        arg(normals.get(), 9 + a, static_cast<float>(value - static_cast<double>(hi)));
      }
    }
  }

  /// Enqueues the three passes reading node positions from `xBuffer` (relative to `offset`, 3
  /// doubles or nullptr for absolute positions).
  void run(cl_mem xBuffer, const double* offset = nullptr) {
    setOffset(offset);
    arg(positions.get(), 3, xBuffer);
    enqueue(positions.get(), vertexCount, "surface_positions");
    enqueue(faceVectors.get(), triangleCount, "surface_face_vectors");
    enqueue(normals.get(), vertexCount, "surface_normals");
  }
};

DeviceSurface::DeviceSurface(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
DeviceSurface::DeviceSurface(DeviceSurface&&) noexcept = default;
DeviceSurface& DeviceSurface::operator=(DeviceSurface&&) noexcept = default;
DeviceSurface::~DeviceSurface() = default;

Result<DeviceSurface> DeviceSurface::create(const SurfaceBinding& binding, const DeviceSurfaceOptions& options) {
  return detail::guardResult<DeviceSurface>([&] {
    const std::size_t n = binding.vertexCount();
    if (binding.nodes.size() != 4 * n || binding.weights.size() != 4 * n ||
        binding.vertexTriangleOffsets.size() != n + 1 || binding.triangles.size() % 3 != 0 ||
        binding.vertexTriangles.size() != binding.triangles.size())
      fail(ErrorCode::BadInput, "DeviceSurface::create: the SurfaceBinding is inconsistent (array sizes do not "
           "match its ", n, " vertices); make it with bindSurface");
    const bool some = options.context || options.queue || options.deviceId;
    const bool all = options.context && options.queue && options.deviceId;
    if (some && !all)
      fail(ErrorCode::BadInput, "DeviceSurfaceOptions: give context, queue and deviceId together, or none of them");

    auto impl = std::make_unique<Impl>();
    impl->ctx = all ? detail::cl::Context::adopt(options.context, options.queue, options.deviceId)
                    : detail::cl::Context::shared(options.device);
    impl->doublePrecision = options.doublePrecision;
    if (impl->doublePrecision && !impl->ctx->info().fp64)
      fail(ErrorCode::BadInput, "DeviceSurfaceOptions::doublePrecision: device '", impl->device(),
           "' has no cl_khr_fp64; use float (doublePrecision = false) or another device");
    impl->realSize = impl->doublePrecision ? sizeof(double) : sizeof(float);
    impl->vertexCount = static_cast<cl_uint>(n);
    impl->triangleCount = static_cast<cl_uint>(binding.triangles.size() / 3);
    impl->nodeCount = binding.tetNodeCount;

    // Weights in the device precision; node indices as uint4, triangles and CSR as uint.
    std::vector<unsigned char> w(impl->realSize * 4 * n);
    for (std::size_t i = 0; i < 4 * n; ++i) {
      if (impl->doublePrecision) std::memcpy(&w[8 * i], &binding.weights[i], 8);
      else {
        const float f = static_cast<float>(binding.weights[i]);
        std::memcpy(&w[4 * i], &f, 4);
      }
    }
    const cl_mem_flags ro = CL_MEM_READ_ONLY, rw = CL_MEM_READ_WRITE;
    impl->nodes = impl->buffer(ro, 4 * n * sizeof(cl_uint), binding.nodes.data(), "vertex node indices");
    impl->weights = impl->buffer(ro, w.size(), w.data(), "weights");
    impl->triangles = impl->buffer(ro, binding.triangles.size() * sizeof(cl_uint), binding.triangles.data(), "triangles");
    impl->offsets = impl->buffer(ro, (n + 1) * sizeof(cl_uint), binding.vertexTriangleOffsets.data(), "adjacency offsets");
    impl->incident = impl->buffer(ro, binding.vertexTriangles.size() * sizeof(cl_uint), binding.vertexTriangles.data(),
                                  "adjacency");
    impl->x = impl->buffer(ro, 3 * impl->nodeCount * impl->realSize, nullptr, "node positions");
    impl->pos = impl->buffer(rw, 3 * n * impl->realSize, nullptr, "vertex positions");
    impl->faces = impl->buffer(rw, binding.triangles.size() * impl->realSize, nullptr, "face vectors");
    impl->out = impl->buffer(rw, 6 * n * sizeof(float), nullptr, "output vertex");

    std::string buildOptions = "-cl-std=CL1.2 -DCOROFEM_SURFACE";
    if (impl->doublePrecision) buildOptions += " -DCOROFEM_DOUBLE";
    const detail::cl::ProgramBuild build =
        detail::cl::buildProgram(*impl->ctx, "surface_update", surfaceProgramSource(), buildOptions);
    impl->positions = impl->kernel(build.program, "surface_positions");
    impl->faceVectors = impl->kernel(build.program, "surface_face_vectors");
    impl->normals = impl->kernel(build.program, "surface_normals");

    Impl& k = *impl;
    k.arg(k.positions.get(), 0, k.vertexCount);
    k.arg(k.positions.get(), 1, k.nodes.get());
    k.arg(k.positions.get(), 2, k.weights.get());
    k.arg(k.positions.get(), 3, k.x.get());
    k.arg(k.positions.get(), 4, k.pos.get());
    k.arg(k.faceVectors.get(), 0, k.triangleCount);
    k.arg(k.faceVectors.get(), 1, k.triangles.get());
    k.arg(k.faceVectors.get(), 2, k.pos.get());
    k.arg(k.faceVectors.get(), 3, k.faces.get());
    k.arg(k.normals.get(), 0, k.vertexCount);
    k.arg(k.normals.get(), 1, k.offsets.get());
    k.arg(k.normals.get(), 2, k.incident.get());
    k.arg(k.normals.get(), 3, k.faces.get());
    k.arg(k.normals.get(), 4, k.pos.get());
    k.arg(k.normals.get(), 5, k.out.get());
    k.setOffset(nullptr);
    return DeviceSurface(std::move(impl));
  });
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
    if (bytes)
      checkCl(clEnqueueWriteBuffer(k.ctx->queue(), k.x.get(), CL_TRUE, 0, bytes, src, 0, nullptr, nullptr),
              "clEnqueueWriteBuffer (node positions)", k.device());
    k.run(k.x.get());
  });
}

Status DeviceSurface::updateFromDevice(_cl_mem* tetNodePositions) {
  return detail::guard([&] {
    if (!tetNodePositions) fail(ErrorCode::BadInput, "DeviceSurface::updateFromDevice: the buffer is null");
    impl_->run(tetNodePositions);
  });
}

Status DeviceSurface::updateFromDevice(_cl_mem* relativeTetNodePositions, const double* offset) {
  return detail::guard([&] {
    if (!relativeTetNodePositions) fail(ErrorCode::BadInput, "DeviceSurface::updateFromDevice: the buffer is null");
    impl_->run(relativeTetNodePositions, offset);
  });
}

Status DeviceSurface::read(float* interleaved) const {
  return detail::guard([&] {
    if (!interleaved) fail(ErrorCode::BadInput, "DeviceSurface::read: the output pointer is null");
    const Impl& k = *impl_;
    if (k.vertexCount == 0) return;
    checkCl(clEnqueueReadBuffer(k.ctx->queue(), k.out.get(), CL_TRUE, 0, 6 * sizeof(float) * k.vertexCount,
                                interleaved, 0, nullptr, nullptr),
            "clEnqueueReadBuffer (surface vertices)", k.device());
  });
}

Status DeviceSurface::finish() const {
  return detail::guard([&] { checkCl(clFinish(impl_->ctx->queue()), "clFinish", impl_->device()); });
}

_cl_mem* DeviceSurface::vertexBuffer() const { return impl_->out.get(); }
std::size_t DeviceSurface::vertexCount() const { return impl_->vertexCount; }
std::string DeviceSurface::deviceName() const { return impl_->device(); }

#else  // no OpenCL in this build

struct DeviceSurface::Impl {};

namespace {
Status notCompiledIn() {
  return Status(ErrorCode::NotCompiledIn,
                "DeviceSurface: this corofem was built without OpenCL; reconfigure with -DCOROFEM_WITH_OPENCL=ON "
                "(and an OpenCL ICD such as pocl-opencl-icd) or use deformSurface on the host");
}
}  // namespace

DeviceSurface::DeviceSurface(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
DeviceSurface::DeviceSurface(DeviceSurface&&) noexcept = default;
DeviceSurface& DeviceSurface::operator=(DeviceSurface&&) noexcept = default;
DeviceSurface::~DeviceSurface() = default;

Result<DeviceSurface> DeviceSurface::create(const SurfaceBinding&, const DeviceSurfaceOptions&) {
  return notCompiledIn();
}
Status DeviceSurface::update(const double*, std::size_t) { return notCompiledIn(); }
Status DeviceSurface::updateFromDevice(_cl_mem*) { return notCompiledIn(); }
Status DeviceSurface::updateFromDevice(_cl_mem*, const double*) { return notCompiledIn(); }
Status DeviceSurface::read(float*) const { return notCompiledIn(); }
Status DeviceSurface::finish() const { return notCompiledIn(); }
_cl_mem* DeviceSurface::vertexBuffer() const { return nullptr; }
std::size_t DeviceSurface::vertexCount() const { return 0; }
std::string DeviceSurface::deviceName() const { return {}; }

#endif

}  // namespace corofem
