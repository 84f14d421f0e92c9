// Helpers of the OpenCL tests and benchmark: the devices to run on and the OpenCL factories; the
// hand-built problems (random element soups, boxes) and random vectors are common/test_problems.hpp.
#pragma once

#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/opencl_backend.hpp"
#include "common/morton.hpp"
#include "common/test_problems.hpp"
#include "model/element.hpp"
#include "model/problem.hpp"

#include <Eigen/Geometry>

#ifndef COROFEM_BENCHMARK
#include <gtest/gtest.h>
#endif

#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

namespace corofem::test {

/// One test parameter: a device index ("" when there is none) and a precision.
struct DeviceCase {
  int device = -1;  ///< index into cl::listDevices(), -1 = no device present
  std::string name;
  Precision precision = Precision::Double;
};

/// How GoogleTest (and so CTest's test list) prints a case: its name, not its bytes.
inline void PrintTo(const DeviceCase& c, std::ostream* os) { *os << c.name; }

inline std::vector<DeviceCase> deviceCases(bool bothPrecisions = true) {
  std::vector<DeviceCase> out;
  const auto devices = detail::cl::listDevices();
  for (std::size_t i = 0; i < devices.size(); ++i) {
    std::string clean;
    for (char c : devices[i].name) clean += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
    clean = "dev" + std::to_string(i) + "_" + clean.substr(0, 24);
    if (devices[i].fp64) out.push_back({static_cast<int>(i), clean, Precision::Double});
    if (bothPrecisions || !devices[i].fp64) out.push_back({static_cast<int>(i), clean, Precision::Float});
  }
  if (out.empty()) out.push_back({-1, "no_opencl_device", Precision::Double});
  return out;
}

#ifndef COROFEM_BENCHMARK
inline std::string caseName(const testing::TestParamInfo<DeviceCase>& info) {
  return info.param.name + (info.param.precision == Precision::Double ? "_double" : "_float");
}

/// Skips the test when no OpenCL device exists.
#define COROFEM_REQUIRE_OPENCL_DEVICE(param)                                                     \
  do {                                                                                           \
    if ((param).device < 0)                                                                      \
      GTEST_SKIP() << "no OpenCL device found on any platform (install a GPU driver or "         \
                      "pocl-opencl-icd); the OpenCL backend cannot be tested here";              \
  } while (0)
#endif

/// One body on an OpenCL device (createOpenCLBackendOn), in the Morton order where the run forces it
/// (--corofem_morton, common/morton.hpp).
inline std::unique_ptr<detail::OpenCLBackendInternal> openclOn(const detail::Problem& problem, const SolverDesc& solver,
                                                               std::shared_ptr<detail::cl::Context> context,
                                                               const OpenCLTuning& tuning = {}) {
  return detail::createOpenCLBackendOn(problem, solver, std::move(context), morton(tuning));
}

/// Bodies on one OpenCL device (createOpenCLBatchOn), in the Morton order where the run forces it.
inline detail::OpenCLBatch openclBatchOn(const std::vector<const detail::Problem*>& problems, const SolverDesc& solver,
                                         std::shared_ptr<detail::cl::Context> context, const OpenCLTuning& tuning = {}) {
  return detail::createOpenCLBatchOn(problems, solver, std::move(context), morton(tuning));
}

}  // namespace corofem::test
