// DeviceSurface in a build without OpenCL: every entry point reports
// ErrorCode::NotCompiledIn (backends/opencl/device_surface.cpp is the implementation).
#ifndef COROFEM_WITH_OPENCL

#include "backends/opencl/device_surface.hpp"
#include "util/error.hpp"

#include <corofem/embed.hpp>

namespace corofem {

namespace detail {
DeviceSurfaceLayout deviceSurfaceLayout(const SurfaceBinding&, std::size_t) { return {}; }
}  // namespace detail

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
Status DeviceSurface::updateFromDevice(const GpuBuffer&, const double*, std::size_t) { return notCompiledIn(); }
Status DeviceSurface::read(float*) const { return notCompiledIn(); }
Status DeviceSurface::read(float*, float*) const { return notCompiledIn(); }
Status DeviceSurface::finish() const { return notCompiledIn(); }
DeviceSurface DeviceSurface::make(const SurfaceBinding&, const DeviceSurfaceOptions&, std::size_t,
                                  const std::vector<std::uint32_t>*) {
  detail::fail(ErrorCode::NotCompiledIn, notCompiledIn().message());
}
std::vector<DeviceSurfaceBuffer> DeviceSurface::buffers() const { return {}; }
std::size_t DeviceSurface::allocatedBytes() const { return 0; }
GpuBuffer DeviceSurface::vertexBuffer() const { return {}; }
GpuBuffer DeviceSurface::normalBuffer() const { return {}; }
bool DeviceSurface::separateStreams() const { return false; }
std::size_t DeviceSurface::vertexCount() const { return 0; }
std::string DeviceSurface::deviceName() const { return {}; }

}  // namespace corofem

#endif
