// The tests' main: GoogleTest's, plus --corofem_morton (common/morton.hpp), which also registers
// the OpenCL backend again so that the devices a Simulation makes through the registry take the
// Morton order.
#include "common/morton.hpp"
#include "device/registry.hpp"

#include <gtest/gtest.h>

#include <cstring>

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  for (int i = 1; i < argc; ++i)
    if (std::strcmp(argv[i], "--corofem_morton") == 0) corofem::test::mortonEverywhere() = true;
  if (corofem::test::mortonEverywhere())
    for (const char* name : {"opencl", "vulkan"})
      if (auto backend = corofem::detail::findBackend(name)) {
        corofem::detail::BackendEntry e = *backend;
        e.create = [inner = backend->create](const std::vector<const corofem::detail::Problem*>& problems,
                                             const corofem::SolverDesc& solver, const corofem::detail::Candidate& c,
                                             const corofem::detail::DeviceOptions& options) {
          corofem::detail::DeviceOptions o = options;
          o.opencl = corofem::test::morton(o.opencl);
          if (o.vulkan.localityOrder < 0) o.vulkan.localityOrder = o.opencl.localityOrder;
          return inner(problems, solver, c, o);
        };
        corofem::detail::registerBackend(std::move(e));
      }
  return RUN_ALL_TESTS();
}
