// Test access to OpenCL internals that no user sets: a device that reports no cl_khr_fp64, and the
// epoch pcg_iterate_team's claims start from (their 32-bit wrap comes after ~10^9 phases).
#pragma once

#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/cpu_pcg.hpp"
#include "backends/opencl/segment_engine.hpp"

#include <memory>
#include <string>

namespace corofem::detail {

namespace cl {
struct ContextTestAccess {
  /// A fresh context on the device `selector` picks, reporting no cl_khr_fp64.
  static std::shared_ptr<cl::Context> withoutFp64(const std::string& selector) {
    std::shared_ptr<cl::Context> ctx = cl::Context::create(selector);
    ctx->info_.fp64 = false;
    return ctx;
  }
};
}  // namespace cl
using cl::ContextTestAccess;

struct SegmentEngineTestAccess {
  /// The last epoch the team's claim words may hold (before the engine's first launch).
  static void setTeamEpoch(SegmentEngine& engine, unsigned epoch) { engine.cpu_->teamEpoch_ = epoch; }
};

}  // namespace corofem::detail
