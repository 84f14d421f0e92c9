// The device's attainable memory bandwidth, the yardstick of "fraction of bandwidth": the copy
// kernel of bench/kernels/bandwidth.cl (embedded in the benchmarks at build time).
#pragma once

#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/program_cache.hpp"

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdio>
#include <string>
#include <vector>

namespace corofem {
struct EmbeddedSource {
  const char* name;
  const char* text;
};
extern const EmbeddedSource corofem_bench_sources[];
extern const std::size_t corofem_bench_sources_count;
}  // namespace corofem

namespace corofem::bench {

/// Bytes per second of the copy kernel (read + write counted) on buffers of 64 MiB on CPUs (2x a
/// development machine's L3) or 512 MiB on GPUs (whose L2, 60 MB on an H200, would otherwise hold
/// much of a 64 MiB pair), the median of 9 runs after a warm-up. Measured again by every benchmark
/// right after its own timing loop, so that the fraction pairs two measurements taken under the
/// same load (the machine is shared; one measurement per run once caught a slow spell). `who`
/// labels the line on stderr.
inline double measuredBandwidth(detail::cl::Context& ctx, const char* who) {
  std::string source;
  for (std::size_t i = 0; i < corofem_bench_sources_count; ++i)
    if (std::string(corofem_bench_sources[i].name) == "bandwidth.cl") source = corofem_bench_sources[i].text;
  const auto build = detail::cl::buildProgram(ctx, "bandwidth", source, "-cl-std=CL1.2");
  cl_int status = CL_SUCCESS;
  cl_kernel k = clCreateKernel(build.program, "bandwidth_copy", &status);
  const std::size_t bytes = (ctx.info().gpu ? std::size_t{512} : std::size_t{64}) << 20, count = bytes / 16;
  cl_mem a = clCreateBuffer(ctx.context(), CL_MEM_READ_WRITE, bytes, nullptr, &status);
  cl_mem b = clCreateBuffer(ctx.context(), CL_MEM_READ_WRITE, bytes, nullptr, &status);
  const float one = 1.0f;
  clEnqueueFillBuffer(ctx.queue(), a, &one, sizeof(one), 0, bytes, 0, nullptr, nullptr);
  cl_uint n = static_cast<cl_uint>(count);
  clSetKernelArg(k, 0, sizeof(n), &n);
  clSetKernelArg(k, 1, sizeof(cl_mem), &a);
  clSetKernelArg(k, 2, sizeof(cl_mem), &b);
  std::vector<double> times;
  for (int rep = 0; rep < 10; ++rep) {
    const std::size_t global = count, local = 256;
    const auto t0 = std::chrono::steady_clock::now();
    clEnqueueNDRangeKernel(ctx.queue(), k, 1, nullptr, &global, &local, 0, nullptr, nullptr);
    clFinish(ctx.queue());
    const auto t1 = std::chrono::steady_clock::now();
    if (rep > 0) times.push_back(std::chrono::duration<double>(t1 - t0).count());  // first: warm-up
  }
  std::sort(times.begin(), times.end());
  const double bw = 2.0 * static_cast<double>(bytes) / times[times.size() / 2];
  clReleaseMemObject(a);
  clReleaseMemObject(b);
  clReleaseKernel(k);
  std::fprintf(stderr, "[%s] %s: copy bandwidth %.1f GB/s\n", who, ctx.deviceName().c_str(), bw / 1e9);
  return bw;
}

}  // namespace corofem::bench
