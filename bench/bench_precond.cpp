// The PCG preconditioners side by side on the "Vega beam" of issue 29, on the reference backend
// and on the OpenCL and Vulkan backends in float (their first devices), through the public
// Simulation API:
// bench/scenes/vega_beam.json (1 x 0.1 x 0.1 m, box cells 60 x 6 x 6, 6 tets per cell = 12,960
// tets, E = 1e6 Pa, nu = 0.3, rho = 1000, clamped at x = 0, gravity -z, backward Euler at h = 1/60 s,
// one Newton iteration, PCG tolerance 1e-6, max_iterations 3000).
//
//   precondStep/<backend>/<preconditioner>/tets_12960   backend "reference", "opencl_float" or
//                                                       "vulkan_float";
//                                                       "diagonal", "block_diagonal", "amg" and,
//                                                       except on Vulkan, "warped_cholesky"
//   precondStep/<backend>/<preconditioner>/tets_103680  cells 120 x 12 x 12, "diagonal" and "amg"
//                                                       (and "warped_cholesky" except on Vulkan);
//                                                       slow (seconds a step on the reference, a
//                                                       set-up of seconds), registered only with
//                                                       the flag --large
//   precondGrab/<backend>/<preconditioner>/tets_12960   "amg" (and "warped_cholesky" except on
//                                                       Vulkan): the beam's tip grabbed by a
//                                                       hard handle after the warm-up and lifted
//                                                       2 cm, the timed steps held, then released:
//                                                       grab_step_ms (the step after the grab: its
//                                                       hierarchy's or factor's set-up),
//                                                       release_step_ms (the spare taken back). At
//                                                       0db57de it compared a hierarchy kept through
//                                                       the grab ("kept") with one made for it.
// (OpenCL and Vulkan variants skip with the reason where the build or the machine has no such device.)
//
// Each benchmark creates its Simulation and takes 3 warm-up steps outside the timed loop (the first
// solve builds the preconditioner: amg's hierarchy, the warped Cholesky's factor), then times 30
// steps (10 on the large beam) from there; a repetition starts again from a fresh Simulation, so
// repetitions time the same steps.
// Counters:
//   ms/step          wall time of sim->step per timed step (the median is the _median aggregate of
//                    --benchmark_repetitions)
//   pcg/step         PCG iterations per timed step
//   first_step_ms    the first warm-up step: the preconditioner's set-up plus a step
//   unconverged      timed steps whose solves stopped at max_iterations (0 expected)
//   tets
//
// From the repository root (a Release build):
//
//   build/bench/bench_precond --benchmark_repetitions=5 --benchmark_report_aggregates_only=true \
//       --benchmark_out=precond.json --benchmark_out_format=json
//   build/bench/bench_precond --large --benchmark_filter=tets_103680 --benchmark_repetitions=3
//   build/bench/bench_precond --benchmark_filter=opencl_float --benchmark_repetitions=5   (OpenCL only)
//
// Results: docs/performance.md, "Preconditioners (issue 29)".
#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>

#include <benchmark/benchmark.h>

#include <chrono>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

namespace {

using namespace corofem;

/// The scene in the source tree it was built from, or under the working directory (a binary carried
/// to another machine and run from the project's root there).
std::string scenePath() {
  const std::string built = std::string(COROFEM_SOURCE_DIR) + "/bench/scenes/vega_beam.json";
  return std::ifstream(built) ? built : std::string("bench/scenes/vega_beam.json");
}
constexpr int kWarmupSteps = 3;

void precondStep(benchmark::State& state, const std::string& backend, const std::string& preconditioner,
                 const std::string& cells, const std::string& grab) {
  // Open-ended in steps: the benchmark decides how many it takes. No probes (no output is written).
  std::vector<std::string> set = {"solver.preconditioner=" + preconditioner, "bodies.0.mesh.box.cells=" + cells,
                                  "analysis.steps=1000000", "output.probes=[]"};
  if (const std::size_t at = backend.find("_float"); at != std::string::npos) {  // "opencl_float", "vulkan_float"
    set.push_back("backend=" + backend.substr(0, at));
    set.push_back("solver.precision=float");
  }
  auto scene = loadScene(scenePath(), set);
  if (!scene) {
    state.SkipWithError(scene.message().c_str());
    return;
  }
  auto sim = Simulation::create(scene.value());
  if (!sim) {
    state.SkipWithError(sim.message().c_str());
    return;
  }
  using Clock = std::chrono::steady_clock;
  double firstStepMs = 0;
  for (int i = 0; i < kWarmupSteps; ++i) {
    const auto t0 = Clock::now();
    Status st = sim->step();
    if (i == 0) firstStepMs = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    if (!st) {
      state.SkipWithError(st.message().c_str());
      return;
    }
  }
  int heldBy = 0;
  if (!grab.empty()) {
    const TetMesh& mesh = sim->restMesh(0);
    HandleDesc tip;
    for (std::size_t n = 0; n < mesh.nodeCount(); ++n)
      if (mesh.nodes[3 * n] > 1.0 - 1e-9) tip.nodes.push_back(static_cast<std::uint32_t>(n));
    Result<int> handle = sim->addHandle(tip);
    if (!handle) {
      state.SkipWithError(handle.message().c_str());
      return;
    }
    std::vector<double> x;
    sim->readPositions(0, x);
    double target[3] = {0, 0, 0};
    for (std::uint32_t n : tip.nodes)
      for (int a = 0; a < 3; ++a) target[a] += x[3 * n + static_cast<std::size_t>(a)] / static_cast<double>(tip.nodes.size());
    target[2] += 0.02;
    sim->moveHandle(handle.value(), target);
    heldBy = handle.value();
    const auto t0 = Clock::now();
    const Status st = sim->step();
    state.counters["grab_step_ms"] = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    if (!st) {
      state.SkipWithError(st.message().c_str());
      return;
    }
  }
  double ms = 0, pcg = 0, unconverged = 0;
  for (auto _ : state) {
    StepReport r;
    const auto t0 = Clock::now();
    Status st = sim->step(&r);
    ms += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    if (!st) {
      state.SkipWithError(st.message().c_str());
      return;
    }
    pcg += r.linearIterations;
    unconverged += r.converged ? 0 : 1;
  }
  if (heldBy != 0) {
    sim->removeHandle(heldBy);
    const auto t0 = Clock::now();
    const Status st = sim->step();
    state.counters["release_step_ms"] = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    if (!st) state.SkipWithError(st.message().c_str());
  }
  const double steps = static_cast<double>(state.iterations());
  state.counters["ms/step"] = ms / steps;
  state.counters["pcg/step"] = pcg / steps;
  state.counters["first_step_ms"] = firstStepMs;
  state.counters["unconverged"] = unconverged;
  state.counters["tets"] = static_cast<double>(sim->restMesh(0).tetCount());
}

void registerAll(bool large) {
  for (const char* b : {"reference", "opencl_float", "vulkan_float"}) {
    const std::string backend = b;
    // "warped_cholesky" runs on the reference and OpenCL backends (Vulkan refuses it).
    std::vector<std::string> held = {"amg"};
    if (backend != "vulkan_float") held.push_back("warped_cholesky");
    std::vector<std::string> kinds = {"diagonal", "block_diagonal"};
    kinds.insert(kinds.end(), held.begin(), held.end());
    for (const std::string& p : kinds)
      benchmark::RegisterBenchmark(("precondStep/" + backend + "/" + p + "/tets_12960").c_str(), precondStep, backend,
                                   p, std::string("[60,6,6]"), std::string())
          ->Iterations(30)
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime();
    for (const std::string& p : held)
      benchmark::RegisterBenchmark(("precondGrab/" + backend + "/" + p + "/tets_12960").c_str(), precondStep, backend,
                                   p, std::string("[60,6,6]"), std::string("grab"))
          ->Iterations(30)
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime();
    if (large) {
      held.insert(held.begin(), "diagonal");
      for (const std::string& p : held)
        benchmark::RegisterBenchmark(("precondStep/" + backend + "/" + p + "/tets_103680").c_str(), precondStep,
                                     backend, p, std::string("[120,12,12]"), std::string())
            ->Iterations(10)
            ->Unit(benchmark::kMillisecond)
            ->UseRealTime();
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  // --large is ours: taken out before Google Benchmark reads the rest.
  bool large = false;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (i > 0 && std::strcmp(argv[i], "--large") == 0) large = true;
    else args.push_back(argv[i]);
  }
  int n = static_cast<int>(args.size());
  args.push_back(nullptr);
  benchmark::Initialize(&n, args.data());
  if (benchmark::ReportUnrecognizedArguments(n, args.data())) return 1;
  registerAll(large);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
