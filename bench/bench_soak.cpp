// The soak of issue 25 (tests/control/soak.hpp): an application drags SOFA's liver and the Fig. 8
// beam by a handle with random, abrupt motions at 90 Hz (and 60 Hz), letting go and grabbing again
// (a hard handle and a spring handle in turns),
// for a long simulated time; counted: failed steps and non-finite positions, per integrator.
// tests/control/test_soak.cpp runs a short form in CI with the library's defaults.
//
//   --soak_seconds=S      simulated seconds per run (default 60; the full soak: 3600)
//   --soak_backend=NAME   "reference" (default) or "opencl"
//
// Counters per run: steps, failed_steps, non_finite, largest_move_m (largest_spring_move_m while a
// spring handle held the body), and the wall time per step.
// Runs: <body>/<integrator>/<Hz> for body liver and beam, integrator default (the library's),
// newmark (gamma 1/2, beta 1/4: the paper's), newmark_dissipative (gamma 0.6, beta 0.3025) and
// backward_euler.
#include "control/soak.hpp"

#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <string>
#include <vector>

namespace {

using namespace corofem;
using namespace corofem::test;

double soakSeconds = 60.0;
BackendKind soakBackend = BackendKind::Reference;

const char* kIntegrators[] = {"default", "newmark", "newmark_dissipative", "backward_euler"};

void BM_Soak(benchmark::State& state, std::string body, std::string integrator, double hz) {
  Scene scene = soakScene(body);
  scene.backend.kind = soakBackend;
  DynamicDesc& d = scene.analysis.dynamics;
  if (integrator == "newmark") {
    d.integrator = Integrator::Newmark;
    d.newmarkGamma = 0.5;
    d.newmarkBeta = 0.25;
  } else if (integrator == "newmark_dissipative") {
    d.integrator = Integrator::Newmark;
    d.newmarkGamma = 0.6;
    d.newmarkBeta = 0.3025;
  } else if (integrator == "backward_euler") {
    d.integrator = Integrator::BackwardEuler;
  }
  const SoakGrip grip = soakGrip(body);
  SoakResult r;
  double wall = 0.0;
  for (auto _ : state) {
    Result<Simulation> sim = Simulation::create(scene);
    if (!sim) {
      state.SkipWithError(sim.message().c_str());
      return;
    }
    const auto t0 = std::chrono::steady_clock::now();
    r = soak(sim.value(), soakSeconds, hz, grip.point, grip.grab, grip.reach, 12345, grip.spring);
    wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  state.counters["steps"] = static_cast<double>(r.steps);
  state.counters["failed_steps"] = static_cast<double>(r.failed);
  state.counters["non_finite"] = static_cast<double>(r.nonFinite);
  state.counters["largest_move_m"] = r.largestMove;
  state.counters["largest_spring_move_m"] = r.largestSpringMove;
  state.counters["ms_per_step"] = r.steps ? 1e3 * wall / static_cast<double>(r.steps) : 0.0;
  if (!r.firstFailure.empty()) state.SetLabel(r.firstFailure.substr(0, 160));
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<char*> rest;
  for (int i = 0; i < argc; ++i) {
    if (std::strncmp(argv[i], "--soak_seconds=", 15) == 0) {
      soakSeconds = std::atof(argv[i] + 15);
    } else if (std::strncmp(argv[i], "--soak_backend=", 15) == 0) {
      const std::string b = argv[i] + 15;
      if (b != "reference" && b != "opencl") {
        std::cerr << "bench_soak: --soak_backend must be reference or opencl, got " << b << '\n';
        return 2;
      }
      soakBackend = b == "opencl" ? BackendKind::OpenCL : BackendKind::Reference;
    } else {
      rest.push_back(argv[i]);
    }
  }
  if (!(soakSeconds > 0.0)) {
    std::cerr << "bench_soak: --soak_seconds must be > 0\n";
    return 2;
  }
  for (const char* body : {"liver", "beam"})
    for (const char* integrator : kIntegrators)
      for (double hz : {90.0, 60.0})
        benchmark::RegisterBenchmark((std::string("BM_Soak/") + body + "/" + integrator + "/" +
                                      std::to_string(static_cast<int>(hz)) + "Hz").c_str(),
                                     BM_Soak, body, integrator, hz)
            ->Iterations(1)
            ->Unit(benchmark::kSecond);
  int n = static_cast<int>(rest.size());
  benchmark::Initialize(&n, rest.data());
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
