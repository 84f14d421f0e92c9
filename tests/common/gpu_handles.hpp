// OpenCL objects as corofem's GpuBuffer and ExternalDevice carry them (corofem/gpu.hpp), for the
// tests that look inside the buffers. OpenCL builds only.
#pragma once

#include "backends/opencl/cl_context.hpp"

#include <corofem/gpu.hpp>

#include <cstdint>

namespace corofem::test {

/// The cl_mem of an OpenCL GpuBuffer; nullptr for an empty one or another API's.
inline cl_mem clMem(const GpuBuffer& b) {
  return b.api == GpuApi::OpenCL ? reinterpret_cast<cl_mem>(static_cast<std::uintptr_t>(b.handle)) : nullptr;
}

/// A whole OpenCL buffer as a GpuBuffer (offset 0).
inline GpuBuffer gpuBuffer(cl_mem m, std::size_t offset = 0) {
  GpuBuffer b = detail::cl::bufferOf(m);
  b.offset = offset;
  return b;
}

/// A context's objects as an application lends them.
inline ExternalDevice externalOf(const detail::cl::Context& c) {
  return {GpuApi::OpenCL, c.context(), c.queue(), c.device()};
}

}  // namespace corofem::test
