// Fault-injecting Backend decorator (see fault_injection.hpp).
#include "schedule/fault_injection.hpp"

#include "util/error.hpp"

#include <limits>

namespace corofem::detail {

namespace {

class FaultyBackend final : public Backend {
 public:
  FaultyBackend(std::unique_ptr<Backend> inner, const FaultSpec& spec) : inner_(std::move(inner)), spec_(spec) {}

  std::string name() const override { return inner_->name(); }
  std::string deviceName() const override { return inner_->deviceName() + " [fault: " + toString(spec_.kind) + "]"; }

  void setPositions(const Eigen::VectorXd& x) override {
    allocation("setPositions");
    inner_->setPositions(x);
  }
  void internalForces(Eigen::VectorXd& f) override {
    allocation("internalForces");
    inner_->internalForces(f);
    if (spec_.kind == FaultKind::ReadBack && ++forces_ == spec_.atCall) {
      f.setConstant(std::numeric_limits<double>::quiet_NaN());
      fail(ErrorCode::DeviceError, "OpenCL: clEnqueueReadBuffer failed: CL_OUT_OF_RESOURCES (injected read-back fault)");
    }
  }
  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) override {
    allocation("apply");
    inner_->apply(c, p, y);
  }
  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    allocation("solve");
    if (spec_.kind == FaultKind::Launch && ++solves_ == spec_.atCall) {
      // Half-done work: the warm start is already overwritten when the launch fails.
      x.setConstant(std::numeric_limits<double>::quiet_NaN());
      fail(ErrorCode::DeviceError, "OpenCL: clEnqueueNDRangeKernel(pcg_update) failed: CL_OUT_OF_RESOURCES (injected launch fault)");
    }
    return inner_->solve(c, b, x);
  }
  double elasticEnergy() override {
    allocation("elasticEnergy");
    return inner_->elasticEnergy();
  }
  bool devicePositions(DevicePositions& out) const override { return inner_->devicePositions(out); }

 private:
  void allocation(const char* call) {
    if (spec_.kind == FaultKind::Allocation && ++calls_ == spec_.atCall)
      fail(ErrorCode::DeviceError, "OpenCL: clCreateBuffer failed in ", call,
           ": CL_MEM_OBJECT_ALLOCATION_FAILURE (injected allocation fault)");
  }

  std::unique_ptr<Backend> inner_;
  FaultSpec spec_;
  int calls_ = 0, solves_ = 0, forces_ = 0;
};

}  // namespace

const char* toString(FaultKind k) {
  switch (k) {
    case FaultKind::None: return "none";
    case FaultKind::Build: return "build";
    case FaultKind::Allocation: return "allocation";
    case FaultKind::Launch: return "launch";
    case FaultKind::ReadBack: return "read-back";
  }
  return "?";
}

std::unique_ptr<Backend> injectFaults(std::unique_ptr<Backend> inner, const FaultSpec& spec) {
  if (spec.kind == FaultKind::Build)
    fail(ErrorCode::DeviceError, "OpenCL: clBuildProgram failed: CL_BUILD_PROGRAM_FAILURE (injected build fault)");
  if (spec.kind == FaultKind::Allocation && spec.atCall == 0)
    fail(ErrorCode::DeviceError, "OpenCL: clCreateBuffer failed: CL_MEM_OBJECT_ALLOCATION_FAILURE (injected allocation fault)");
  return std::make_unique<FaultyBackend>(std::move(inner), spec);
}

}  // namespace corofem::detail
