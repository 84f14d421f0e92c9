// One dynamic step of the same scene on every backend, in one run, so that their ratio is a
// measured number: a co-rotational block (6 tets per cell) clamped at one end, under gravity, implicit Newmark, one
// Newton iteration (dissipative Newmark, see below) and exactly 20 PCG iterations (tolerance 1e-30 with a cap of 20, so every backend
// does the same work), diagonal preconditioner. Sizes from 1k to 100k elements.
//
// The Vulkan rows run on every Vulkan device's default (the first: a GPU where there is one, else
// lavapipe; COROFEM_DEVICE does not apply to an explicit backend).
//
//   ./build/bench/bench_backends --benchmark_repetitions=5 --benchmark_report_aggregates_only=true \
//       --benchmark_format=json > bench_backends.json
#include <corofem/corofem.hpp>

#include "bench_scenes.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <optional>
#include <string>
#include <vector>

namespace {

using namespace corofem;

struct Size {
  const char* label;
  std::array<int, 3> cells;  // 6 tets per cell
};

// Elements: 6 * nx * ny * nz. Stubby blocks (2:1:1), not slender beams: 20 PCG iterations must
// leave an accurate step for thousands of timed steps, and a slender soft beam whips and needs more.
const Size kSizes[] = {
    {"1k", {8, 5, 4}},       // 960
    {"10k", {20, 9, 9}},     // 9,720
    {"100k", {40, 20, 20}},  // 96,000
};

Scene beamScene(const Size& size, BackendKind backend, Precision precision) {
  Scene s;
  s.name = "bench_beam";
  // A 0.4 m x 0.2 m x 0.2 m block at every resolution, soft rubber.
  BodyDesc b = bench::clampedBox("beam", {0.4, 0.2, 0.2}, size.cells, 6, 1e5, 0.3, 1000);
  b.material.rayleighMass = 5.0;  // damped, so thousands of timed steps settle instead of swinging
  s.bodies.push_back(b);
  bench::twentyIterationSteps(s, 1000000, precision);
  s.backend.kind = backend;
  return s;
}

// Steps timed per simulation before a fresh one is made (untimed). With 20 PCG iterations the
// solves are inexact (on the 100k block the first steps' true residual is 0.6-0.8 of |b|), and a
// swinging body gains energy until the energy guard stops it: measured after ~100-120 steps on the
// 10k block, and after 26 steps on the 100k block in float (the same before and after the
// single-reduction PCG: its true residuals agree with the textbook PCG's to 5 digits). The first
// 20 steps of the motion are where every backend does the same, comparable work.
constexpr int kStepsPerSimulation = 20;

void stepBenchmark(benchmark::State& state, Size size, BackendKind backend, Precision precision,
                   SimulationOptions options) {
  const Scene scene = beamScene(size, backend, precision);
  std::optional<Simulation> sim;
  StepReport r;
  auto fresh = [&]() -> bool {
    auto created = Simulation::create(scene, options);
    if (!created) {
      state.SkipWithError(created.message().c_str());
      return false;
    }
    sim.emplace(std::move(created.value()));
    for (int i = 0; i < 2; ++i) sim->step(&r);  // warm-up: program build or cache load, first allocation
    return true;
  };
  if (!fresh()) return;
  for (auto _ : state) {
    if (sim->stepsTaken() >= kStepsPerSimulation) {
      state.PauseTiming();
      const bool ok = fresh();
      state.ResumeTiming();
      if (!ok) return;
    }
    Status st = sim->step(&r);
    if (!st) {
      // A dynamic failure here is the scene's, not the backend's; report it rather than time it.
      state.SkipWithError(st.message().c_str());
      return;
    }
  }
  const double elements = static_cast<double>(sim->restMesh(0).tetCount());
  state.counters["elements"] = elements;
  state.counters["elements_per_second"] = benchmark::Counter(elements, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["pcg_iterations"] = r.linearIterations;
  state.SetLabel(sim->backendName() + " on " + sim->deviceName());
}

int registerAll() {
  for (const Size& size : kSizes) {
    benchmark::RegisterBenchmark((std::string("step/reference/") + size.label).c_str(), stepBenchmark, size,
                                 BackendKind::Reference, Precision::Double, SimulationOptions{})
        ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(0.5);
#ifdef COROFEM_WITH_OPENCL
    benchmark::RegisterBenchmark((std::string("step/opencl_float/") + size.label).c_str(), stepBenchmark, size,
                                 BackendKind::OpenCL, Precision::Float, SimulationOptions{})
        ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(0.5);
    benchmark::RegisterBenchmark((std::string("step/opencl_double/") + size.label).c_str(), stepBenchmark, size,
                                 BackendKind::OpenCL, Precision::Double, SimulationOptions{})
        ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(0.5);
#endif
#ifdef COROFEM_WITH_VULKAN
    // The Vulkan backend's default PCG path for the device, and the path of a dispatch per phase
    // (VulkanTuning::groupPcgNodes = -1), which a GPU takes for every body and a CPU device for
    // bodies of more than 2,048 nodes.
    SimulationOptions phases;
    phases.vulkan.groupPcgNodes = -1;
    for (Precision p : {Precision::Float, Precision::Double}) {
      const std::string name = p == Precision::Float ? "vulkan_float" : "vulkan_double";
      benchmark::RegisterBenchmark(("step/" + name + "/" + size.label).c_str(), stepBenchmark, size,
                                   BackendKind::Vulkan, p, SimulationOptions{})
          ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(0.5);
      benchmark::RegisterBenchmark(("step/" + name + "_phases/" + size.label).c_str(), stepBenchmark, size,
                                   BackendKind::Vulkan, p, phases)
          ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(0.5);
    }
#endif
  }
  return 0;
}

const int kRegistered = registerAll();

}  // namespace

BENCHMARK_MAIN();
