// Many bodies, one set of launches (issue 5): 100 bodies of 2,000 elements each, stepped
//   batched    in one Simulation whose bodies share the device's buffers and launches
//              (one device call per operation for the whole set, solve/driver.hpp; the default);
//   separate   as 100 separate Simulations of one body each (what an application without batching
//              does), stepped one after the other;
//   unbatched  in one Simulation with "backend": {"batch": false} (100 backends, stepped in turn).
// All on one OpenCL device (default: the first GPU, else the first device, i.e. the PoCL CPU
// device here; COROFEM_BENCH_DEVICE names another), float precision, dynamic (Newmark, one
// Newton iteration, the paper's linearised step), PCG to 1e-4 relative, diagonal preconditioner.
// The bodies are cantilevers (box mesh 20 x 4 x 5 cells, 5 tets per cell = 2,000 elements, 630
// nodes), clamped at x = 0 under gravity, with 100 different materials (Young's modulus 2e5 to
// 2e6 Pa, Poisson 0.25 to 0.45, density 800 to 1200, every third with Rayleigh damping), so their
// PCG iteration counts differ: a converged body stops costing work in the batch.
//
// A second variant gives every body the same material (same PCG counts), which separates the
// saving of shared launches from the cost of iterating until the slowest body has converged. A
// third gives the bodies different meshes (one material): lengths of 8 to 44 cells (800 to 4,400
// elements), the largest first in the scene, so that nothing packs and pcg_iterate_group's
// work-groups take bodies of very different costs.
//
// BM_HundredBodySurfaces: the same 100 bodies (one material), batched, each driving a render
// surface (a UV sphere of 2,002 vertices inside the body, written as OBJ to a temporary folder):
// a frame is one step plus every body's surface brought up to date on the device (updateSurface,
// which waits), as a renderer does before drawing. Counters: the step and the surfaces' time per
// frame and the surfaces' share.
//
// One benchmark iteration = kStepsPerSample steps of the whole set with each of the three, taken
// alternately so that all three go through the same physical states; the counters are set-steps
// per second (one set-step = every body advanced one step) and the ratios, and per batched
// set-step and call (set_positions, internal_forces, solve, ...): the device calls ("rounds"), their
// device time and the host's time before them (the drivers' own arithmetic, while the device idles). Each configuration is
// created and warmed up (one step) once, outside the timing.
//
//   ./build/bench/bench_batch --benchmark_repetitions=5 --benchmark_report_aggregates_only=true \
//       --benchmark_out=bench_batch.json --benchmark_out_format=json
#include <corofem/corofem.hpp>

#include "embed/embed_test_util.hpp"

#include "bench_scenes.hpp"

#include <benchmark/benchmark.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

namespace {

using namespace corofem;
using Clock = std::chrono::steady_clock;

/// Bodies in the set (COROFEM_BENCH_BODIES overrides the 100 of the issue, for exploring scaling).
const int kBodies = [] {
  const char* n = std::getenv("COROFEM_BENCH_BODIES");
  return n && *n ? std::max(2, std::atoi(n)) : 100;
}();
constexpr int kStepsPerSample = 3;

/// The sets: 100 materials (the issue's), one material, one material and 100 meshes.
enum Set { kOneMaterial = 0, kMaterials = 1, kMeshes = 2 };

/// Body i of the set; kOneMaterial gives every body the same material (body 0's stiffness at the
/// middle of the range), which isolates the launch sharing from the spread of PCG counts.
BodyDesc body(int i, int set) {
  const bool varied = set == kMaterials;
  const std::array<int, 3> cells{set == kMeshes ? 8 + (kBodies - 1 - i) * 36 / (kBodies - 1) : 20, 4, 5};  // the largest first
  const double f = varied ? static_cast<double>(i) / (kBodies - 1) : 0.5;  // 0 .. 1 over the bodies
  BodyDesc b = bench::clampedBox("body" + std::to_string(i), {1.0, 0.2, 0.25}, cells, 5,
                                 2e5 * std::pow(10.0, f),  // 2e5 .. 2e6 Pa
                                 varied ? 0.25 + 0.2 * static_cast<double>((i * 37) % kBodies) / kBodies : 0.35,
                                 varied ? 800 + 400 * static_cast<double>((i * 61) % kBodies) / kBodies : 1000);
  b.mesh.translate = {0.0, 0.0, 0.5 * i};
  b.material.rayleighMass = varied && i % 3 == 0 ? 2.0 : 0.0;
  return b;
}

Scene scene(const std::vector<BodyDesc>& bodies, bool batch) {
  Scene s;
  s.name = "bench_batch";
  s.bodies = bodies;
  s.analysis.kind = AnalysisDesc::Kind::Dynamic;
  s.analysis.dynamics.timeStep = 1.0 / 60.0;
  s.analysis.dynamics.steps = 1000000;  // never finished within a run
  s.analysis.dynamics.newtonIterations = 1;
  s.solver.precision = Precision::Float;
  s.solver.tolerance = 1e-4;
  s.solver.maxIterations = 200;
  s.solver.preconditioner = PreconditionerKind::Diagonal;
  s.backend.kind = BackendKind::OpenCL;
  if (const char* d = std::getenv("COROFEM_BENCH_DEVICE"); d && *d) s.backend.device = d;
  s.backend.batch = batch;
  return s;
}

Simulation make(const Scene& s) {
  Result<Simulation> sim = Simulation::create(s);
  if (!sim) {
    std::cerr << "bench_batch: " << sim.message() << std::endl;
    std::exit(1);
  }
  Simulation out = std::move(sim.value());
  if (const Status st = out.step(); !st) {  // warm-up: first launches, lazy set-up
    std::cerr << "bench_batch: warm-up step failed: " << st.message() << std::endl;
    std::exit(1);
  }
  return out;
}

struct Setups {
  Simulation batched, unbatched;
  std::vector<Simulation> separate;
};

Setups& setups(int set) {
  static std::unique_ptr<Setups> made[3];
  std::unique_ptr<Setups>& s = made[set];
  if (!s) {
    std::vector<BodyDesc> bodies;
    for (int i = 0; i < kBodies; ++i) bodies.push_back(body(i, set));
    Simulation batched = make(scene(bodies, true));
    Simulation unbatched = make(scene(bodies, false));
    std::vector<Simulation> separate;
    for (const BodyDesc& b : bodies) separate.push_back(make(scene({b}, true)));
    s.reset(new Setups{std::move(batched), std::move(unbatched), std::move(separate)});
    const nlohmann::json sched = nlohmann::json::parse(s->batched.schedulerReport());
    static const char* const names[] = {"one material", "100 materials", "one material, 100 meshes"};
    std::cerr << "bench_batch: " << kBodies << " bodies, the first of " << s->batched.restMesh(0).tetCount()
              << " elements (" << names[set] << ") on " << s->batched.deviceName() << "; batches: "
              << sched["batches"].size() << " (" << (sched["batches"].empty() ? 0 : sched["batches"][0]["bodies"].size())
              << " bodies in the first)" << (sched["unbatched"].empty() ? "" : "; unbatched: " + sched["unbatched"].dump())
              << std::endl;
    if (sched["batches"].size() != 1) std::exit(1);
  }
  return *s;
}

double secondsOf(const std::function<void()>& fn) {
  const auto t0 = Clock::now();
  fn();
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

int stepOrDie(Simulation& sim, long long& pcg) {
  StepReport r;
  const Status st = sim.step(&r);
  if (!st) {
    std::cerr << "bench_batch: step failed: " << st.message() << std::endl;
    std::exit(1);
  }
  pcg += r.linearIterations;
  return r.linearIterations;
}

void BM_HundredBodies(benchmark::State& state) {
  Setups& s = setups(static_cast<int>(state.range(0)));
  const auto deviceSeconds = [&] {
    return nlohmann::json::parse(s.batched.schedulerReport())["batches"][0]["device_seconds"].get<double>();
  };
  // Per call of the bodies inside the batched steps: calls, device seconds, and the host's time
  // before them (the drivers' arithmetic), summed from the scheduler's report.
  const auto byCall = [&] {
    return nlohmann::json::parse(s.batched.schedulerReport())["batches"][0]["rounds_by_call"];
  };
  const double device0 = deviceSeconds();
  const nlohmann::json calls0 = byCall();
  double tBatched = 0, tSeparate = 0, tUnbatched = 0;
  long long pcgBatched = 0, pcgSeparate = 0, pcgUnbatched = 0, pcgSlowest = 0;
  for (auto _ : state) {
    for (int k = 0; k < kStepsPerSample; ++k) {
      tBatched += secondsOf([&] { stepOrDie(s.batched, pcgBatched); });
      int slowest = 0;
      tSeparate += secondsOf([&] {
        for (Simulation& sim : s.separate) slowest = std::max(slowest, stepOrDie(sim, pcgSeparate));
      });
      pcgSlowest += slowest;
      tUnbatched += secondsOf([&] { stepOrDie(s.unbatched, pcgUnbatched); });
    }
  }
  const double steps = static_cast<double>(state.iterations()) * kStepsPerSample;
  state.counters["batched_set_steps_per_s"] = steps / tBatched;
  state.counters["separate_set_steps_per_s"] = steps / tSeparate;
  state.counters["unbatched_scene_set_steps_per_s"] = steps / tUnbatched;
  state.counters["ratio_batched_vs_separate"] = tSeparate / tBatched;
  state.counters["ratio_batched_vs_unbatched_scene"] = tUnbatched / tBatched;
  // PCG iterations per body-step of each (the same work, or the runs drifted apart).
  state.counters["pcg_per_body_step_batched"] = pcgBatched / (steps * kBodies);
  state.counters["pcg_per_body_step_separate"] = pcgSeparate / (steps * kBodies);
  state.counters["pcg_per_body_step_unbatched"] = pcgUnbatched / (steps * kBodies);
  // The batch's PCG runs until its slowest body converges (converged bodies' work-groups return
  // at once, but the launches go on): the slowest body's count per step.
  state.counters["pcg_slowest_body_step"] = pcgSlowest / steps;
  state.counters["body_steps_per_s_batched"] = steps * kBodies / tBatched;
  // Share of the batched step spent in the device's calls (the rest: the drivers' host work).
  state.counters["batched_device_fraction"] = (deviceSeconds() - device0) / tBatched;
  // Per set-step of the batched runs, by call: rounds, device ms and wait ms before them.
  const nlohmann::json calls1 = byCall();
  double waitSeconds = 0.0;
  for (const auto& c : calls1.items()) {
    const auto before = [&](const char* key) {
      return calls0.contains(c.key()) ? calls0[c.key()][key].get<double>() : 0.0;
    };
    const double rounds = c.value()["rounds"].get<double>() - before("rounds");
    const double device = c.value()["device_seconds"].get<double>() - before("device_seconds");
    const double wait = c.value()["wait_seconds"].get<double>() - before("wait_seconds");
    waitSeconds += wait;
    state.counters["batched_" + c.key() + "_rounds"] = rounds / steps;
    state.counters["batched_" + c.key() + "_device_ms"] = 1e3 * device / steps;
    state.counters["batched_" + c.key() + "_wait_ms"] = 1e3 * wait / steps;
  }
  state.counters["batched_wait_fraction"] = waitSeconds / tBatched;
}
// Arg: 1 = varied materials (the benchmark), 0 = one material for all, 2 = one material
// and 100 meshes of 800 to 4,400 elements.
BENCHMARK(BM_HundredBodies)->ArgName("varied")->Arg(1)->Arg(0)->Arg(2)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

void BM_HundredBodySurfaces(benchmark::State& state) {
  static std::unique_ptr<Simulation> sim;
  if (!sim) {
    const auto dir = std::filesystem::temp_directory_path() / "corofem_bench_batch_surfaces";
    std::filesystem::create_directories(dir);
    // Inside every body: the body box is [0, 1] x [0, 0.2] x [0, 0.25] before its translation.
    const std::string obj = (dir / "sphere.obj").string();
    if (!writeSurfaceMesh(obj, test::uvSphere({0.5, 0.1, 0.125}, 0.09, 40, 50))) std::exit(1);
    std::vector<BodyDesc> bodies;
    for (int i = 0; i < kBodies; ++i) {
      bodies.push_back(body(i, kOneMaterial));
      bodies.back().surface = obj;
    }
    sim = std::make_unique<Simulation>(make(scene(bodies, true)));
    const nlohmann::json sched = nlohmann::json::parse(sim->schedulerReport());
    if (sched["batches"].size() != 1 || sched["batches"][0]["bodies"].size() != static_cast<std::size_t>(kBodies)) {
      std::cerr << "bench_batch: the bodies with surfaces did not form one batch: " << sched["batches"].dump() << std::endl;
      std::exit(1);
    }
  }
  double tStep = 0, tSurfaces = 0;
  long long pcg = 0;
  std::size_t vertices = 0;
  for (auto _ : state) {
    for (int k = 0; k < kStepsPerSample; ++k) {
      tStep += secondsOf([&] { stepOrDie(*sim, pcg); });
      tSurfaces += secondsOf([&] {
        // Enqueue every update (surfaceBuffer), then wait once: the batch's bodies share one
        // in-order queue, so the last body's updateSurface waits for all of them.
        for (int b = 0; b < kBodies; ++b)
          if (!sim->surfaceBuffer(b)) std::exit(1);
        if (!sim->updateSurface(kBodies - 1)) std::exit(1);
      });
    }
  }
  for (int b = 0; b < kBodies; ++b) vertices += sim->restSurface(b)->vertexCount();
  const double frames = static_cast<double>(state.iterations()) * kStepsPerSample;
  state.counters["step_ms"] = 1e3 * tStep / frames;
  state.counters["surfaces_ms"] = 1e3 * tSurfaces / frames;
  state.counters["surfaces_share"] = tSurfaces / (tStep + tSurfaces);
  state.counters["surface_vertices"] = static_cast<double>(vertices);
  state.counters["surface_vertices_per_s"] = static_cast<double>(vertices) * frames / tSurfaces;
  state.counters["on_device"] = sim->surfaceBuffer(0) ? 1 : 0;
}
BENCHMARK(BM_HundredBodySurfaces)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
