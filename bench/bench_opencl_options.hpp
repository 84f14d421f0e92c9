// Command-line settings of the OpenCL benchmarks, read before Google Benchmark's own flags:
//   --tuning=field=value[,field=value...]  OpenCLTuning fields for every backend the benchmark makes
//                                          (e.g. --tuning=workGroupSize=128,groupPcg=0)
//   --profile                              per kernel: launches, device time and the device's idle
//                                          time before its launches, on stderr after each benchmark
// They replace the environment variables the library once read: measurement variants live here.
#pragma once

#include "backends/opencl/opencl_backend.hpp"
#include "backends/opencl/segment_engine.hpp"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <string>

namespace corofem::bench {

struct OpenCLBenchOptions {
  OpenCLTuning tuning;
  bool profile = false;
};

inline OpenCLBenchOptions& openclOptions() {
  static OpenCLBenchOptions o;
  return o;
}

/// Sets one OpenCLTuning field by name; false for an unknown name.
inline bool setTuningField(OpenCLTuning& t, const std::string& name, long long v) {
  const std::map<std::string, std::size_t*> sizes = {
      {"workGroupSize", &t.workGroupSize},         {"elementsPerItem", &t.elementsPerItem},
      {"nodesPerItem", &t.nodesPerItem},           {"hostChunk", &t.hostChunk},
      {"groupPcgMinBodies", &t.groupPcgMinBodies}, {"groupPcgSmallElements", &t.groupPcgSmallElements},
      {"groupPcgMaxElements", &t.groupPcgMaxElements}, {"teamPcgMaxElements", &t.teamPcgMaxElements},
      {"teamPcgMinElements", &t.teamPcgMinElements},   {"teamPcgSize", &t.teamPcgSize},
      {"packPcgMinLanes", &t.packPcgMinLanes},     {"claimWorkGroups", &t.claimWorkGroups}};
  const std::map<std::string, int*> ints = {
      {"workGroupSums", &t.workGroupSums}, {"quaternionIterations", &t.quaternionIterations},
      {"groupPcg", &t.groupPcg},           {"teamPcg", &t.teamPcg},
      {"packPcg", &t.packPcg},             {"localityOrder", &t.localityOrder},
      {"flushDenormals", &t.flushDenormals}};
  if (auto it = sizes.find(name); it != sizes.end()) return *it->second = static_cast<std::size_t>(v), true;
  if (auto it = ints.find(name); it != ints.end()) return *it->second = static_cast<int>(v), true;
  if (name == "tileBytes") return t.tileBytes = v, true;
  return false;
}

/// Takes --tuning and --profile out of argv (before benchmark::Initialize); exits with a message
/// on a malformed value.
inline void parseOpenCLBenchOptions(int& argc, char** argv) {
  OpenCLBenchOptions& o = openclOptions();
  int out = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--profile") {
      o.profile = true;
    } else if (arg.rfind("--tuning=", 0) == 0) {
      std::string list = arg.substr(9);
      while (!list.empty()) {
        const std::string item = list.substr(0, list.find(','));
        list = list.size() > item.size() ? list.substr(item.size() + 1) : "";
        const std::size_t eq = item.find('=');
        char* end = nullptr;
        const long long v = eq == std::string::npos ? 0 : std::strtoll(item.c_str() + eq + 1, &end, 10);
        if (eq == std::string::npos || !end || *end || !setTuningField(o.tuning, item.substr(0, eq), v)) {
          std::fprintf(stderr, "--tuning: '%s' is not field=integer with an OpenCLTuning field "
                               "(corofem/tuning.hpp)\n", item.c_str());
          std::exit(2);
        }
      }
    } else {
      argv[out++] = argv[i];
    }
  }
  argc = out;
}

/// The context the benchmarks run on: the process-wide one of the device, or with --profile a
/// context of its own whose queue profiles (one per device, kept for the process).
inline std::shared_ptr<detail::cl::Context> benchContext(int device) {
  const std::string selector = std::to_string(device);
  if (!openclOptions().profile) return detail::cl::Context::shared(selector);
  static std::map<int, std::shared_ptr<detail::cl::Context>> profiling;
  auto& ctx = profiling[device];
  if (!ctx) {
    const detail::cl::DeviceInfo info = detail::cl::selectDevice(selector);
    cl_int status = CL_SUCCESS;
    cl_context c = clCreateContext(nullptr, 1, &info.device, nullptr, nullptr, &status);
    cl_command_queue q = clCreateCommandQueue(c, info.device, CL_QUEUE_PROFILING_ENABLE, &status);
    ctx = detail::cl::Context::adopt(c, q, info.device);
    clReleaseCommandQueue(q);  // the adopted context holds its own references
    clReleaseContext(c);
  }
  return ctx;
}

/// With --profile: the engine's kernel profile on stderr, under `title`.
inline void printProfile(detail::SegmentEngine& engine, const std::string& title) {
  if (!openclOptions().profile) return;
  for (const detail::KernelProfile& k : engine.kernelProfile())
    std::fprintf(stderr, "[profile %s] %-24s %8ld launches %10.1f us each, device idle %8.1f us before each\n",
                 title.c_str(), k.kernel.c_str(), k.launches, 1e6 * k.deviceSeconds / static_cast<double>(k.launches),
                 1e6 * k.idleSecondsBefore / static_cast<double>(k.launches));
}

}  // namespace corofem::bench
