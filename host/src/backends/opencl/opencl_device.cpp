// The OpenCL device (device/device.hpp) over a SegmentEngine (segment_engine.hpp), which holds the
// kernels' data and launch sequences for one or many bodies: per-element rotations, matrix-free
// co-rotational forces and products, deterministic per-node gathers and the PCG building blocks
// with the scalars on the device (kernels/opencl/). Also the one-body view of the tests and
// benchmarks, the factories and the registry's entry.
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/opencl_backend.hpp"

#include "backends/opencl/opencl_surfaces.hpp"
#include "backends/opencl/cpu_pcg.hpp"
#include "backends/opencl/segment_engine.hpp"
#include "device/registry.hpp"
#include "solve/pcg.hpp"
#include "util/error.hpp"

#include <sstream>
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
  void setConstraints(const BodySet& bodies, const std::vector<const std::vector<std::uint8_t>*>& constrained) override {
    engine_.setConstraints(bodies, constrained);
  }
  void setMaterial(const BodySet& bodies, const std::vector<const Problem*>& problems) override {
    engine_.setMaterial(bodies, problems);
  }
  void setSprings(const BodySet& bodies, const std::vector<const Problem*>& problems) override {
    engine_.setSprings(bodies, problems);
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

  std::unique_ptr<DeviceSurfaces> createSurfaces(const std::vector<SurfaceMember>& members,
                                                 bool separateStreams) override {
    return createOpenCLSurfaces(engine_, members, separateStreams);
  }

  std::vector<DeviceBuffer> buffers() const override { return engine_.buffers(); }
  std::vector<DeviceCounter> counters() const override {
    const CpuPcgCounts c = engine_.pcgCounts();
    return {{"pcg_group_launches", static_cast<long long>(c.groupLaunches)},
            {"pcg_team_launches", static_cast<long long>(c.teamLaunches)},
            {"pcg_pack_launches", static_cast<long long>(c.packLaunches)},
            {"pcg_pack_lanes", static_cast<long long>(c.packLanes)},
            {"amg_hierarchies_made", engine_.amgBuilds()},
            {"warped_cholesky_factors_made", engine_.warpedBuilds()}};
  }
  bool devicePositions(std::size_t body, DevicePositions& out) const override {
    if (body >= engine_.segmentCount()) return false;
    out = engine_.devicePositions(body);
    return true;
  }

  SegmentEngine& engine() { return engine_; }

 private:
  SegmentEngine engine_;
};

}  // namespace

std::unique_ptr<Device> createOpenCLDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                           std::shared_ptr<cl::Context> context, const OpenCLTuning& tuning) {
  return std::make_unique<OpenCLDevice>(problems, solver, std::move(context), tuning);
}

OpenCLBackendInternal::OpenCLBackendInternal(std::unique_ptr<Device> device, SegmentEngine& engine,
                                             const SolverDesc& solver)
    : device_(std::move(device)), engine_(engine), solver_(solver) {}
OpenCLBackendInternal::~OpenCLBackendInternal() = default;

LinearSolveStats OpenCLBackendInternal::solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) {
  return solveLinear(*device_, 0, c, b, x, solver_);
}
double OpenCLBackendInternal::elasticEnergy() {
  std::vector<double> e;
  device_->elasticEnergy({0}, e);
  return e.at(0);
}
std::vector<double> OpenCLBackendInternal::readRotations() { return engine_.readRotations(0); }
const std::string& OpenCLBackendInternal::buildOptions() const { return engine_.buildOptions(); }
cl::ProgramOrigin OpenCLBackendInternal::programOrigin() const { return engine_.programBuild().origin; }
const cl::ProgramBuild& OpenCLBackendInternal::programBuild() const { return engine_.programBuild(); }
cl::Context& OpenCLBackendInternal::context() { return engine_.context(); }
std::size_t OpenCLBackendInternal::allocatedBytes() const { return engine_.allocatedBytes(); }
cl_mem OpenCLBackendInternal::positionBuffer() const { return engine_.positionBuffer(); }
bool OpenCLBackendInternal::positionsAreDouble() const { return engine_.positionsAreDouble(); }
const double* OpenCLBackendInternal::positionCentroid() const { return engine_.positionCentroid(0); }
void OpenCLBackendInternal::enqueueRotations() { engine_.enqueueRotations(); }
void OpenCLBackendInternal::enqueueForces() { engine_.enqueueForces(); }
void OpenCLBackendInternal::enqueueElementForces() { engine_.enqueueElementForces(); }
void OpenCLBackendInternal::enqueueProduct(const SystemCoeffs& c) { engine_.enqueueProduct(c); }
void OpenCLBackendInternal::enqueueElementProduct(const SystemCoeffs& c) { engine_.enqueueElementProduct(c); }
void OpenCLBackendInternal::enqueuePcgIterations(const SystemCoeffs& c, int iterations) {
  engine_.enqueuePcgIterations(c, iterations);
}
void OpenCLBackendInternal::finish() { engine_.finish(); }

OpenCLBatch createOpenCLBatchOn(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                std::shared_ptr<cl::Context> context, const OpenCLTuning& tuning) {
  auto device = std::make_unique<OpenCLDevice>(problems, solver, std::move(context), tuning);
  OpenCLBatch out;
  out.engine = &device->engine();
  out.device = std::move(device);
  return out;
}

std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendOn(const Problem& problem, const SolverDesc& solver,
                                                             std::shared_ptr<cl::Context> context,
                                                             const OpenCLTuning& tuning) {
  OpenCLBatch one = createOpenCLBatchOn({&problem}, solver, std::move(context), tuning);
  return std::make_unique<OpenCLBackendInternal>(std::move(one.device), *one.engine, solver);
}

std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendAdopting(const Problem& problem, const SolverDesc& solver,
                                                                   cl_context context, cl_command_queue queue,
                                                                   cl_device_id device, const OpenCLTuning& tuning) {
  return createOpenCLBackendOn(problem, solver, cl::Context::adopt(context, queue, device), tuning);
}

// ---------------------------------------------------------------------------- the registry's entry

namespace {

Candidate candidateOf(const cl::DeviceInfo& info, std::size_t index) {
  Candidate c;
  c.backend = "opencl";
  c.device = info.name;
  c.selector = std::to_string(index);
  c.driver = info.platformName + " " + info.driverVersion;
  c.gpu = info.gpu;
  return c;
}

}  // namespace

void registerOpenCLBackend() {
  BackendEntry e;
  e.name = "opencl";
  e.batches = true;
  e.passes = [](const PlanPasses& step) {
    std::vector<std::string> k;
    if (step.corotational) k.push_back(std::string("compute_rotations (") + toString(step.rotation) + ")");
    k.push_back("element_forces + gather_forces");
    k.push_back(step.dynamic ? (step.damping ? "element_product (M, C, K_t) + gather_product"
                                             : "element_product (M, K_t) + gather_product")
                             : "element_product (K_t) + gather_product");
    k.push_back(std::string("pcg_init") + step.formsInverse() +
                ", pcg_update, reduce_finish (single-reduction PCG; on a CPU device the iterations "
                "of a round of small bodies, or of as many bodies as cores, run in one launch: "
                "pcg_iterate_group, where bodies of one mesh take a vector lane each of a pack of 8: "
                "pcg_iterate_pack; those of a round of fewer bodies than cores in one launch by a team "
                "of work-groups per body: pcg_iterate_team)");
    if (step.amg())
      k.push_back("amg V-cycle per iteration: Chebyshev smoothing with 4 products (element_product + "
                  "gather_product), amg_fine_*, amg_spmv on the coarse levels (the iterations are launched "
                  "ones, not pcg_iterate_*)");
    return k;
  };
  e.candidates = [] {
    std::vector<Candidate> out;
    const std::vector<cl::DeviceInfo> devices = cl::listDevices();
    for (std::size_t i = 0; i < devices.size(); ++i) out.push_back(candidateOf(devices[i], i));
    return out;
  };
  e.resolve = [](const std::string& selector) {
    if (selector == kExternalSelector) {
      Candidate c;
      c.backend = "opencl";
      c.device = "the application's OpenCL device";
      c.selector = kExternalSelector;
      c.driver = "external";
      return c;
    }
    const cl::DeviceInfo info = cl::selectDevice(selector);  // DeviceError listing the devices
    const std::vector<cl::DeviceInfo> all = cl::listDevices();
    for (std::size_t i = 0; i < all.size(); ++i)
      if (all[i].device == info.device) return candidateOf(info, i);
    fail(ErrorCode::DeviceError, "OpenCL device '", info.name, "' is not in the device list");
  };
  e.refuses = hostOnlyFeature;
  e.create = [](const std::vector<const Problem*>& problems, const SolverDesc& solver, const Candidate& c,
                const DeviceOptions& options) {
    if (c.selector == kExternalSelector) {
      if (!options.external)
        fail(ErrorCode::BadInput, "\"opencl:", kExternalSelector, "\" names the application's OpenCL device, and "
             "none was given; set SimulationOptions::device (context, queue, device)");
      return createOpenCLDevice(problems, solver, cl::Context::adopt(options.external, "SimulationOptions::device"),
                                options.opencl);
    }
    return createOpenCLDevice(problems, solver, cl::Context::shared(c.selector), options.opencl);
  };
  e.buildId = [] {
    // The kernels' source, and the revision of the defaults that choose among them (tuning.cpp,
    // cpu_pcg.cpp): a change of either makes earlier calibrations stale. Revision 2: teams chosen by
    // measurement (team_choice.hpp).
    constexpr int kStrategyRevision = 2;
    std::ostringstream hex;
    hex << "kernels " << std::hex << cl::fnv1a64(cl::corofemProgramSource()) << std::dec << ", strategies "
        << kStrategyRevision;
    return hex.str();
  };
  registerBackend(std::move(e));
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
