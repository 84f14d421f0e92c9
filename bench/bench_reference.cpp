// Reference backend (Eigen, double, assembled) through the public Simulation API, on the shared
// bar meshes (10 x 0.5 x 1, clamped at x = 0, self-weight in -z):
//   - BM_DynamicStep: one co-rotational Newmark step (one linearised Newton iteration as in the
//     paper, PCG with the diagonal preconditioner, tolerance 1e-6, h = 1/60 s). gamma = 0.6 (with
//     beta = 0.3025) so that the thousands of steps a benchmark takes stay stable: the undamped
//     linearised trapezoidal step gains energy on co-rotational bodies (see DynamicSolver).
//   - BM_StaticSolve: one full static Newton solve (co-rotational, one increment, Cholesky).
// Counters: elements/s (elements x steps per second of wall time), PCG and Newton iterations per
// step. A missing mesh skips the benchmark with the reason.
#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>

#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace {

using namespace corofem;

std::string meshPath(const std::string& name) {
  const char* env = std::getenv("COROFEM_DATA_DIR");
  const std::string root = env ? env : std::string(COROFEM_SOURCE_DIR) + "/../shared/data";
  return root + "/meshes/ipc/" + name + ".msh";
}

Scene barScene(const std::string& path, AnalysisDesc::Kind kind) {
  BodyDesc body;
  body.name = "bar";
  body.mesh.file = path;
  body.material.youngsModulus = 1e8;  // beam theory: q L^4 / (8 E I) = 1.5 m of sag, 15 % of L
  body.material.poissonRatio = 0.3;
  body.material.density = 1000;
  body.formulation = Formulation::Corotational;
  NodeSetDesc clamp;
  clamp.kind = NodeSetDesc::Kind::Plane;
  clamp.planePoint = {0, 0, 0};
  clamp.planeNormal = {1, 0, 0};
  clamp.planeTolerance = 1e-6;
  body.fixed.push_back(clamp);
  LoadDesc g;
  g.kind = LoadDesc::Kind::Gravity;
  g.vector = {0, 0, -9.81};
  body.loads.push_back(g);

  Scene scene;
  scene.name = "bench";
  scene.bodies.push_back(body);
  scene.backend.kind = BackendKind::Reference;
  scene.analysis.kind = kind;
  if (kind == AnalysisDesc::Kind::Dynamic) {
    scene.analysis.dynamics.timeStep = 1.0 / 60.0;
    scene.analysis.dynamics.steps = 1 << 30;
    scene.analysis.dynamics.newmarkGamma = 0.6;
    scene.analysis.dynamics.newmarkBeta = 0.3025;
    scene.solver.linearSolver = LinearSolverKind::Pcg;
    scene.solver.preconditioner = PreconditionerKind::Diagonal;
    scene.solver.tolerance = 1e-6;
  } else {
    scene.analysis.statics.increments = 1;
    scene.solver.linearSolver = LinearSolverKind::Cholesky;
  }
  return scene;
}

void dynamicStep(benchmark::State& state, const std::string& mesh) {
  const std::string path = meshPath(mesh);
  if (!std::filesystem::exists(path)) {
    state.SkipWithError(("mesh file absent: " + path).c_str());
    return;
  }
  auto sim = Simulation::create(barScene(path, AnalysisDesc::Kind::Dynamic));
  if (!sim) {
    state.SkipWithError(sim.message().c_str());
    return;
  }
  const double elements = static_cast<double>(sim->restMesh(0).tetCount());
  double pcg = 0, newton = 0;
  for (auto _ : state) {
    StepReport r;
    Status st = sim->step(&r);
    if (!st) {
      state.SkipWithError(st.message().c_str());
      return;
    }
    pcg += r.linearIterations;
    newton += r.newtonIterations;
  }
  const double steps = static_cast<double>(state.iterations());
  state.counters["elements"] = elements;
  state.counters["elements/s"] = benchmark::Counter(elements, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["pcg_iter/step"] = pcg / steps;
  state.counters["newton/step"] = newton / steps;
}

void staticSolve(benchmark::State& state, const std::string& mesh) {
  const std::string path = meshPath(mesh);
  if (!std::filesystem::exists(path)) {
    state.SkipWithError(("mesh file absent: " + path).c_str());
    return;
  }
  const Scene scene = barScene(path, AnalysisDesc::Kind::Static);
  double elements = 0, newton = 0;
  for (auto _ : state) {
    state.PauseTiming();
    auto sim = Simulation::create(scene);  // set-up (mesh read, element set-up) is not timed
    state.ResumeTiming();
    if (!sim) {
      state.SkipWithError(sim.message().c_str());
      return;
    }
    StepReport r;
    Status st = sim->step(&r);
    if (!st) {
      state.SkipWithError(st.message().c_str());
      return;
    }
    elements = static_cast<double>(sim->restMesh(0).tetCount());
    newton += r.newtonIterations;
  }
  state.counters["elements"] = elements;
  state.counters["elements/s"] = benchmark::Counter(elements, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["newton/solve"] = newton / static_cast<double>(state.iterations());
}

}  // namespace

BENCHMARK_CAPTURE(dynamicStep, bar_186, std::string("bar-186"))->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(dynamicStep, bar_651, std::string("bar-651"))->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(dynamicStep, bar_2523, std::string("bar-2523"))->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(dynamicStep, bar_14114, std::string("bar-14114"))->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(staticSolve, bar_186, std::string("bar-186"))->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(staticSolve, bar_651, std::string("bar-651"))->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(staticSolve, bar_2523, std::string("bar-2523"))->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(staticSolve, bar_14114, std::string("bar-14114"))->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
