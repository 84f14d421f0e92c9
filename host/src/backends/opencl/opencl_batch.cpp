// The OpenCL batch device (solve/batch.hpp): every body a segment of one SegmentEngine
// (segment_engine.hpp), so a round costs one launch sequence per kind of call instead of one per
// body. A round's requests are grouped by op and each op runs once for all bodies requesting it;
// bodies that do not request an op keep their state (their segments are inactive for it).
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/segment_engine.hpp"
#include "solve/batch.hpp"
#include "util/error.hpp"

#include <array>
#include <exception>
#include <utility>

namespace corofem::detail {

namespace {

class OpenCLBatchDevice final : public OpenCLBatchDeviceInternal {
 public:
  OpenCLBatchDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                    std::shared_ptr<cl::Context> ctx, const OpenCLTuning& tuning)
      : engine_(problems, solver, std::move(ctx), tuning) {}

  std::string name() const override { return "opencl"; }
  std::string deviceName() const override { return engine_.deviceDescription(); }
  std::size_t bodyCount() const override { return engine_.segmentCount(); }
  std::size_t allocatedBytes() const override { return engine_.allocatedBytes(); }
  std::vector<DeviceBuffer> deviceBuffers() const override { return engine_.buffers(); }
  bool devicePositions(std::size_t body, DevicePositions& out) const override {
    if (body >= engine_.segmentCount()) return false;
    out = engine_.devicePositions(body);
    return true;
  }

  SegmentEngine& engine() override { return engine_; }

  void run(std::vector<BatchRequest*>& round) override {
    constexpr std::size_t kOps = 5;  // BatchOp values, in the order they run
    std::array<std::vector<BatchRequest*>, kOps> byOp;
    std::vector<char> seen(engine_.segmentCount(), 0);
    for (BatchRequest* r : round) {
      r->error = nullptr;
      if (r->body >= seen.size() || seen[r->body]) {
        try {
          fail(ErrorCode::Internal, "OpenCL batch: ", r->body >= seen.size() ? "no body " : "a second request for body ",
               r->body, " in one round (", engine_.segmentCount(), " bodies, at most one request each)");
        } catch (...) {
          r->error = std::current_exception();
        }
        continue;
      }
      seen[r->body] = 1;
      byOp[static_cast<std::size_t>(r->op)].push_back(r);
    }
    try {
      for (std::size_t op = 0; op < kOps; ++op)
        if (!byOp[op].empty()) engine_.run(static_cast<BatchOp>(op), byOp[op]);
    } catch (...) {
      // A device failure (DeviceError) fails every request of the round.
      const std::exception_ptr error = std::current_exception();
      for (BatchRequest* r : round) r->error = error;
    }
  }

 private:
  SegmentEngine engine_;
};

}  // namespace

std::unique_ptr<BatchDevice> createOpenCLBatchDevice(const std::vector<const Problem*>& problems,
                                                     const SolverDesc& solver, const std::string& deviceSelector,
                                                     const OpenCLTuning& tuning) {
  return std::make_unique<OpenCLBatchDevice>(problems, solver, cl::Context::shared(deviceSelector), tuning);
}

std::unique_ptr<OpenCLBatchDeviceInternal> createOpenCLBatchDeviceOn(const std::vector<const Problem*>& problems,
                                                                    const SolverDesc& solver,
                                                                    std::shared_ptr<cl::Context> context,
                                                                    const OpenCLTuning& tuning) {
  return std::make_unique<OpenCLBatchDevice>(problems, solver, std::move(context), tuning);
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
