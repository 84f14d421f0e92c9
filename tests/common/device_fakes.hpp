// Test doubles of devices (device/device.hpp), registered through the same registry users see
// (device/registry.hpp): a forwarding base, a device that fails the way an OpenCL device does
// (build, allocation, launch, read-back), and a scope that registers a backend for a test.
#pragma once

#include "device/registry.hpp"
#include "util/error.hpp"

#include <cmath>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace corofem::test {

/// Forwards every call to the device it wraps (owned, or kept alive by the caller); a fake
/// overrides what it changes.
class ForwardingDevice : public detail::Device {
 public:
  explicit ForwardingDevice(std::unique_ptr<detail::Device> inner) : owned_(std::move(inner)), inner_(owned_.get()) {}
  explicit ForwardingDevice(detail::Device& borrowed) : inner_(&borrowed) {}
  std::string name() const override { return inner_->name(); }
  std::string deviceName() const override { return inner_->deviceName(); }
  std::size_t bodyCount() const override { return inner_->bodyCount(); }
  const detail::Problem& problem(std::size_t body) const override { return inner_->problem(body); }
  void setPositions(const detail::BodySet& b, const detail::ConstVectors& x) override { inner_->setPositions(b, x); }
  void internalForces(const detail::BodySet& b, const detail::Vectors& f) override { inner_->internalForces(b, f); }
  void apply(const detail::BodySet& b, const std::vector<detail::SystemCoeffs>& c, const detail::ConstVectors& p,
             const detail::Vectors& y) override {
    inner_->apply(b, c, p, y);
  }
  void elasticEnergy(const detail::BodySet& b, std::vector<double>& e) override { inner_->elasticEnergy(b, e); }
  void setConstraints(const detail::BodySet& b, const std::vector<const std::vector<std::uint8_t>*>& c) override {
    inner_->setConstraints(b, c);
  }
  void setMaterial(const detail::BodySet& b, const std::vector<const detail::Problem*>& p) override {
    inner_->setMaterial(b, p);
  }
  void setSprings(const detail::BodySet& b, const std::vector<const detail::Problem*>& p) override {
    inner_->setSprings(b, p);
  }
  std::vector<detail::BodySet> pcgTiles(const detail::BodySet& b) const override { return inner_->pcgTiles(b); }
  std::vector<detail::PcgStart> pcgBegin(const detail::BodySet& bodies, const std::vector<detail::SystemCoeffs>& c,
                                         const detail::ConstVectors& b, const detail::ConstVectors& x, double tol,
                                         int cap) override {
    return inner_->pcgBegin(bodies, c, b, x, tol, cap);
  }
  bool pcgOneLaunch() const override { return inner_->pcgOneLaunch(); }
  bool pcgSetupReadable() const override { return inner_->pcgSetupReadable(); }
  void pcgIterate(int n, const std::vector<char>& running) override { inner_->pcgIterate(n, running); }
  detail::PcgTicket pcgRead() override { return inner_->pcgRead(); }
  void pcgTake(detail::PcgTicket t, std::vector<detail::PcgScalars>& s) override { inner_->pcgTake(t, s); }
  void pcgResidual(const std::vector<char>& bodies) override { inner_->pcgResidual(bodies); }
  void pcgEnd(const std::vector<int>& it, const detail::Vectors& x, std::vector<detail::PcgScalars>& r) override {
    inner_->pcgEnd(it, x, r);
  }
  bool hasDirectSolve() const override { return inner_->hasDirectSolve(); }
  detail::LinearSolveStats solveDirect(std::size_t body, const detail::SystemCoeffs& c, const Eigen::VectorXd& b,
                                       Eigen::VectorXd& x) override {
    return inner_->solveDirect(body, c, b, x);
  }
  std::unique_ptr<detail::DeviceSurfaces> createSurfaces(const std::vector<detail::SurfaceMember>& m,
                                                         bool separate) override {
    return inner_->createSurfaces(m, separate);
  }
  std::vector<detail::DeviceBuffer> buffers() const override { return inner_->buffers(); }
  std::vector<detail::DeviceCounter> counters() const override { return inner_->counters(); }
  bool devicePositions(std::size_t body, detail::DevicePositions& out) const override {
    return inner_->devicePositions(body, out);
  }
  detail::Device& inner() { return *inner_; }

 private:
  std::unique_ptr<detail::Device> owned_;
  detail::Device* inner_;
};

enum class FaultKind {
  None,
  Build,       ///< at creation: the program does not build
  Allocation,  ///< at the atCall-th call (element operations and solves; 0 = at creation): an allocation fails
  Launch,      ///< at the atCall-th solve (pcgBegin or solveDirect): a kernel launch fails before anything ran
  ReadBack,    ///< at the atCall-th internalForces: the work ran, its output is garbage (NaN), then the read fails
};

struct FaultSpec {
  FaultKind kind = FaultKind::None;
  int atCall = 1;  ///< 1-based count of the calls the kind counts
};

inline const char* toString(FaultKind k) {
  switch (k) {
    case FaultKind::None: return "none";
    case FaultKind::Build: return "build";
    case FaultKind::Allocation: return "allocation";
    case FaultKind::Launch: return "launch";
    case FaultKind::ReadBack: return "read-back";
  }
  return "?";
}

/// A device that throws Error(DeviceError) the way a failing OpenCL device does, at a chosen call.
class FaultyDevice : public ForwardingDevice {
 public:
  FaultyDevice(std::unique_ptr<detail::Device> inner, FaultSpec spec) : ForwardingDevice(std::move(inner)), spec_(spec) {}
  std::string deviceName() const override { return ForwardingDevice::deviceName() + " [faulty]"; }
  void setPositions(const detail::BodySet& b, const detail::ConstVectors& x) override {
    count(false);
    ForwardingDevice::setPositions(b, x);
  }
  void internalForces(const detail::BodySet& b, const detail::Vectors& f) override {
    count(false);
    if (spec_.kind == FaultKind::ReadBack && ++reads_ == spec_.atCall) {
      ForwardingDevice::internalForces(b, f);
      for (Eigen::VectorXd* v : f) v->setConstant(std::nan(""));
      fail("clEnqueueReadBuffer");
    }
    ForwardingDevice::internalForces(b, f);
  }
  void apply(const detail::BodySet& b, const std::vector<detail::SystemCoeffs>& c, const detail::ConstVectors& p,
             const detail::Vectors& y) override {
    count(false);
    ForwardingDevice::apply(b, c, p, y);
  }
  void elasticEnergy(const detail::BodySet& b, std::vector<double>& e) override {
    count(false);
    ForwardingDevice::elasticEnergy(b, e);
  }
  std::vector<detail::PcgStart> pcgBegin(const detail::BodySet& bodies, const std::vector<detail::SystemCoeffs>& c,
                                         const detail::ConstVectors& b, const detail::ConstVectors& x, double tol,
                                         int cap) override {
    count(true);
    return ForwardingDevice::pcgBegin(bodies, c, b, x, tol, cap);
  }
  detail::LinearSolveStats solveDirect(std::size_t body, const detail::SystemCoeffs& c, const Eigen::VectorXd& b,
                                       Eigen::VectorXd& x) override {
    count(true);
    return ForwardingDevice::solveDirect(body, c, b, x);
  }

 private:
  [[noreturn]] static void fail(const char* call) {
    detail::fail(ErrorCode::DeviceError, call, " failed with CL_OUT_OF_RESOURCES (injected by the test)");
  }
  void count(bool solve) {
    if (spec_.kind == FaultKind::Allocation && ++calls_ == spec_.atCall) fail("clCreateBuffer");
    if (solve && spec_.kind == FaultKind::Launch && ++solves_ == spec_.atCall) fail("clEnqueueNDRangeKernel");
  }
  FaultSpec spec_;
  int calls_ = 0, solves_ = 0, reads_ = 0;
};

/// `inner` with `spec`'s fault; throws Error(DeviceError) here for Build, and for Allocation at call 0.
inline std::unique_ptr<detail::Device> injectFaults(std::unique_ptr<detail::Device> inner, const FaultSpec& spec) {
  if (spec.kind == FaultKind::Build)
    detail::fail(ErrorCode::DeviceError, "clBuildProgram failed with CL_BUILD_PROGRAM_FAILURE (injected by the test)");
  if (spec.kind == FaultKind::Allocation && spec.atCall == 0)
    detail::fail(ErrorCode::DeviceError, "clCreateBuffer failed with CL_MEM_OBJECT_ALLOCATION_FAILURE (injected by the test)");
  return std::make_unique<FaultyDevice>(std::move(inner), spec);
}

/// A candidate of a fake backend.
inline detail::Candidate fakeCandidate(const std::string& backend, const std::string& device,
                                       const std::string& selector = "0", bool gpu = false) {
  detail::Candidate c;
  c.backend = backend;
  c.device = device;
  c.selector = selector;
  c.driver = "test";
  c.gpu = gpu;
  return c;
}

using DeviceFactory = std::function<std::unique_ptr<detail::Device>(
    const std::vector<const detail::Problem*>&, const SolverDesc&, const detail::Candidate&)>;

/// A backend entry of fake devices: `candidates` as listed, each resolved by its selector, every
/// device made by `make`.
inline detail::BackendEntry fakeBackend(const std::string& name, std::vector<detail::Candidate> candidates,
                                        DeviceFactory make, bool batches = false) {
  detail::BackendEntry e;
  e.name = name;
  e.batches = batches;
  e.candidates = [candidates] { return candidates; };
  e.resolve = [candidates, name](const std::string& selector) {
    for (const detail::Candidate& c : candidates)
      if (selector.empty() || c.selector == selector || c.device == selector) return c;
    detail::fail(ErrorCode::DeviceError, "no fake device '", selector, "' on backend '", name, "'");
  };
  e.create = [make](const std::vector<const detail::Problem*>& problems, const SolverDesc& solver,
                    const detail::Candidate& c, const detail::DeviceOptions&) { return make(problems, solver, c); };
  return e;
}

/// The registered backend `name` (a copy of its entry) with every device it makes passed through
/// `wrap` (with the bodies it holds): a real backend with a fault or a limit of the test's.
inline detail::BackendEntry wrapBackend(
    const std::string& name,
    std::function<std::unique_ptr<detail::Device>(std::unique_ptr<detail::Device>, const std::vector<const detail::Problem*>&)>
        wrap) {
  const auto found = detail::findBackend(name);
  if (!found) detail::fail(ErrorCode::BadInput, "no backend '", name, "' to wrap");
  detail::BackendEntry e = *found;
  e.create = [real = e.create, wrap](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                                     const detail::Candidate& c, const detail::DeviceOptions& o) {
    return wrap(real(problems, s, c, o), problems);
  };
  return e;
}

/// Registers a backend for the scope of a test and restores what had its name before (or removes it).
class ScopedBackend {
 public:
  explicit ScopedBackend(detail::BackendEntry entry)
      : name_(entry.name), previous_(detail::findBackend(entry.name)) {
    detail::registerBackend(std::move(entry));
  }
  /// Hides the backend `name` for the scope (registered again at its end).
  explicit ScopedBackend(const std::string& name) : name_(name), previous_(detail::findBackend(name)) {
    detail::unregisterBackend(name);
  }
  ~ScopedBackend() {
    if (previous_) detail::registerBackend(*previous_);
    else detail::unregisterBackend(name_);
  }
  ScopedBackend(const ScopedBackend&) = delete;
  ScopedBackend& operator=(const ScopedBackend&) = delete;

 private:
  std::string name_;
  std::shared_ptr<const detail::BackendEntry> previous_;
};

}  // namespace corofem::test
