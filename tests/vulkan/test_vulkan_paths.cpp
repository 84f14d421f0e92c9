// The Vulkan backend's PCG paths (VulkanTuning::groupPcgNodes and fusedPcg): whole iterations in
// one dispatch, a work-group per body (kernels/vulkan/pcg_group.comp), and off it an iteration by
// phases in four dispatches (the update, the product's element and node passes, the scalars) or,
// fused, in two (the update folded into the product's passes, the scalars into the node pass's last
// work-group: element_fused.comp and pcg_fused.comp; three with the multigrid's V-cycle). The
// conformance suite checks the default path against the reference (its bodies are small: the
// one-dispatch path on a CPU device); here the others are held to it on every Vulkan device, in
// double and float, for every preconditioner the backend has, on the conformance suite's seven
// bodies solved together: the same operations in the same order give the same iteration counts
// and answers.
#include "backends/vulkan/vk_runtime.hpp"
#include "conformance/conformance_support.hpp"
#include "solve/beam_helpers.hpp"

#include <corofem/simulation.hpp>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <limits>
#include <random>

namespace corofem::test {
namespace {

std::vector<ConformanceCase> vulkanCases() {
  std::vector<ConformanceCase> out;
  for (const ConformanceCase& c : conformanceCases())
    if (c.backend == "vulkan") out.push_back(c);
  return out;
}

class VulkanPaths : public ConformanceBase {
 protected:
  /// A device of the case on the path `groupNodes` and `fused` pick (-1: dispatches per phase, four
  /// an iteration, or fused = 1: two, three with the multigrid; a large value: whole iterations in
  /// one dispatch).
  std::unique_ptr<detail::Device> onPath(const SolverDesc& s, long long groupNodes, int fused = 0) const {
    const auto entry = detail::findBackend(GetParam().backend);
    detail::DeviceOptions o = options();
    o.vulkan.groupPcgNodes = groupNodes;
    o.vulkan.fusedPcg = fused;
    return entry->create(problemsOf(bodies()), s, entry->resolve(GetParam().selector), o);
  }
  static long long counter(const detail::Device& d, const std::string& name) {
    for (const detail::DeviceCounter& c : d.counters())
      if (c.name == name) return c.value;
    return -1;
  }
};

TEST_P(VulkanPaths, EveryPcgPathIteratesAlikeAndGivesTheSameAnswers) {
  const detail::BodySet all = detail::allBodies(count());
  std::vector<Eigen::VectorXd> x(count()), b(count()), zeros(count());
  detail::ConstVectors xs;
  std::vector<detail::SystemCoeffs> systems;
  std::mt19937 rng(4711);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (std::size_t i = 0; i < count(); ++i) {
    x[i] = randomPositions(problem(i), 900 + static_cast<unsigned>(i));
    xs.push_back(&x[i]);
    b[i].resize(static_cast<Eigen::Index>(problem(i).dofCount()));
    for (Eigen::Index d = 0; d < b[i].size(); ++d) b[i][d] = u(rng);
    zeros[i] = Eigen::VectorXd::Zero(b[i].size());
    systems.push_back(bodies()[i].solve);
  }
  for (PreconditionerKind pc : {PreconditionerKind::None, PreconditionerKind::Diagonal, PreconditionerKind::BlockDiagonal,
                                PreconditionerKind::Amg}) {
    SCOPED_TRACE(toString(pc));
    const bool amg = pc == PreconditionerKind::Amg;
    const SolverDesc s = solver(pc);
    // The path the others are held to: one dispatch (the multigrid has none: four by phases).
    std::unique_ptr<detail::Device> first = amg ? onPath(s, -1, 0) : onPath(s, std::numeric_limits<long long>::max());
    first->setPositions(all, xs);
    const SetSolve g = solveSet(*first, all, b, zeros, s, systems);
    EXPECT_EQ(counter(*first, "pcg_group_dispatches") > 0, !amg);
    EXPECT_EQ(counter(*first, "pcg_phase_dispatches") > 0, amg);
    long long fourPerIteration = amg ? counter(*first, "pcg_phase_dispatches") : 0;
    for (int fused : amg ? std::vector<int>{1} : std::vector<int>{0, 1}) {
      const long long perIteration = fused ? (amg ? 3 : 2) : 4;
      SCOPED_TRACE(std::to_string(perIteration) + " dispatches an iteration");
      std::unique_ptr<detail::Device> phases = onPath(s, -1, fused);
      phases->setPositions(all, xs);
      const SetSolve a = solveSet(*phases, all, b, zeros, s, systems);
      // Each device took the path asked for (else the comparison would compare a path with itself):
      // no body reaches the cap, so every path enqueues the same iterations, each of its number of
      // dispatches.
      EXPECT_EQ(counter(*phases, "pcg_group_dispatches"), 0);
      const long long dispatches = counter(*phases, "pcg_phase_dispatches");
      if (fused == 0) fourPerIteration = dispatches;
      EXPECT_GT(dispatches, 0);
      EXPECT_EQ(4 * dispatches, perIteration * fourPerIteration);
      for (std::size_t i = 0; i < count(); ++i) {
        SCOPED_TRACE(problem(i).name);
        ASSERT_TRUE(a.solves[i].failure.empty()) << a.solves[i].failure;
        ASSERT_TRUE(g.solves[i].failure.empty()) << g.solves[i].failure;
        std::printf("[info] %s, %s, %s: %d iterations in %lld dispatches each, %d on the first path, |x_a - x_g| / "
                    "|x_a| %.1e\n", GetParam().describe().c_str(), toString(pc), problem(i).name.c_str(),
                    a.solves[i].stats.iterations, perIteration, g.solves[i].stats.iterations, relErr(g.x[i], a.x[i]));
        EXPECT_EQ(a.solves[i].stats.iterations, g.solves[i].stats.iterations);
        EXPECT_EQ(a.solves[i].stats.converged, g.solves[i].stats.converged);
        // The same operations in the same order: equal up to the compiler's freedom to fuse a
        // multiply-add differently in two shaders (a few roundings of the device's precision).
        EXPECT_LE(relErr(g.x[i], a.x[i]), isDouble() ? 1e-12 : 1e-4);
      }
    }
  }
}

TEST_P(VulkanPaths, ManyIterationsInOneCallMatchOneAtATime) {
  // 150 iterations asked for at once (a solve with a large checkEvery) on the one-dispatch path, for
  // a body of 2,541 nodes (40 passes of 64 nodes per phase): the same scalars and x as 150 calls of
  // one iteration. Lavapipe ended such work-groups silently after about 1,500 passes in one dispatch
  // (here: after 38 iterations, stopped but "running"), which the host now splits (VulkanDevice).
  detail::Problem p = makeProblem(cellBox(20, 10, 10, 0.1, 0.1, 0.1), 5e5, 0.3, 1200.0);
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
    if (p.mesh.nodes[3 * n] < 1e-9)
      for (std::size_t k = 0; k < 3; ++k) p.constrained[3 * n + k] = 1;
  SolverDesc s = solver(PreconditionerKind::None);
  s.tolerance = 1e-30;  // no stop before the 150th
  const auto entry = detail::findBackend(GetParam().backend);
  detail::DeviceOptions o = options();
  o.vulkan.groupPcgNodes = std::numeric_limits<long long>::max();
  Eigen::VectorXd x = p.restPositions, b(static_cast<Eigen::Index>(p.dofCount()));
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (Eigen::Index d = 0; d < b.size(); ++d) b[d] = u(rng);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(b.size());
  constexpr int kIterations = 150;
  auto run = [&](int perCall, std::vector<detail::PcgScalars>& last, Eigen::VectorXd& out) {
    std::unique_ptr<detail::Device> d = entry->create({&p}, s, entry->resolve(GetParam().selector), o);
    d->setPositions({0}, {&x});
    ASSERT_EQ(d->pcgBegin({0}, {{0.0, 0.0, 1.0}}, {&b}, {&zero}, s.tolerance, 1000)[0], detail::PcgStart::Running);
    for (int done = 0; done < kIterations; done += perCall) d->pcgIterate(perCall, {1});
    d->pcgTake(d->pcgRead(), last);
    std::vector<detail::PcgScalars> residual;
    d->pcgEnd({kIterations}, {&out}, residual);
  };
  std::vector<detail::PcgScalars> one, all;
  Eigen::VectorXd xOne, xAll;
  run(1, one, xOne);
  run(kIterations, all, xAll);
  ASSERT_EQ(one.size(), 1u);
  ASSERT_EQ(all.size(), 1u);
  EXPECT_EQ(one[0].iterations, kIterations);
  EXPECT_EQ(all[0].iterations, kIterations);
  EXPECT_EQ(all[0].stop, detail::PcgStop::Running);
  EXPECT_EQ(all[0].rr, one[0].rr);
  EXPECT_TRUE(xAll == xOne) << "x differs: " << relErr(xAll, xOne);
}

/// A whole dynamic run off the one-dispatch path with the iterations in two dispatches (fusedPcg =
/// 1, a GPU's default; three with the multigrid) and in four (0), on the default Vulkan device: the
/// same positions. VulkanPaths holds the PCG building blocks to each other; this holds the whole
/// step around them (the forces, the set-up, the reads every checkEvery iterations, the true
/// residual, the update) on the path a GPU takes, which lavapipe does not by default.
TEST(VulkanPathsScene, AWholeRunInTwoDispatchesAnIterationIsTheRunInFour) {
  int compared = 0;
  for (Precision precision : {Precision::Double, Precision::Float})
    for (PreconditionerKind pc : {PreconditionerKind::Diagonal, PreconditionerKind::Amg}) {
      SCOPED_TRACE(std::string(toString(precision)) + ", " + toString(pc));
      BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {1.0, 0.1, 0.1}, {20, 2, 2}), 0.0, 1e6, 0.3, 1000.0,
                                     Formulation::Corotational);
      body.loads.push_back(gravity({0, -9.81, 0}));
      Scene scene = staticScene(body, 1, LinearSolverKind::Pcg);
      scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
      scene.analysis.dynamics.integrator = Integrator::BackwardEuler;
      scene.analysis.dynamics.timeStep = 1.0 / 60.0;
      scene.analysis.dynamics.steps = 8;
      scene.solver.precision = precision;
      scene.solver.preconditioner = pc;
      scene.solver.tolerance = precision == Precision::Double ? 1e-9 : 1e-5;
      scene.solver.maxIterations = 3000;
      scene.backend.kind = BackendKind::Vulkan;
      std::vector<double> x[2];
      long long dispatches[2] = {0, 0};
      bool ran = true;
      for (int fused : {0, 1}) {
        SimulationOptions o;
        o.vulkan.groupPcgNodes = -1;
        o.vulkan.fusedPcg = fused;
        auto sim = Simulation::create(scene, o);
        if (!sim) {
          ASSERT_TRUE(sim.status().code() == ErrorCode::NotCompiledIn || sim.status().code() == ErrorCode::DeviceError)
              << sim.message();
          std::printf("[info] skipped: %s\n", sim.message().c_str());
          ran = false;
          break;
        }
        ASSERT_TRUE(runToEnd(sim.value()));
        ASSERT_TRUE(sim->readPositions(0, x[fused]));
        const nlohmann::json report = nlohmann::json::parse(sim->schedulerReport());
        dispatches[fused] = report.value("device_counters", nlohmann::json::object()).value("pcg_phase_dispatches", 0LL);
      }
      if (!ran) continue;
      ASSERT_EQ(x[0].size(), x[1].size());
      double worst = 0, lowest = 0;  // the beam's lowest point: y from 0 at rest
      for (std::size_t i = 0; i < x[0].size(); ++i) worst = std::max(worst, std::abs(x[1][i] - x[0][i]));
      for (std::size_t i = 1; i < x[0].size(); i += 3) lowest = std::min(lowest, x[0][i]);
      std::printf("[info] %s, %s: largest position difference, two dispatches - four, %.3g m (the beam's lowest "
                  "point %.3g m)\n", toString(precision), toString(pc), worst, lowest);
      EXPECT_LT(lowest, -1e-3);  // it moved
      // Each run took the path asked for: the same iterations, two (three) dispatches each or four.
      EXPECT_GT(dispatches[0], 0);
      EXPECT_EQ(4 * dispatches[1], (pc == PreconditionerKind::Amg ? 3 : 2) * dispatches[0]);
      // The same operations in the same order (the same bits on lavapipe); a device may contract
      // the element products' multiply-adds differently in the two element shaders, which the
      // solves' tolerance bounds.
      EXPECT_LE(worst, precision == Precision::Double ? 1e-9 : 1e-5);
      ++compared;
    }
  if (compared == 0) GTEST_SKIP() << "no Vulkan device";
}

/// The process's instance outlives every backend and enumeration: on an H100 (NVIDIA's driver 580),
/// a backend made after the device list had been read (an instance made and dropped) failed with
/// VK_ERROR_INCOMPATIBLE_DRIVER. lavapipe makes instances again fine, so this checks the policy
/// that avoids it, not the driver.
TEST(VulkanInstance, OnceMadeItOutlivesTheDeviceListAndEveryBackend) {
  std::weak_ptr<detail::vk::Instance> seen;
  try {
    seen = detail::vk::Instance::shared();
  } catch (const std::exception& e) {
    GTEST_SKIP() << "no Vulkan instance: " << e.what();
  }
  const auto entry = detail::findBackend("vulkan");
  ASSERT_NE(entry, nullptr);
  const std::vector<detail::Candidate> devices = entry->candidates();
  EXPECT_FALSE(seen.expired()) << "the device list let the instance go";
  if (devices.empty()) GTEST_SKIP() << "no usable Vulkan device";
  const detail::Problem beam = makeProblem(cellBox(4, 1, 1, 0.1, 0.1, 0.1), 1e5, 0.3, 1000.0);
  for (int round = 0; round < 2; ++round) {  // made and dropped twice: each finds the same instance
    SolverDesc s;
    s.precision = Precision::Float;
    auto device = entry->create({&beam}, s, entry->resolve("0"), {});
    ASSERT_NE(device, nullptr);
    device.reset();
    ASSERT_FALSE(seen.expired()) << "round " << round << ": the instance went with the backend";
    EXPECT_EQ(seen.lock().get(), detail::vk::Instance::shared().get());
  }
}

INSTANTIATE_TEST_SUITE_P(Vulkan, VulkanPaths, testing::ValuesIn(vulkanCases()), caseName);
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(VulkanPaths);

}  // namespace
}  // namespace corofem::test
