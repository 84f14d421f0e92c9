// The OpenCL backend's locality order (mesh/locality_order.hpp) on real meshes: the meshes of
// ../shared/data as their files number them (OpenCLTuning::localityOrder = 0) against the device's
// Morton order (the default rule, which takes it for every mesh here), on every OpenCL device, float:
//   product/<mesh>/<order>   the matrix-free product y = A p (element pass + gather), device only;
//   step/<mesh>/<order>      a dynamic step as bench_opencl's dynamic_step: positions up, rotations,
//                            forces down, PCG with 20 iterations (diagonal), the solution down.
// And the box generator's 100k-element box, whose layered numbering the rule keeps, with the Morton
// order forced (localityOrder = 1), for what that order costs where it is not taken; and on the
// Armadillo, denormal floats flushed (the default on CPUs) against kept (OpenCLTuning::
// flushDenormals = 0): the step as above, and the product of a vector of 1e-39, a denormal float
// (the velocities of a body that came to rest under damping long ago, in a scene without
// analysis.sleep, decay to such values).
//   ./build/bench/bench_mesh_order --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
// Reads the meshes from $COROFEM_DATA_DIR/meshes, else ../shared/data/meshes beside the sources;
// skips a mesh whose file is absent.
#include <benchmark/benchmark.h>

#ifdef COROFEM_WITH_OPENCL

#define COROFEM_BENCHMARK
#include "backends/opencl/opencl_backend.hpp"
#include "opencl/opencl_test_support.hpp"

#include <corofem/mesh.hpp>

#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace corofem {
namespace {

const char* kMeshes[] = {"ipc/Armadillo13K.msh", "ipc/dolphin5K.msh", "ipc/rod300x33.msh", "sfepy/wheelset.vtk",
                         "box100k"};

const detail::Problem* problemOf(const std::string& name) {
  static std::map<std::string, std::unique_ptr<detail::Problem>> cache;
  auto& slot = cache[name];
  if (!slot) {
    TetMesh mesh;
    if (name == "box100k") {
      mesh = test::cellBox(40, 20, 21, 0.1, 0.1, 0.1);
    } else {
      const char* env = std::getenv("COROFEM_DATA_DIR");  // as the tests: else ../shared beside the sources
      const std::string path = (env && *env ? std::string(env) : std::string(COROFEM_SOURCE_DIR) + "/../shared/data") +
                               "/meshes/" + name;
      if (!std::filesystem::exists(path)) return nullptr;
      auto read = readTetMesh(path);
      if (!read) return nullptr;
      mesh = std::move(read.value());
    }
    slot = std::make_unique<detail::Problem>(test::makeProblem(mesh, 1e5, 0.4, 1000.0));
    // Clamp the nodes of the lowest 10 % along x, so that the step's system is a body held in place.
    double lo = 1e300, hi = -1e300;
    for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
      lo = std::min(lo, mesh.nodes[3 * n]);
      hi = std::max(hi, mesh.nodes[3 * n]);
    }
    for (std::size_t n = 0; n < mesh.nodeCount(); ++n)
      if (mesh.nodes[3 * n] < lo + 0.1 * (hi - lo))
        for (int k = 0; k < 3; ++k) slot->constrained[3 * n + k] = 1;
  }
  return slot.get();
}

/// The rest shape bent about z and turned as a whole (every element rotates, as in a frame).
Eigen::VectorXd deformed(const detail::Problem& p, double turn) {
  Eigen::VectorXd x = p.restPositions;
  double lo = 1e300, hi = -1e300;
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) {
    lo = std::min(lo, p.restPositions[3 * n]);
    hi = std::max(hi, p.restPositions[3 * n]);
  }
  const double length = std::max(hi - lo, 1e-12);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.5 + turn, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) {
    const Eigen::Vector3d X = p.restPositions.segment<3>(3 * n);
    const double s = (X.x() - lo) / length;
    x.segment<3>(3 * n) = R * (X + Eigen::Vector3d(0.0, -0.1 * length * s * s, 0.0));
  }
  return x;
}

void run(benchmark::State& state, std::string name, int order, bool step, int flush, double pValue) {
  const detail::Problem* p = problemOf(name);
  if (!p) {
    state.SkipWithError(("the mesh " + name + " is absent (../shared/data/meshes beside the sources, or COROFEM_DATA_DIR)").c_str());
    return;
  }
  SolverDesc s;
  s.precision = Precision::Float;
  s.preconditioner = PreconditionerKind::Diagonal;
  s.tolerance = 1e-30;  // exactly 20 iterations
  s.maxIterations = 20;
  s.checkEvery = 4;
  detail::OpenCLTuning o;
  o.localityOrder = order;
  o.flushDenormals = flush;
  std::unique_ptr<detail::OpenCLBackendInternal> b;
  try {
    b = detail::createOpenCLBackendOn(*p, s, detail::cl::Context::shared("0"), o);
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
    return;
  }
  detail::DevicePositions where;
  b->devicePositions(where);
  const Eigen::VectorXd x[2] = {deformed(*p, 0.0), deformed(*p, 0.0175)};
  const double dt = 1.0 / 60.0;
  const detail::SystemCoeffs coeffs{1.0, 0.5 * dt, 0.25 * dt * dt};
  Eigen::VectorXd f, rhs, v = Eigen::VectorXd::Zero(x[0].size()), y;
  b->setPositions(x[0]);
  b->apply(coeffs, Eigen::VectorXd::Constant(x[0].size(), pValue), y);  // p on the device
  b->finish();
  long k = 0;
  int iterations = 0;
  for (auto _ : state) {
    if (step) {
      b->setPositions(x[k++ % 2]);
      b->internalForces(f);
      rhs = -dt * f;
      iterations = b->solve(coeffs, rhs, v).iterations;
    } else {
      b->enqueueProduct(coeffs);
      b->finish();
    }
  }
  state.counters["elements"] = static_cast<double>(p->mesh.tetCount());
  state.counters["elements_per_s"] =
      benchmark::Counter(static_cast<double>(p->mesh.tetCount()) * static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate);
  state.counters["device_reordered"] = where.deviceNode ? 1 : 0;
  if (step) state.counters["pcg_iterations"] = iterations;  // 20 unless the residual underflowed to 0
  state.SetLabel(b->deviceName());
}

int registerAll() {
  for (bool step : {false, true})
    for (const char* mesh : kMeshes) {
      const std::string name = mesh;
      const bool box = name == "box100k";
      struct Variant {
        int order, flush;
        const char* label;
        double p = 1e-3;
      };
      std::vector<Variant> variants = {{0, -1, "file_order"}, {box ? 1 : -1, -1, box ? "morton_forced" : "morton"}};
      if (name == "ipc/Armadillo13K.msh") {
        variants.push_back({-1, 0, "morton_denormals_kept"});
        if (!step) {
          variants.push_back({-1, -1, "morton_p_1e-39", 1e-39});
          variants.push_back({-1, 0, "morton_p_1e-39_denormals_kept", 1e-39});
        }
      }
      for (const Variant& v : variants)
        benchmark::RegisterBenchmark((std::string(step ? "step/" : "product/") + name + "/" + v.label).c_str(), run,
                                     name, v.order, step, v.flush, v.p)
            ->Unit(benchmark::kMicrosecond)
            ->UseRealTime();
    }
  return 0;
}
const int registered = registerAll();

}  // namespace
}  // namespace corofem

#endif  // COROFEM_WITH_OPENCL

BENCHMARK_MAIN();
