// The "opencl" entry of a library built without the OpenCL backend: it lists no device, and asking
// for it gives a clear status, never a broken link.
#ifndef COROFEM_WITH_OPENCL

#include "device/registry.hpp"
#include "util/error.hpp"

namespace corofem::detail {

namespace {

[[noreturn]] void notCompiledIn() {
  fail(ErrorCode::NotCompiledIn,
       "the OpenCL backend is not compiled into this corofem build; reconfigure with "
       "-DCOROFEM_WITH_OPENCL=ON (cmake --preset opencl), or use \"backend\": \"reference\"");
}

}  // namespace

void registerOpenCLBackend() {
  BackendEntry e;
  e.name = "opencl";
  e.candidates = [] { return std::vector<Candidate>{}; };
  e.resolve = [](const std::string&) -> Candidate { notCompiledIn(); };
  e.refuses = [](const Problem&, const SolverDesc&) -> std::string { notCompiledIn(); };
  e.create = [](const std::vector<const Problem*>&, const SolverDesc&, const Candidate&,
                const DeviceOptions&) -> std::unique_ptr<Device> { notCompiledIn(); };
  registerBackend(std::move(e));
}

}  // namespace corofem::detail

#endif
