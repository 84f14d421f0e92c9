// Vulkan backend benchmarks on every Vulkan device (lavapipe here; a GPU where there is one), on
// generated boxes of ~1k, 10k, 100k and 1M elements (6 tets per cell), float:
//
//   step/<device>/<size>        a whole dynamic step as an application runs it (Simulation::step:
//                               one Newton iteration, exactly 20 PCG iterations, diagonal
//                               preconditioner, transfers included), with the host's CPU time per
//                               step (the calling thread's: what the step costs the application's
//                               frame besides waiting) and the submissions and stalled host waits
//                               per step (the backend's device counters).
//   pcg_iterations/<device>/<size>  20 PCG iterations on the device and one read of the scalars
//                               (the host round trip the driver makes every `checkEvery`), with the
//                               bytes an iteration must move at least (product and vector updates)
//                               over the copy bandwidth measured in the same run: the fraction of
//                               the memory's rate the iterations reach.
//   dispatch/<device>/<barrier> the launch yardstick: the time of one small dispatch (64
//                               work-groups) followed by the library's barrier between passes
//                               (full), a compute-only barrier (compute) or none, as a 200th of a
//                               chain of 200 recorded, submitted and waited for at once
//                               (us_per_dispatch; the benchmark's time is the chain's), and the
//                               host's time recording one (record_us_per_dispatch: what a
//                               command buffer recorded once and replayed would spare).
//   roundtrip/<device>          one wait for the device as the library makes one to read a
//                               result: a small dispatch and a 64-byte copy to the host,
//                               recorded, submitted and waited for (what each blocking wait of
//                               a step costs beside its work).
//   copy/<device>               the yardstick: a compute shader's copy between two device buffers
//                               (64 MiB on CPU devices, 512 MiB on GPUs; bench/kernels/copy.comp,
//                               four copies a submission), bytes read + written per second. Not
//                               vkCmdCopyBuffer: on an H200 that reached 0.75-0.78 TB/s, a sixth of
//                               the memory's rate (most likely a copy engine's pace; not measured).
//
//   ./build/bench/bench_vulkan --benchmark_format=json [--benchmark_filter=-/1M]   (skip the 1M box)
//   --group_pcg_nodes=N   VulkanTuning::groupPcgNodes for every backend it makes (-1: a dispatch
//                         per phase for every body; the default, 0, runs the 1k box's iterations
//                         in one dispatch on a CPU device and every box per phase on a GPU)
//   --fused_pcg=N         VulkanTuning::fusedPcg for every backend it makes (1: two dispatches an
//                         iteration off the one-dispatch path, 0: four; the default, -1, two on a
//                         GPU and four on a CPU device)
//   --device_store=N      VulkanTuning::deviceStore for every backend it makes (1: the dynamics'
//                         vectors on the device, 0 (the default): on the host, -1: on a GPU only)
//
// lavapipe needs LP_NUM_THREADS=0 (its rasteriser threads are not used by compute) to behave.
#include "bench_scenes.hpp"

#include <benchmark/benchmark.h>

#ifdef COROFEM_WITH_VULKAN

#include <corofem/simulation.hpp>

#include "backends/vulkan/vk_runtime.hpp"
#include "common/test_problems.hpp"
#include "device/registry.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace corofem {
namespace {

/// The tuning every backend of the run gets (--group_pcg_nodes).
VulkanTuning& benchTuning() {
  static VulkanTuning t;
  return t;
}

struct BoxSize {
  const char* label;
  int nx, ny, nz;  ///< cells; 6 tets per cell
};
constexpr BoxSize kSizes[] = {{"1k", 10, 4, 4}, {"10k", 20, 9, 9}, {"100k", 40, 20, 21}, {"1M", 80, 45, 46}};

/// The copy's buffer size: 512 MiB on a GPU, 64 MiB on a CPU device, at most what one storage
/// buffer binding may span there (maxStorageBufferRange: Vulkan promises 128 MiB).
std::size_t copyBytes(std::size_t index) {
  const detail::vk::PhysicalDevice& d = detail::vk::Instance::shared()->devices()[index];
  const std::size_t wanted = (d.gpu ? std::size_t{512} : std::size_t{64}) << 20;
  return std::min<std::size_t>(wanted, d.limits.maxStorageBufferRange / 16 * 16);
}

/// The calling thread's CPU time (s): the host's own work, not the device's threads (lavapipe) nor
/// the time the thread sleeps waiting for the device.
double threadSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

/// glslc's SPIR-V of bench/kernels/copy.comp (bench/CMakeLists.txt).
const std::uint32_t kCopyShader[] =
#include "copy.inc"
    ;

/// What follows each dispatch of a chain (CopyRig::chain): the library's barrier between two
/// passes (all commands, any memory write before any access: vk::fullBarrier), a compute-to-compute
/// barrier on shader memory alone (vk::computeBarrier), or nothing (dispatches that may overlap).
enum class DispatchBarrier { Full, Compute, None };

/// Earlier compute shaders' writes made visible to later compute shaders alone (the library puts
/// vk::fullBarrier between its passes).
void computeBarrier(VkCommandBuffer cb) {
  VkMemoryBarrier m{};
  m.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
  m.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
  m.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT;
  vkCmdPipelineBarrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 1, &m, 0,
                       nullptr, 0, nullptr);
}

/// Two device buffers (64 MiB on CPU devices, 512 MiB on GPUs) on Vulkan device `index` and the
/// copy shader between them, made once: a GPU copies 512 MiB in a fraction of a millisecond, far
/// less than making a device and its buffers.
class CopyRig {
 public:
  explicit CopyRig(std::size_t index)
      : ctx_(detail::vk::Instance::shared(), index, false, 2, sizeof(std::uint32_t)), bytes_(copyBytes(index)),
        a_(ctx_, bytes_, false), b_(ctx_, bytes_, false),
        pipeline_(ctx_.pipeline(kCopyShader, sizeof(kCopyShader), "copy.comp")),
        host_(ctx_, 64, true), ab_(ctx_.descriptorSet({&a_, &b_})), ba_(ctx_.descriptorSet({&b_, &a_})) {
    once();  // warm-up
  }
  std::size_t bytes() const { return bytes_; }
  /// The time of one copy (s): four, a to b and back twice, with a barrier between each, in one
  /// submission that is waited for (the submission and the wait shared among the four).
  double once() {
    const std::uint32_t words = static_cast<std::uint32_t>(bytes_ / 16);
    return copies(std::min<std::uint32_t>(65535, (words + 255) / 256), words, 4, DispatchBarrier::Full);
  }
  /// The time of one small dispatch (s): `dispatches` copies of 64 work-groups (256 KiB each way,
  /// the size of a 10k-element body's node pass) one after another in one submission, each followed
  /// by `barrier`, the submission and its wait shared among them.
  double chain(int dispatches, DispatchBarrier barrier) { return copies(64, 64 * 256, dispatches, barrier); }
  /// The host's time recording the last chain or copy (s per dispatch, its barrier included).
  double recordTime() const { return record_; }
  /// One host round trip (s), as the library makes one to read a result: one small dispatch (64
  /// work-groups) and a copy of 64 bytes into host-visible memory, recorded, submitted and waited
  /// for.
  double roundTrip() {
    const auto t0 = std::chrono::steady_clock::now();
    VkCommandBuffer cb = ctx_.begin();
    recordCopies(cb, 64, 64 * 256, 1, DispatchBarrier::Full);
    VkBufferCopy region{0, 0, 64};
    vkCmdCopyBuffer(cb, b_.handle(), host_.handle(), 1, &region);
    detail::vk::hostReadBarrier(cb);
    ctx_.wait(ctx_.submit());
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }

 private:
  /// `dispatches` copies of `words` 16-byte words by `groups` work-groups, alternately a to b and b
  /// to a, each followed by `barrier`, recorded into cb.
  void recordCopies(VkCommandBuffer cb, std::uint32_t groups, std::uint32_t words, int dispatches,
                    DispatchBarrier barrier) const {
    vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_);
    vkCmdPushConstants(cb, ctx_.pipelineLayout(), VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(words), &words);
    for (int k = 0; k < dispatches; ++k) {
      VkDescriptorSet set = k % 2 == 0 ? ab_ : ba_;
      vkCmdBindDescriptorSets(cb, VK_PIPELINE_BIND_POINT_COMPUTE, ctx_.pipelineLayout(), 0, 1, &set, 0, nullptr);
      vkCmdDispatch(cb, groups, 1, 1);
      if (barrier == DispatchBarrier::Full) detail::vk::fullBarrier(cb);
      if (barrier == DispatchBarrier::Compute) computeBarrier(cb);
    }
  }

  /// recordCopies in one submission that is waited for: the time of one copy (s).
  double copies(std::uint32_t groups, std::uint32_t words, int dispatches, DispatchBarrier barrier) {
    const auto t0 = std::chrono::steady_clock::now();
    recordCopies(ctx_.begin(), groups, words, dispatches, barrier);
    record_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / dispatches;
    ctx_.wait(ctx_.submit());
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / dispatches;
  }

  detail::vk::Context ctx_;
  std::size_t bytes_;
  detail::vk::Buffer a_, b_;
  VkPipeline pipeline_;
  detail::vk::Buffer host_;  ///< a round trip's 64 bytes
  VkDescriptorSet ab_, ba_;
  double record_ = 0;
};

/// Bytes per second of the copy shader (read + write): the median of 9 copies, measured right after
/// the benchmark that reports it (the machine is shared: both measurements under the same load).
double copyBandwidth(std::size_t index) {
  CopyRig rig(index);
  std::vector<double> times;
  for (int i = 0; i < 9; ++i) times.push_back(rig.once());
  std::sort(times.begin(), times.end());
  return 2.0 * static_cast<double>(rig.bytes()) / times[times.size() / 2];
}

void copy(benchmark::State& state, std::size_t index) {
  CopyRig rig(index);
  for (auto _ : state) state.SetIterationTime(rig.once());
  state.SetBytesProcessed(static_cast<std::int64_t>(2 * rig.bytes()) * state.iterations());
}

/// The launch yardstick: the time of a small dispatch and its barrier, a 200th of a chain of 200 in
/// one submission (CopyRig::chain; recording, submission and wait included), the floor under a PCG
/// iteration of a few dispatches. The benchmark's time is the whole chain's (a time per dispatch as
/// the iteration time would make Google Benchmark run 200 times longer than its minimum time),
/// us_per_dispatch its 200th.
void dispatchChain(benchmark::State& state, std::size_t index, DispatchBarrier barrier) {
  constexpr int kDispatches = 200;
  CopyRig rig(index);
  rig.chain(kDispatches, barrier);  // warm-up
  double total = 0, recording = 0;
  for (auto _ : state) {
    const double t = kDispatches * rig.chain(kDispatches, barrier);
    state.SetIterationTime(t);
    total += t;
    recording += rig.recordTime();
  }
  state.counters["us_per_dispatch"] = benchmark::Counter(1e6 * total / kDispatches, benchmark::Counter::kAvgIterations);
  state.counters["record_us_per_dispatch"] = benchmark::Counter(1e6 * recording, benchmark::Counter::kAvgIterations);
}

/// The cost of one wait for the device: a round trip (CopyRig::roundTrip) as the iteration time.
/// What a step's blocking waits cost beside its dispatches.
void roundTrip(benchmark::State& state, std::size_t index) {
  CopyRig rig(index);
  rig.roundTrip();  // warm-up
  for (auto _ : state) state.SetIterationTime(rig.roundTrip());
}

/// The box clamped at x = 0, E = 1e5 Pa, nu = 0.4, 1000 kg/m^3, cells of 5 cm.
detail::Problem boxProblem(const BoxSize& size) {
  detail::Problem p = test::makeProblem(test::cellBox(size.nx, size.ny, size.nz, 0.05, 0.05, 0.05), 1e5, 0.4, 1000.0);
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
    if (p.mesh.nodes[3 * n] < 1e-9)
      for (int k = 0; k < 3; ++k) p.constrained[3 * n + k] = 1;
  return p;
}

/// Bytes a PCG iteration must move per element at least, in float (4-byte indices and reals; node
/// data amortised by nodes / elements): the element pass reads 4 corners, 10 geometry reals and the
/// 12 corner values and writes its 12-vector; the gather reads 4 entries and those 12 reals back;
/// per node the product reads mass and p and writes y, and the update reads and writes the PCG
/// vectors (x, r, u, p, s, w, M^-1: about 12 node vectors).
double iterationBytesPerElement(const detail::Problem& p) {
  const double r = 4.0, nodesPerElement = static_cast<double>(p.mesh.nodeCount()) / static_cast<double>(p.mesh.tetCount());
  return 16 + r * (10 + 12 + 12) + 16 + r * 12 + nodesPerElement * r * (9 + 3 * 12);
}

void pcgIterations(benchmark::State& state, std::size_t index, BoxSize size) {
  const detail::Problem p = boxProblem(size);
  SolverDesc s;
  s.precision = Precision::Float;
  s.preconditioner = PreconditionerKind::Diagonal;
  const auto entry = detail::findBackend("vulkan");
  std::unique_ptr<detail::Device> dev;
  try {
    detail::DeviceOptions o;
    o.vulkan = benchTuning();
    dev = entry->create({&p}, s, entry->resolve(std::to_string(index)), o);
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
    return;
  }
  const detail::BodySet one{0};
  const Eigen::VectorXd x = p.restPositions;
  dev->setPositions(one, {&x});
  Eigen::VectorXd b = test::randomVector(p.dofCount(), 7), x0 = Eigen::VectorXd::Zero(b.size()), out = x0;
  const std::vector<detail::SystemCoeffs> coeffs{{3600.0, 0.0, 1.0}};
  std::vector<detail::PcgScalars> scalars;
  const std::vector<char> running{1};
  auto begin = [&] { dev->pcgBegin(one, coeffs, {&b}, {&x0}, 1e-30, 1 << 30); };
  begin();
  for (auto _ : state) {
    dev->pcgIterate(20, running);
    dev->pcgTake(dev->pcgRead(), scalars);
    if (scalars[0].stop != detail::PcgStop::Running) {  // converged or broke down: start again, untimed
      state.PauseTiming();
      std::vector<detail::PcgScalars> residual;
      dev->pcgEnd({scalars[0].iterations}, {&out}, residual);
      begin();
      state.ResumeTiming();
    }
  }
  const double elements = static_cast<double>(p.mesh.tetCount()), iterations = 20.0 * static_cast<double>(state.iterations());
  const double bw = copyBandwidth(index);
  state.counters["elements"] = elements;
  state.counters["elements_per_s"] = benchmark::Counter(elements * iterations, benchmark::Counter::kIsRate);
  state.counters["bytes_per_element"] = iterationBytesPerElement(p);
  state.counters["copy_GBps"] = bw / 1e9;
  state.counters["bandwidth_fraction"] =
      benchmark::Counter(elements * iterations * iterationBytesPerElement(p) / bw, benchmark::Counter::kIsRate);
  state.SetLabel(dev->deviceName());
}

/// The box as a scene (one Newton iteration of dissipative Newmark, exactly 20 PCG iterations,
/// diagonal preconditioner, float) on Vulkan device `index`.
Scene boxScene(const BoxSize& size, std::size_t index) {
  Scene s;
  s.name = "bench_vulkan_box";
  BodyDesc b = bench::clampedBox("box", {0.05 * size.nx, 0.05 * size.ny, 0.05 * size.nz}, {size.nx, size.ny, size.nz},
                                 6, 1e5, 0.4, 1000);
  b.material.rayleighMass = 5.0;
  s.bodies.push_back(b);
  bench::twentyIterationSteps(s, 0, Precision::Float);
  s.backend.kind = BackendKind::Vulkan;
  s.backend.device = std::to_string(index);
  return s;
}

/// A counter of the simulation's devices (the scheduler report's "device_counters", summed).
long long deviceCounter(const Simulation& sim, const char* name) {
  const nlohmann::json report = nlohmann::json::parse(sim.schedulerReport());
  return report.value("device_counters", nlohmann::json::object()).value(name, 0LL);
}

void step(benchmark::State& state, std::size_t index, BoxSize size) {
  const Scene scene = boxScene(size, index);
  std::optional<Simulation> sim;
  auto fresh = [&]() -> bool {
    SimulationOptions o;
    o.vulkan = benchTuning();
    auto created = Simulation::create(scene, o);
    if (!created) {
      state.SkipWithError(created.message().c_str());
      return false;
    }
    sim.emplace(std::move(created.value()));
    for (int i = 0; i < 2; ++i) sim->step();  // warm-up: first allocations and uploads
    return true;
  };
  if (!fresh()) return;
  // Steps per simulation: the first steps of the motion, where 20 iterations keep the solve sound
  // (bench_backends measured the energy guard stopping the 100k block after 26 float steps).
  constexpr int kSteps = 20;
  double host = 0;
  long long submissions = 0, waits = 0, counted = 0;
  long long submittedBefore = deviceCounter(*sim, "submissions"), waitsBefore = deviceCounter(*sim, "blocking_waits");
  for (auto _ : state) {
    if (sim->stepsTaken() >= kSteps) {
      state.PauseTiming();
      submissions += deviceCounter(*sim, "submissions") - submittedBefore;
      waits += deviceCounter(*sim, "blocking_waits") - waitsBefore;
      const bool ok = fresh();
      submittedBefore = deviceCounter(*sim, "submissions");
      waitsBefore = deviceCounter(*sim, "blocking_waits");
      state.ResumeTiming();
      if (!ok) return;
    }
    const double t0 = threadSeconds();
    const Status st = sim->step();
    host += threadSeconds() - t0;
    ++counted;
    if (!st) {
      state.SkipWithError(st.message().c_str());
      return;
    }
  }
  submissions += deviceCounter(*sim, "submissions") - submittedBefore;
  waits += deviceCounter(*sim, "blocking_waits") - waitsBefore;
  const double n = static_cast<double>(std::max<long long>(counted, 1));
  state.counters["elements"] = static_cast<double>(sim->restMesh(0).tetCount());
  state.counters["host_ms_per_step"] = 1e3 * host / n;
  state.counters["submissions_per_step"] = static_cast<double>(submissions) / n;
  state.counters["blocking_waits_per_step"] = static_cast<double>(waits) / n;
  state.SetLabel(sim->backendName() + " on " + sim->deviceName());
}

int registerAll() {
  std::vector<detail::Candidate> devices;
  if (const auto entry = detail::findBackend("vulkan")) devices = entry->candidates();
  for (std::size_t i = 0; i < devices.size(); ++i) {
    const std::string dev = std::to_string(i);
    benchmark::RegisterBenchmark(("copy/" + dev).c_str(), copy, i)->UseManualTime()->MinTime(0.5)->Unit(benchmark::kMillisecond);
    for (const auto& [name, barrier] : {std::pair{"full", DispatchBarrier::Full}, std::pair{"compute", DispatchBarrier::Compute},
                                        std::pair{"none", DispatchBarrier::None}})
      benchmark::RegisterBenchmark(("dispatch/" + dev + "/" + name).c_str(), dispatchChain, i, barrier)
          ->UseManualTime()->MinTime(0.3)->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("roundtrip/" + dev).c_str(), roundTrip, i)
        ->UseManualTime()->MinTime(0.3)->Unit(benchmark::kMicrosecond);
    for (const BoxSize& size : kSizes) {
      benchmark::RegisterBenchmark(("pcg_iterations/" + dev + "/" + size.label).c_str(), pcgIterations, i, size)
          ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(0.5);
      benchmark::RegisterBenchmark(("step/" + dev + "/" + size.label).c_str(), step, i, size)
          ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(0.5);
    }
  }
  return 0;
}

}  // namespace

/// Takes --group_pcg_nodes, --fused_pcg and --device_store out of argv; exits with a message on a
/// malformed value.
void parseVulkanBenchOptions(int& argc, char** argv) {
  int out = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const std::string group = "--group_pcg_nodes=", fused = "--fused_pcg=", store = "--device_store=";
    const std::string* flag = arg.rfind(group, 0) == 0   ? &group
                              : arg.rfind(fused, 0) == 0 ? &fused
                              : arg.rfind(store, 0) == 0 ? &store
                                                         : nullptr;
    if (!flag) {
      argv[out++] = argv[i];
      continue;
    }
    char* end = nullptr;
    const long long v = std::strtoll(arg.c_str() + flag->size(), &end, 10);
    if (arg.size() == flag->size() || !end || *end) {
      std::fprintf(stderr, "%s: not an integer (VulkanTuning::%s)\n", arg.c_str(),
                   flag == &group ? "groupPcgNodes" : flag == &fused ? "fusedPcg" : "deviceStore");
      std::exit(2);
    }
    if (flag == &group) benchTuning().groupPcgNodes = v;
    else if (flag == &fused) benchTuning().fusedPcg = static_cast<int>(v);
    else benchTuning().deviceStore = static_cast<int>(v);
  }
  argc = out;
}

}  // namespace corofem

#endif  // COROFEM_WITH_VULKAN

int main(int argc, char** argv) {
#ifdef COROFEM_WITH_VULKAN
  corofem::parseVulkanBenchOptions(argc, argv);
  corofem::registerAll();
#endif
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
