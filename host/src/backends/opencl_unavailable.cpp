// The "opencl" entry of a library built without the OpenCL backend: it lists no device, and asking
// for it gives a clear status, never a broken link.
#ifndef COROFEM_WITH_OPENCL

#include "device/registry.hpp"

namespace corofem::detail {

void registerOpenCLBackend() {
  registerBackend(unavailableBackend(
      "opencl", "the OpenCL backend is not compiled into this corofem build; reconfigure with "
                "-DCOROFEM_WITH_OPENCL=ON (cmake --preset opencl), or use \"backend\": \"reference\""));
}

}  // namespace corofem::detail

#endif
