// OpenCL backend benchmarks: per kernel (rotation methods, internal force, product, PCG
// iteration) on generated boxes of ~1k, 10k, 100k and 1M elements, on every
// OpenCL device, plus a full dynamic step of a 10k-element beam (20 PCG iterations, transfers
// included). Reports elements/s and the fraction of the device bandwidth measured here by a copy
// kernel. Run:  bench_opencl --benchmark_format=json [--benchmark_filter=-1M]  (skip the 1M mesh);
// --tuning=field=value,... and --profile: bench_opencl_options.hpp.
// Precision is float unless the name says double or mixed (pcg_iteration_mixed: float vectors and
// products, dot products and PCG scalars in double; pcg_iteration_double for the third point). Device work only (no transfers) except
// dynamic_step, which is what an application sees per frame.
#include <benchmark/benchmark.h>

#ifdef COROFEM_WITH_OPENCL

#define COROFEM_BENCHMARK
#include "backends/opencl/opencl_backend.hpp"
#include "bench_bandwidth.hpp"
#include "bench_opencl_options.hpp"
#include "opencl/opencl_test_support.hpp"

#include <chrono>
#include <cstdio>
#include <map>
#include <memory>
#include <random>

namespace corofem {
namespace {

struct MeshSize {
  const char* label;
  int nx, ny, nz;  ///< cells; 6 tets per cell
};
constexpr MeshSize kSizes[] = {{"1k", 10, 4, 4}, {"10k", 20, 9, 9}, {"100k", 40, 20, 21}, {"1M", 80, 45, 46}};

/// A box problem with the x = 0 face clamped, cached per size (the largest is slow to set up).
const detail::Problem& boxProblem(const MeshSize& size) {
  static std::map<std::string, std::unique_ptr<detail::Problem>> cache;
  auto& slot = cache[size.label];
  if (!slot) {
    if (!cache.empty())
      for (auto& entry : cache)
        if (entry.first != size.label) entry.second.reset();  // one size in memory at a time
    slot = std::make_unique<detail::Problem>(
        test::makeProblem(test::cellBox(size.nx, size.ny, size.nz, 0.1, 0.1, 0.1), 1e5, 0.4, 1000.0));
    for (std::size_t n = 0; n < slot->mesh.nodeCount(); ++n)
      if (slot->mesh.nodes[3 * n] < 1e-9)
        for (int k = 0; k < 3; ++k) slot->constrained[3 * n + k] = 1;
  }
  return *slot;
}

/// Positions: the box bent (tip deflection 10% of its length, whatever the size) and rotated, so
/// that every element gets a non-trivial rotation of comparable size on every mesh.
Eigen::VectorXd deformed(const detail::Problem& p) {
  Eigen::VectorXd x = p.restPositions;
  double length = 0;
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) length = std::max(length, p.restPositions[3 * n]);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) {
    const Eigen::Vector3d X = p.restPositions.segment<3>(3 * n);
    x.segment<3>(3 * n) = R * (X + Eigen::Vector3d(0.0, -0.1 * X.x() * X.x() / length, 0.02 * X.z()));
  }
  return x;
}

double measuredBandwidth(int device) {
  return bench::measuredBandwidth(*detail::cl::Context::shared(std::to_string(device)), "bench_opencl");
}

enum class Work { Rotation, Force, Product, PcgIteration };

struct Config {
  int device;
  MeshSize size;
  Work work;
  RotationMethod rotation = RotationMethod::Polar;
  Precision precision = Precision::Float;
  PreconditionerKind preconditioner = PreconditionerKind::Diagonal;
};

/// Minimum bytes each kernel family must move per element (4-byte indices, r-byte reals, node
/// data amortised with nodes/elements ~ 1/5 for these boxes): the numerator of the bandwidth
/// fraction. Element pass: 4 indices, its per-element reals, the 4 corner vectors it gathers, the
/// 12-vector it writes; gather pass: 4 list entries and the 12-vector read back, plus per node
/// the vectors it reads and writes.
double bytesPerElement(const Config& c, const detail::Problem& p) {
  const double r = c.precision == Precision::Double ? 8.0 : 4.0;  // mixed: float vectors
  const double nodesPerElement = static_cast<double>(p.mesh.nodeCount()) / static_cast<double>(p.mesh.tetCount());
  switch (c.work) {
    case Work::Rotation:  // indices, 9 gradients, 12 corner positions -> 9 R + 9 a
      return 16 + r * (9 + 12 + 18);
    case Work::Force:  // indices, 10 geometry, 12 positions, write 12; gather 16 + 12 r; node: 3 out
      return 16 + r * (10 + 12 + 12) + 16 + r * 12 + nodesPerElement * r * 3;
    case Work::Product:  // as forces, node: mass, p, y
      return 16 + r * (10 + 12 + 12) + 16 + r * 12 + nodesPerElement * r * 9;
    case Work::PcgIteration:  // product + vector updates (x, r, p, q, z, minv: ~12 node vectors);
                              // timed: set-up (1 product) + 20 iterations, counted as 20
      return 16 + r * (10 + 12 + 12) + 16 + r * 12 + nodesPerElement * r * (9 + 3 * 12);
  }
  return 0;
}

void runKernel(benchmark::State& state, Config c) {
  const detail::Problem& p = boxProblem(c.size);
  SolverDesc s;
  s.precision = c.precision;
  s.rotation = c.rotation;
  s.preconditioner = c.preconditioner;
  s.tolerance = 1e-30;  // PCG: run exactly maxIterations
  s.maxIterations = 20;
  s.checkEvery = 1000;
  std::unique_ptr<detail::OpenCLBackendInternal> b;
  try {
    b = detail::createOpenCLBackendOn(p, s, bench::benchContext(c.device), bench::openclOptions().tuning);
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
    return;
  }
  const Eigen::VectorXd x = deformed(p);
  b->setPositions(x);
  const detail::SystemCoeffs coeffs{14400.0, 0.0, 1.0};
  Eigen::VectorXd v = Eigen::VectorXd::Constant(static_cast<Eigen::Index>(p.dofCount()), 1e-3), y, rhs;
  b->apply(coeffs, v, y);  // uploads p for the product benchmarks
  b->internalForces(rhs);
  Eigen::VectorXd sol = Eigen::VectorXd::Zero(rhs.size());
  if (c.work == Work::PcgIteration) b->solve(coeffs, rhs, sol);  // puts b and x on the device
  b->finish();
  for (auto _ : state) {
    switch (c.work) {
      case Work::Rotation: b->enqueueRotations(); break;
      case Work::Force: b->enqueueForces(); break;
      case Work::Product: b->enqueueProduct(coeffs); break;
      case Work::PcgIteration: b->enqueuePcgIterations(coeffs, 20); break;
    }
    b->finish();
  }
  const double elems = static_cast<double>(p.mesh.tetCount());
  const double perIteration = c.work == Work::PcgIteration ? 20.0 : 1.0;
  state.counters["elements"] = elems;
  state.counters["elements_per_s"] =
      benchmark::Counter(elems * perIteration * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  const double bw = measuredBandwidth(c.device);
  state.counters["copy_GBps"] = bw / 1e9;
  state.counters["bandwidth_fraction"] = benchmark::Counter(
      elems * perIteration * bytesPerElement(c, p) * static_cast<double>(state.iterations()) / bw,
      benchmark::Counter::kIsRate);
  state.counters["bytes_per_element"] = bytesPerElement(c, p);
  state.SetLabel(b->deviceName());
  if (c.work == Work::PcgIteration)
    bench::printProfile(b->engine(), std::string(c.preconditioner == PreconditionerKind::Amg ? "pcg_iteration_amg/" : "pcg_iteration/") + c.size.label);
}

/// The 10k-element beam of the dynamic step benchmark (40 x 6 x 7 cells, 10,080 tets), clamped at x = 0.
const detail::Problem& beamProblem() {
  static std::unique_ptr<detail::Problem> beam;
  if (!beam) {
    beam = std::make_unique<detail::Problem>(test::makeProblem(test::cellBox(40, 6, 7, 0.05, 0.05, 0.05), 1e5, 0.4, 1000.0));
    for (std::size_t n = 0; n < beam->mesh.nodeCount(); ++n)
      if (beam->mesh.nodes[3 * n] < 1e-9)
        for (int k = 0; k < 3; ++k) beam->constrained[3 * n + k] = 1;
  }
  return *beam;
}

/// One frame of a linearised implicit step as an application runs it: upload positions,
/// rotations + preconditioner blocks, internal forces down, PCG (20 iterations) with b and the
/// warm start up and the solution down. Float, diagonal preconditioner, checkEvery 4. The positions
/// alternate between two states 1 degree of rotation apart, like consecutive frames. `size` null:
/// the 10k beam; else the box of that size (the 1M-element step on a GPU).
void dynamicStep(benchmark::State& state, int device, const MeshSize* size) {
  const detail::Problem& problem = size ? boxProblem(*size) : beamProblem();
  SolverDesc s;
  s.precision = Precision::Float;
  s.preconditioner = PreconditionerKind::Diagonal;
  s.tolerance = 1e-30;
  s.maxIterations = 20;
  s.checkEvery = 4;
  std::unique_ptr<detail::OpenCLBackendInternal> b;
  try {
    b = detail::createOpenCLBackendOn(problem, s, bench::benchContext(device), bench::openclOptions().tuning);
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
    return;
  }
  // Two states a step apart, taken in turns: the bent body, and the same turned by a further 1
  // degree about its centroid (a body turning at 1 rad/s at 60 Hz), so that every step's
  // rotations differ from the previous step's as in a running simulation.
  Eigen::VectorXd x[2] = {deformed(problem), deformed(problem)};
  {
    const std::size_t nodes = problem.mesh.nodeCount();
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (std::size_t n = 0; n < nodes; ++n) c += x[0].segment<3>(3 * n) / static_cast<double>(nodes);
    const Eigen::Matrix3d turn = Eigen::AngleAxisd(M_PI / 180.0, Eigen::Vector3d(0.3, 0.5, 1.0).normalized()).toRotationMatrix();
    for (std::size_t n = 0; n < nodes; ++n) x[1].segment<3>(3 * n) = c + turn * (x[0].segment<3>(3 * n) - c);
  }
  Eigen::VectorXd f, rhs, v = Eigen::VectorXd::Zero(x[0].size());  // reused, as an application's own
  const double dt = 1.0 / 60.0;
  const detail::SystemCoeffs coeffs{1.0, 0.5 * dt, 0.25 * dt * dt};  // Newmark on velocities
  int iterations = 0;
  long step = 0;
  for (auto _ : state) {
    b->setPositions(x[step++ % 2]);
    b->internalForces(f);
    rhs = -dt * f;
    const auto st = b->solve(coeffs, rhs, v);
    iterations = st.iterations;
  }
  state.counters["elements"] = static_cast<double>(problem.mesh.tetCount());
  state.counters["pcg_iterations"] = iterations;
  state.SetLabel(b->deviceName());
  bench::printProfile(b->engine(), std::string("dynamic_step/dev") + std::to_string(device) + "/" + (size ? size->label : "10k_beam"));
}

const char* workName(Work w) {
  switch (w) {
    case Work::Rotation: return "rotation";
    case Work::Force: return "internal_force";
    case Work::Product: return "product";
    case Work::PcgIteration: return "pcg_iteration";
  }
  return "?";
}

int registerAll() {
  const auto devices = detail::cl::listDevices();
  for (std::size_t d = 0; d < devices.size(); ++d) {
    const int dev = static_cast<int>(d);
    const std::string devName = "dev" + std::to_string(d);
    benchmark::RegisterBenchmark(("dynamic_step_10k_beam_20pcg/" + devName).c_str(),
                                 [dev](benchmark::State& st) { dynamicStep(st, dev, nullptr); })
        ->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true)->UseRealTime();
    for (const MeshSize& size : kSizes)  // the same frame on the boxes (the GPU targets: 10k and 1M)
      benchmark::RegisterBenchmark(("dynamic_step_20pcg/" + devName + "/" + size.label).c_str(),
                                   [dev, &size](benchmark::State& st) { dynamicStep(st, dev, &size); })
          ->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true)->UseRealTime();
    for (const MeshSize& size : kSizes) {
      auto add = [&](const std::string& name, Config c) {
        benchmark::RegisterBenchmark((name + "/" + devName + "/" + size.label).c_str(),
                                     [c](benchmark::State& st) { runKernel(st, c); })
            ->Unit(benchmark::kMicrosecond)->Repetitions(3)->ReportAggregatesOnly(true)->MinTime(0.1)->UseRealTime();
      };
      for (RotationMethod m : {RotationMethod::Polar, RotationMethod::Svd, RotationMethod::Quaternion,
                               RotationMethod::Qr})
        add(std::string("rotation_") + toString(m), {dev, size, Work::Rotation, m});
      add(workName(Work::Force), {dev, size, Work::Force});
      add(workName(Work::Product), {dev, size, Work::Product});
      if (devices[d].fp64) add("product_double", {dev, size, Work::Product, RotationMethod::Polar, Precision::Double});
      add(workName(Work::PcgIteration), {dev, size, Work::PcgIteration});
      // An iteration with the multigrid's V-cycle (its bandwidth fraction counts the diagonal's bytes).
      add("pcg_iteration_amg", {dev, size, Work::PcgIteration, RotationMethod::Polar, Precision::Float,
                                PreconditionerKind::Amg});
      if (devices[d].fp64) {
        add("pcg_iteration_mixed", {dev, size, Work::PcgIteration, RotationMethod::Polar, Precision::Mixed});
        add("pcg_iteration_double", {dev, size, Work::PcgIteration, RotationMethod::Polar, Precision::Double});
      }
    }
  }
  return 0;
}

const int registered = registerAll();

}  // namespace
}  // namespace corofem

#endif  // COROFEM_WITH_OPENCL

int main(int argc, char** argv) {
#ifdef COROFEM_WITH_OPENCL
  corofem::bench::parseOpenCLBenchOptions(argc, argv);
#endif
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
