// The OpenCL device (device/device.hpp) over a SegmentEngine (segment_engine.hpp), which holds the
// kernels' data and launch sequences for one or many bodies: per-element rotations, matrix-free
// co-rotational forces and products, deterministic per-node gathers and the PCG building blocks
// with the scalars on the device (kernels/opencl/). Also the per-body Backend and the batch of
// solve/ over it, and the factories.
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/opencl_backend.hpp"

#include "backends/opencl/segment_engine.hpp"
#include "solve/pcg.hpp"
#include "util/error.hpp"

#include <utility>

namespace corofem::detail {

namespace {

class OpenCLDevice final : public Device {
 public:
  OpenCLDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver, std::shared_ptr<cl::Context> ctx,
               const OpenCLTuning& tuning)
      : engine_(problems, solver, std::move(ctx), tuning) {}

  std::string name() const override { return "opencl"; }
  std::string deviceName() const override { return engine_.deviceDescription(); }
  std::size_t bodyCount() const override { return engine_.segmentCount(); }
  const Problem& problem(std::size_t body) const override { return engine_.problem(body); }

  void setPositions(const BodySet& bodies, const ConstVectors& x) override { engine_.setPositions(bodies, x); }
  void internalForces(const BodySet& bodies, const Vectors& f) override { engine_.internalForces(bodies, f); }
  void apply(const BodySet& bodies, const std::vector<SystemCoeffs>& c, const ConstVectors& p, const Vectors& y) override {
    engine_.apply(bodies, c, p, y);
  }
  void elasticEnergy(const BodySet& bodies, std::vector<double>& energy) override {
    engine_.elasticEnergy(bodies, energy);
  }

  std::vector<BodySet> pcgTiles(const BodySet& bodies) const override { return engine_.pcgTiles(bodies); }
  std::vector<PcgStart> pcgBegin(const BodySet& bodies, const std::vector<SystemCoeffs>& c, const ConstVectors& b,
                                 const ConstVectors& x, double tolerance, int maxIterations) override {
    return engine_.pcgBegin(bodies, c, b, x, tolerance, maxIterations);
  }
  bool pcgOneLaunch() const override { return engine_.pcgOneLaunch(); }
  bool pcgSetupReadable() const override { return engine_.pcgSetupReadable(); }
  void pcgIterate(int n, const std::vector<char>& running) override { engine_.pcgIterate(n, running); }
  PcgTicket pcgRead() override { return engine_.pcgRead(); }
  void pcgTake(PcgTicket ticket, std::vector<PcgScalars>& scalars) override { engine_.pcgTake(ticket, scalars); }
  void pcgResidual(const std::vector<char>& bodies) override { engine_.pcgResidual(bodies); }
  void pcgEnd(const std::vector<int>& iterations, const Vectors& x, std::vector<PcgScalars>& residual) override {
    engine_.pcgEnd(iterations, x, residual);
  }

  std::vector<DeviceBuffer> buffers() const override { return engine_.buffers(); }
  bool devicePositions(std::size_t body, DevicePositions& out) const override {
    if (body >= engine_.segmentCount()) return false;
    out = engine_.devicePositions(body);
    return true;
  }

  SegmentEngine& engine() { return engine_; }

 private:
  SegmentEngine engine_;
};

/// One body on a device of its own, with the internals tests and benchmarks read.
class OpenCLBackend final : public OpenCLBackendInternal {
 public:
  OpenCLBackend(const Problem& problem, const SolverDesc& solver, std::shared_ptr<cl::Context> ctx,
                const OpenCLTuning& tuning)
      : device_(std::make_shared<OpenCLDevice>(std::vector<const Problem*>{&problem}, solver, std::move(ctx), tuning)),
        body_(device_, 0, solver) {}

  std::string name() const override { return body_.name(); }
  std::string deviceName() const override { return body_.deviceName(); }
  void setPositions(const Eigen::VectorXd& x) override { body_.setPositions(x); }
  void internalForces(Eigen::VectorXd& f) override { body_.internalForces(f); }
  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) override { body_.apply(c, p, y); }
  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    return body_.solve(c, b, x);
  }
  double elasticEnergy() override { return body_.elasticEnergy(); }
  std::vector<DeviceBuffer> deviceBuffers() const override { return engine().buffers(); }
  bool devicePositions(DevicePositions& out) const override { return body_.devicePositions(out); }

  std::vector<double> readRotations() override { return engine().readRotations(0); }
  const std::string& buildOptions() const override { return engine().buildOptions(); }
  cl::ProgramOrigin programOrigin() const override { return engine().programBuild().origin; }
  const cl::ProgramBuild& programBuild() const override { return engine().programBuild(); }
  cl::Context& context() override { return engine().context(); }
  std::size_t allocatedBytes() const override { return engine().allocatedBytes(); }
  cl_mem positionBuffer() const override { return engine().positionBuffer(); }
  bool positionsAreDouble() const override { return engine().positionsAreDouble(); }
  const double* positionCentroid() const override { return engine().positionCentroid(0); }
  void enqueueRotations() override { engine().enqueueRotations(); }
  void enqueueForces() override { engine().enqueueForces(); }
  void enqueueElementForces() override { engine().enqueueElementForces(); }
  void enqueueProduct(const SystemCoeffs& c) override { engine().enqueueProduct(c); }
  void enqueueElementProduct(const SystemCoeffs& c) override { engine().enqueueElementProduct(c); }
  void enqueuePcgIterations(const SystemCoeffs& c, int iterations) override {
    engine().enqueuePcgIterations(c, iterations);
  }
  void finish() override { engine().finish(); }
  SegmentEngine& engine() override { return device_->engine(); }

 private:
  const SegmentEngine& engine() const { return device_->engine(); }
  std::shared_ptr<OpenCLDevice> device_;
  DeviceBody body_;
};

class OpenCLBatch final : public OpenCLBatchDeviceInternal {
 public:
  OpenCLBatch(std::shared_ptr<OpenCLDevice> device, const SolverDesc& solver)
      : OpenCLBatchDeviceInternal(device, solver), device_(std::move(device)) {}
  SegmentEngine& engine() override { return device_->engine(); }

 private:
  std::shared_ptr<OpenCLDevice> device_;
};

}  // namespace

std::unique_ptr<Device> createOpenCLDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                           std::shared_ptr<cl::Context> context, const OpenCLTuning& tuning) {
  return std::make_unique<OpenCLDevice>(problems, solver, std::move(context), tuning);
}

std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendOn(const Problem& problem, const SolverDesc& solver,
                                                             std::shared_ptr<cl::Context> context,
                                                             const OpenCLTuning& tuning) {
  return std::make_unique<OpenCLBackend>(problem, solver, std::move(context), tuning);
}

std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendAdopting(const Problem& problem, const SolverDesc& solver,
                                                                   cl_context context, cl_command_queue queue,
                                                                   cl_device_id device, const OpenCLTuning& tuning) {
  return createOpenCLBackendOn(problem, solver, cl::Context::adopt(context, queue, device), tuning);
}

std::unique_ptr<Backend> createOpenCLBackend(const Problem& problem, const SolverDesc& solver,
                                             const std::string& deviceSelector, const OpenCLTuning& tuning) {
  return createOpenCLBackendOn(problem, solver, cl::Context::shared(deviceSelector), tuning);
}

std::unique_ptr<OpenCLBatchDeviceInternal> createOpenCLBatchDeviceOn(const std::vector<const Problem*>& problems,
                                                                    const SolverDesc& solver,
                                                                    std::shared_ptr<cl::Context> context,
                                                                    const OpenCLTuning& tuning) {
  return std::make_unique<OpenCLBatch>(std::make_shared<OpenCLDevice>(problems, solver, std::move(context), tuning),
                                       solver);
}

std::unique_ptr<BatchDevice> createOpenCLBatchDevice(const std::vector<const Problem*>& problems,
                                                     const SolverDesc& solver, const std::string& deviceSelector,
                                                     const OpenCLTuning& tuning) {
  return createOpenCLBatchDeviceOn(problems, solver, cl::Context::shared(deviceSelector), tuning);
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
