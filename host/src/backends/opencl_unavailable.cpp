// Factory of the OpenCL backend when the library is built without it: a clear status, never a
// broken link.
#ifndef COROFEM_WITH_OPENCL

#include "solve/backend.hpp"
#include "solve/batch.hpp"
#include "util/error.hpp"

namespace corofem::detail {

std::unique_ptr<Backend> createOpenCLBackend(const Problem&, const SolverDesc&, const std::string&, const OpenCLTuning&) {
  fail(ErrorCode::NotCompiledIn,
       "the OpenCL backend is not compiled into this corofem build; reconfigure with "
       "-DCOROFEM_WITH_OPENCL=ON (cmake --preset opencl), or use \"backend\": \"reference\"");
}

std::unique_ptr<BatchDevice> createOpenCLBatchDevice(const std::vector<const Problem*>&, const SolverDesc&,
                                                     const std::string&, const OpenCLTuning&) {
  fail(ErrorCode::NotCompiledIn,
       "the OpenCL batch device (many bodies, one set of launches) is not compiled into this corofem "
       "build; reconfigure with -DCOROFEM_WITH_OPENCL=ON (cmake --preset opencl), or use \"backend\": "
       "\"reference\"");
}

}  // namespace corofem::detail

#endif
