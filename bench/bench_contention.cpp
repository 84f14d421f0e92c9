// One body on an OpenCL CPU device (PoCL) while another process keeps a core busy, as inside a
// renderer whose own threads are busy (issue 24). The body: a 1.2 x 0.1 x 0.1 m cantilever of
// 72 x 6 x 6 cells x 5 tets = 12,960 elements (E = 1e6 Pa, nu = 0.3, rho = 1000), clamped at x = 0
// under gravity; backward Euler, h = 1/60 s, PCG to 1e-6 with the library's default preconditioner
// ("auto": "amg" for this body) unless --preconditioner names one, float, on the OpenCL backend with
// its default tuning. Counters: the median and the mean wall time of a step (ms) over the timed
// steps, and PCG iterations per step.
//
//   --busy_cpu=N           fork a process that spins on CPU N (pinned) for the whole run; -1 (default): none
//   --preconditioner=NAME  auto (default), diagonal, block_diagonal (the measurements before "auto"), amg
//   --team_pcg=N           OpenCLTuning::teamPcg (1: always a team for the lone body, 0: never; default
//                          -1: the team or one work-group, whichever measures faster)
//   --group_small=N        OpenCLTuning::groupPcgSmallElements (100000 with --team_pcg=0: one work-group
//                          on one core)
//
// bench/contention.sh runs it in turns: default and PoCL on one thread (POCL_MAX_PTHREAD_COUNT=1,
// which must be set before the process starts), each with and without the busy process, and says
// whether the default with a busy core is no slower than PoCL on one thread with it.
#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>

#include "bench_scenes.hpp"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <string>
#include <vector>

#ifdef __linux__
#include <sched.h>
#include <sys/wait.h>
#include <unistd.h>
#endif

namespace {

using namespace corofem;

int busyCpu = -1;
PreconditionerKind preconditioner = PreconditionerKind::Auto;
int teamPcg = -1;  ///< OpenCLTuning::teamPcg of the run (--team_pcg)
std::size_t groupSmall = 0;  ///< OpenCLTuning::groupPcgSmallElements of the run (--group_small)

Scene beamScene() {
  const BodyDesc body = bench::clampedBox("beam", {1.2, 0.1, 0.1}, {72, 6, 6}, 5, 1e6, 0.3, 1000);
  Scene s;
  s.name = "contention";
  s.bodies.push_back(body);
  s.analysis.kind = AnalysisDesc::Kind::Dynamic;
  s.analysis.dynamics.integrator = Integrator::BackwardEuler;
  s.analysis.dynamics.timeStep = 1.0 / 60.0;
  s.analysis.dynamics.steps = 1 << 30;
  s.solver.precision = Precision::Float;
  s.solver.tolerance = 1e-6;
  s.solver.preconditioner = preconditioner;
  s.backend.kind = BackendKind::OpenCL;
  return s;
}

/// A process spinning on one CPU until killed.
class BusyProcess {
 public:
  explicit BusyProcess(int cpu) {
#ifdef __linux__
    if (cpu < 0) return;
    pid_ = fork();
    if (pid_ == 0) {
      cpu_set_t set;
      CPU_ZERO(&set);
      CPU_SET(cpu, &set);
      if (sched_setaffinity(0, sizeof(set), &set) != 0) _exit(1);
      volatile unsigned long long spin = 0;
      for (;;) spin = spin + 1;
    }
#else
    (void)cpu;
#endif
  }
  ~BusyProcess() {
#ifdef __linux__
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
#endif
  }
  bool running() const { return pid_ > 0; }

 private:
  int pid_ = -1;
};

void BM_BeamStep(benchmark::State& state) {
  SimulationOptions options;
  options.opencl.teamPcg = teamPcg;
  options.opencl.groupPcgSmallElements = groupSmall;
  Result<Simulation> sim = Simulation::create(beamScene(), options);
  if (!sim) {
    state.SkipWithError(sim.message().c_str());
    return;
  }
  BusyProcess busy(busyCpu);
  if (busyCpu >= 0 && !busy.running()) {
    state.SkipWithError("could not start the busy process");
    return;
  }
  for (int k = 0; k < 2; ++k)  // warm-up: first launches, lazy set-up, the busy process settling
    if (!sim->step()) {
      state.SkipWithError("warm-up step failed");
      return;
    }
  std::vector<double> ms;
  long long pcg = 0;
  for (auto _ : state) {
    StepReport r;
    const auto t0 = std::chrono::steady_clock::now();
    const Status st = sim->step(&r);
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    if (!st) {
      state.SkipWithError(st.message().c_str());
      return;
    }
    pcg += r.linearIterations;
  }
  std::vector<double> sorted = ms;
  std::sort(sorted.begin(), sorted.end());
  const std::size_t n = sorted.size();
  double mean = 0;
  for (double v : ms) mean += v / static_cast<double>(n);
  state.counters["median_ms_per_step"] = n % 2 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
  state.counters["mean_ms_per_step"] = mean;
  state.counters["pcg_per_step"] = static_cast<double>(pcg) / static_cast<double>(n);
  state.counters["busy_cpu"] = busyCpu;
  state.SetLabel(sim->deviceName());
}
BENCHMARK(BM_BeamStep)->Iterations(20)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

int main(int argc, char** argv) {
  std::vector<char*> rest;
  for (int i = 0; i < argc; ++i) {
    if (std::strncmp(argv[i], "--busy_cpu=", 11) == 0) {
      busyCpu = std::atoi(argv[i] + 11);
    } else if (std::strncmp(argv[i], "--team_pcg=", 11) == 0) {
      teamPcg = std::atoi(argv[i] + 11);
    } else if (std::strncmp(argv[i], "--group_small=", 14) == 0) {
      groupSmall = std::strtoul(argv[i] + 14, nullptr, 10);
    } else if (std::strncmp(argv[i], "--preconditioner=", 17) == 0) {
      const std::string name = argv[i] + 17;
      bool known = false;
      for (PreconditionerKind k : {PreconditionerKind::Auto, PreconditionerKind::Diagonal,
                                   PreconditionerKind::BlockDiagonal, PreconditionerKind::Amg})
        if (name == toString(k)) {
          preconditioner = k;
          known = true;
        }
      if (!known) {
        std::cerr << "bench_contention: --preconditioner must be auto, diagonal, block_diagonal or amg, got " << name
                  << '\n';
        return 2;
      }
    } else {
      rest.push_back(argv[i]);
    }
  }
  int count = static_cast<int>(rest.size());
  benchmark::Initialize(&count, rest.data());
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
