// The OpenCL backend of one body: the one-segment case of the SegmentEngine (segment_engine.hpp),
// which holds the kernels' data and launch sequences for one or many bodies: per-element
// rotations, matrix-free co-rotational forces and products, deterministic per-node gathers and a
// PCG whose scalars stay on the device (kernels/opencl/).
//
// Per call:
//   setPositions   upload x; compute_rotations (a_i = R grad N_i; R when read); the preconditioner
//                  blocks, which rotate with the elements, are left to the next solve
//   internalForces element_forces + gather_sum; download f (a warm-started body's A x is queued
//                  behind it for the next solve)
//   apply          upload p; element_product + gather_product; download y
//   solve          upload b, x; corner_gradients + node_stiffness_blocks if the rotations changed
//                  since they were formed; M^-1, r = b - A x, w = A M^-1 r (pcg_init); single-reduction PCG
//                  iterations (4 launches each, no host read), stopped on the device at convergence;
//                  non-blocking reads of the scalars every checkEvery iterations; true residual;
//                  download x
// Build switches and tuning overrides: segment_engine.cpp.
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/opencl_backend.hpp"

#include "backends/opencl/segment_engine.hpp"
#include "util/error.hpp"

#include <exception>
#include <utility>

namespace corofem::detail {

namespace {

class OpenCLBackend final : public OpenCLBackendInternal {
 public:
  OpenCLBackend(const Problem& problem, const SolverDesc& solver, std::shared_ptr<cl::Context> ctx,
                const OpenCLTuning& tuning)
      : engine_({&problem}, solver, std::move(ctx), tuning) {}

  std::string name() const override { return "opencl"; }
  std::string deviceName() const override { return engine_.deviceDescription(); }

  void setPositions(const Eigen::VectorXd& x) override { call(BatchOp::SetPositions, {}, &x); }
  void internalForces(Eigen::VectorXd& f) override { call(BatchOp::InternalForces, {}, nullptr, &f); }
  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) override {
    call(BatchOp::Apply, c, &p, &y);
  }
  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    return call(BatchOp::Solve, c, &b, &x).stats;
  }
  double elasticEnergy() override { return call(BatchOp::ElasticEnergy).energy; }

  std::vector<double> readRotations() override { return engine_.readRotations(0); }
  const std::string& buildOptions() const override { return engine_.buildOptions(); }
  cl::ProgramOrigin programOrigin() const override { return engine_.programBuild().origin; }
  const cl::ProgramBuild& programBuild() const override { return engine_.programBuild(); }
  cl::Context& context() override { return engine_.context(); }
  std::size_t allocatedBytes() const override { return engine_.allocatedBytes(); }
  std::vector<DeviceBuffer> deviceBuffers() const override { return engine_.buffers(); }
  cl_mem positionBuffer() const override { return engine_.positionBuffer(); }
  bool positionsAreDouble() const override { return engine_.positionsAreDouble(); }
  const double* positionCentroid() const override { return engine_.positionCentroid(0); }
  bool devicePositions(DevicePositions& out) const override {
    out = engine_.devicePositions(0);
    return true;
  }
  void enqueueRotations() override { engine_.enqueueRotations(); }
  void enqueueForces() override { engine_.enqueueForces(); }
  void enqueueElementForces() override { engine_.enqueueElementForces(); }
  void enqueueProduct(const SystemCoeffs& c) override { engine_.enqueueProduct(c); }
  void enqueueElementProduct(const SystemCoeffs& c) override { engine_.enqueueElementProduct(c); }
  void enqueuePcgIterations(const SystemCoeffs& c, int iterations) override {
    engine_.enqueuePcgIterations(c, iterations);
  }
  void finish() override { engine_.finish(); }
  SegmentEngine& engine() override { return engine_; }

 private:
  /// A round of one: the body's own Backend call; its failure is thrown here.
  BatchRequest call(BatchOp op, const SystemCoeffs& c = {}, const Eigen::VectorXd* in = nullptr,
                    Eigen::VectorXd* out = nullptr) {
    BatchRequest r{op, 0, c, in, out, {}, 0.0, nullptr};
    engine_.run(op, {&r});
    if (r.error) std::rethrow_exception(r.error);
    return r;
  }

  SegmentEngine engine_;
};

}  // namespace

std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendOn(const Problem& problem, const SolverDesc& solver,
                                                             std::shared_ptr<cl::Context> context,
                                                             const OpenCLTuning& tuning) {
  return std::make_unique<OpenCLBackend>(problem, solver, std::move(context), tuning);
}

std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendAdopting(const Problem& problem,
                                                                   const SolverDesc& solver,
                                                                   cl_context context,
                                                                   cl_command_queue queue,
                                                                   cl_device_id device,
                                                                   const OpenCLTuning& tuning) {
  return createOpenCLBackendOn(problem, solver, cl::Context::adopt(context, queue, device), tuning);
}

std::unique_ptr<Backend> createOpenCLBackend(const Problem& problem, const SolverDesc& solver,
                                             const std::string& deviceSelector, const OpenCLTuning& tuning) {
  return createOpenCLBackendOn(problem, solver, cl::Context::shared(deviceSelector), tuning);
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
