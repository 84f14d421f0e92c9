// Device failure fallback: a fault-injecting device (common/device_fakes.hpp) fails the way an
// OpenCL device does (program build, allocation, kernel launch, read-back) and the body carries
// on, state and all, on the next candidate.
#include "schedule_support.hpp"

#include "backends/reference/reference_device.hpp"
#include "output/run_outputs.hpp"

#include <nlohmann/json.hpp>

#include <fstream>

namespace corofem::test {
namespace {

/// A backend "faulty" whose devices (a, b) are reference devices with `spec`'s fault injected (the
/// fault of device b: `specB`); the factory counts the devices it made.
detail::BackendEntry faultyBackend(const FaultSpec& spec, int* created = nullptr, const FaultSpec& specB = {}) {
  return fakeBackend("faulty", {fakeCandidate("faulty", "faulty", "a"), fakeCandidate("faulty", "faulty-b", "b")},
                     [spec, specB, created](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                                            const detail::Candidate& c) {
                       if (created) ++*created;
                       return injectFaults(detail::createReferenceDevice(problems, s), c.selector == "a" ? spec : specB);
                     });
}

/// The body on "faulty" first (no calibration), then the reference backend.
SimulationOptions faultyFirst() {
  SimulationOptions o;
  o.devices = {"faulty:a"};
  return o;
}

/// Counts the reference devices made (the replacements).
detail::BackendEntry countingReference(int* created) {
  detail::BackendEntry e = *detail::findBackend("reference");
  e.create = [created](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                       const detail::Candidate&, const detail::DeviceOptions&) {
    ++*created;
    return detail::createReferenceDevice(problems, s);
  };
  return e;
}

std::vector<double> undisturbed(const Scene& scene) {
  HookScope scope;
  Scene s = scene;
  s.backend.kind = BackendKind::Reference;
  auto sim = Simulation::create(s);
  EXPECT_TRUE(sim) << sim.message();
  return sim ? runToEnd(sim.value()) : std::vector<double>{};
}

struct FaultCase {
  const char* name;
  FaultSpec spec;
  const char* call;  ///< the Backend call the failure is reported in
  const char* when;  ///< "create", "step" (a step), or "" (either)
};

// Every failure kind, on dynamics and statics. Reference -> reference fallback: the answer must
// be bit-identical to the undisturbed run (the repeated call sees the same positions and inputs).
TEST(Failover, EveryFaultKindEndsBitIdenticalOnTheFallback) {
  const std::vector<FaultCase> cases = {
      {"build", {FaultKind::Build, 1}, "create", "create"},
      {"allocation at create", {FaultKind::Allocation, 0}, "create", "create"},
      {"allocation later", {FaultKind::Allocation, 9}, "", ""},
      {"launch in solve", {FaultKind::Launch, 5}, "solve", "step"},
      {"read-back of forces", {FaultKind::ReadBack, 4}, "internalForces", "step"},
  };
  for (bool dynamic : {true, false}) {
    const Scene scene = dynamic ? dynamicScene(boxBeam(), 6) : staticScene(boxBeam(), 3);
    const std::vector<double> expected = undisturbed(scene);
    ASSERT_FALSE(expected.empty());
    for (const FaultCase& fc : cases) {
      SCOPED_TRACE(std::string(dynamic ? "dynamic, " : "static, ") + fc.name);
      int created = 0;
      HookScope scope({faultyBackend(fc.spec, &created), countingReference(&created)});
      auto sim = Simulation::create(scene, faultyFirst());
      ASSERT_TRUE(sim) << sim.message();
      const std::vector<double> x = runToEnd(sim.value());
      ASSERT_EQ(x.size(), expected.size());
      EXPECT_TRUE(x == expected) << "positions differ from the undisturbed reference run";
      std::vector<double> v;
      ASSERT_TRUE(sim->readVelocities(0, v));
      const auto report = nlohmann::json::parse(sim->schedulerReport());
      ASSERT_EQ(report["fallbacks"].size(), 1u) << report.dump(1);
      const auto& ev = report["fallbacks"][0];
      EXPECT_EQ(ev["from"], "faulty:a (faulty)");
      EXPECT_EQ(ev["to"], "reference");
      EXPECT_NE(ev["error"].get<std::string>().find("injected"), std::string::npos) << ev.dump();
      if (*fc.call) {
        EXPECT_EQ(ev["call"], fc.call);
      }
      if (std::string(fc.when) == "create") {
        EXPECT_EQ(ev["when"], "create");
      }
      if (std::string(fc.when) == "step") {
        EXPECT_EQ(ev["when"].get<std::string>().rfind("step ", 0), 0u) << ev.dump();
      }
      EXPECT_EQ(created, 2);  // the faulty backend and its one replacement
      EXPECT_EQ(sim->deviceName(), "host (Eigen, double)");  // the replacement, no fault tag
    }
  }
}

// The fallback is recorded in summary.json.
TEST(Failover, SummaryListsTheFallback) {
  HookScope scope({faultyBackend({FaultKind::Launch, 2})});
  auto sim = Simulation::create(dynamicScene(boxBeam(), 3), faultyFirst());
  ASSERT_TRUE(sim) << sim.message();
  const std::string dir = scope.cacheDir() + "/out";
  detail::RunOutputs out(sim.value(), dir);
  ASSERT_FALSE(runToEnd(sim.value()).empty());
  out.finish(sim.value(), Status::ok(), 0.0);
  std::ifstream in(dir + "/summary.json");
  const auto summary = nlohmann::json::parse(in);
  ASSERT_EQ(summary["fallbacks"].size(), 1u) << summary.dump(1);
  EXPECT_EQ(summary["fallbacks"][0]["call"], "solve");
  EXPECT_EQ(summary["fallbacks"][0]["when"], "step 1");
  EXPECT_TRUE(summary["scheduler"].contains("choice"));
  EXPECT_TRUE(summary["scheduler"].contains("reason"));
  EXPECT_TRUE(summary["scheduler"].contains("candidates"));
  EXPECT_TRUE(summary["scheduler"].contains("from_cache"));
}

// When every candidate fails the step reports DeviceError naming each failure, and the body keeps
// its last good state.
TEST(Failover, EveryCandidateFailingIsADeviceErrorAndKeepsTheState) {
  // a fails at its 3rd solve, b (its replacement) at its first, and the reference backend (always
  // the last of an order) is replaced by one that fails at its first: every device fails.
  detail::BackendEntry failingReference = *detail::findBackend("reference");
  failingReference.create = [](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                               const detail::Candidate&, const detail::DeviceOptions&) {
    return injectFaults(detail::createReferenceDevice(problems, s), {FaultKind::Launch, 1});
  };
  HookScope scope({faultyBackend({FaultKind::Launch, 3}, nullptr, {FaultKind::Launch, 1}), failingReference});
  SimulationOptions o;
  o.devices = {"faulty:a", "faulty:b"};
  auto sim = Simulation::create(dynamicScene(boxBeam(), 6), o);
  ASSERT_TRUE(sim) << sim.message();
  Status st;
  std::vector<double> before;
  while (!sim->finished()) {
    ASSERT_TRUE(sim->readPositions(0, before));
    st = sim->step();
    if (!st) break;
  }
  ASSERT_FALSE(st);
  EXPECT_EQ(st.code(), ErrorCode::DeviceError) << st.message();
  EXPECT_NE(st.message().find("every backend failed"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("faulty") , std::string::npos) << st.message();
  std::vector<double> after;
  ASSERT_TRUE(sim->readPositions(0, after));
  EXPECT_EQ(before, after);
  // The reports still describe the scene, and the next step fails the same way, at once.
  const auto report = nlohmann::json::parse(sim->schedulerReport());
  EXPECT_EQ(report["fallbacks"].size(), 2u) << report.dump(1);
  EXPECT_FALSE(nlohmann::json::parse(sim->planReport())["bodies"].empty());
  EXPECT_FALSE(sim->backendName().empty());
  const Status again = sim->step();
  EXPECT_EQ(again.code(), ErrorCode::DeviceError);
  EXPECT_NE(again.message().find("every backend failed"), std::string::npos) << again.message();
}

// An application's order is a preference, not a demand: an entry that cannot take the body (a
// device not on this machine, a formulation the backend refuses) is skipped and named in the
// report, and a candidate whose creation fails for any reason during a failover is passed over.
TEST(Failover, OrderEntriesThatCannotTakeTheBodyArePassedOver) {
  int made = 0;
  detail::BackendEntry picky = fakeBackend("picky", {fakeCandidate("picky", "picky", "a")},
                                           [&made](const std::vector<const detail::Problem*>& problems,
                                                   const SolverDesc& s, const detail::Candidate&) {
                                             ++made;
                                             return detail::createReferenceDevice(problems, s);
                                           });
  picky.refuses = [](const detail::Problem& p, const SolverDesc&) -> std::string {
    return p.formulation == Formulation::Linear ? "the picky device runs no linear bodies" : "";
  };
  detail::BackendEntry refusing = fakeBackend("refusing", {fakeCandidate("refusing", "refusing", "a")},
                                              [](const std::vector<const detail::Problem*>&, const SolverDesc&,
                                                 const detail::Candidate&) -> std::unique_ptr<detail::Device> {
                                                detail::fail(ErrorCode::BadInput,
                                                             "workGroupSize 512 is above this device's 256");
                                              });
  HookScope scope({faultyBackend({FaultKind::Launch, 3}), picky, refusing});
  BodyDesc linear = boxBeam();
  linear.formulation = Formulation::Linear;
  SimulationOptions o;
  o.devices = {"faulty:nowhere", "picky:a"};
  auto sim = Simulation::create(dynamicScene(linear, 2), o);
  ASSERT_TRUE(sim) << sim.message();
  auto rep = nlohmann::json::parse(sim->schedulerReport());
  EXPECT_EQ(rep["choice"], "reference") << rep.dump(1);
  ASSERT_EQ(rep["candidates"].size(), 2u) << rep.dump(1);
  EXPECT_NE(rep["candidates"][0]["error"].get<std::string>().find("nowhere"), std::string::npos) << rep.dump(1);
  EXPECT_NE(rep["candidates"][1]["error"].get<std::string>().find("no linear bodies"), std::string::npos);
  EXPECT_EQ(made, 0);
  EXPECT_FALSE(runToEnd(sim.value()).empty());

  // A corotational body takes "picky"; when "faulty" fails mid-step, "refusing" cannot be made
  // (BadInput) and the body goes on on the reference backend, the step intact.
  const Scene scene = dynamicScene(boxBeam(), 6);
  const std::vector<double> expected = undisturbed(scene);
  o.devices = {"faulty:a", "refusing:a"};
  auto moved = Simulation::create(scene, o);
  ASSERT_TRUE(moved) << moved.message();
  EXPECT_EQ(runToEnd(moved.value()), expected);
  rep = nlohmann::json::parse(moved->schedulerReport());
  ASSERT_EQ(rep["fallbacks"].size(), 1u) << rep.dump(1);
  EXPECT_EQ(rep["fallbacks"][0]["to"], "reference");
  EXPECT_EQ(moved->backendName(), "reference");
}

// An explicit choice that cannot start is an error, as before the scheduler (no silent move).
TEST(Failover, ExplicitChoiceThatCannotStartIsAnError) {
  HookScope scope;
  Scene scene = dynamicScene(boxBeam(), 2);
  scene.backend.kind = BackendKind::OpenCL;
  scene.backend.device = "no-such-device-xyz";
  auto sim = Simulation::create(scene);
  ASSERT_FALSE(sim);
#ifdef COROFEM_WITH_OPENCL
  EXPECT_EQ(sim.status().code(), ErrorCode::DeviceError) << sim.message();
#else
  EXPECT_EQ(sim.status().code(), ErrorCode::NotCompiledIn) << sim.message();
#endif
}

// "auto" with a device named is an explicit request for that OpenCL device.
TEST(Failover, AutoWithADeviceNamedIsAnExplicitRequest) {
  HookScope scope;
  Scene scene = dynamicScene(boxBeam(), 2);
  scene.backend.kind = BackendKind::Auto;
  scene.backend.device = "no-such-device-xyz";
  auto sim = Simulation::create(scene);
  ASSERT_FALSE(sim);
#ifdef COROFEM_WITH_OPENCL
  EXPECT_EQ(sim.status().code(), ErrorCode::DeviceError) << sim.message();
#else
  EXPECT_EQ(sim.status().code(), ErrorCode::NotCompiledIn) << sim.message();
#endif
}

#ifdef COROFEM_WITH_OPENCL
// A real OpenCL device (PoCL here) failing in the middle of the run: the body finishes on the
// reference backend. The steps before the failure ran on the device, so the answer equals the
// undisturbed reference run only to the solver tolerance.
TEST(Failover, OpenClLaunchFailureFinishesOnTheReference) {
  HookScope scope0;
  const std::vector<detail::Candidate> cands = detail::listCandidates();
  if (cands.size() < 2) GTEST_SKIP() << "no OpenCL device";
  const detail::Candidate device = cands.front();
  const Scene scene = dynamicScene(boxBeam(), 6);
  const std::vector<double> expected = undisturbed(scene);
  HookScope scope({wrapBackend("opencl", [](std::unique_ptr<detail::Device> d, const auto&) {
    return injectFaults(std::move(d), {FaultKind::Launch, 6});
  })});
  SimulationOptions o;
  o.devices = {"opencl:" + device.selector};
  auto sim = Simulation::create(scene, o);
  ASSERT_TRUE(sim) << sim.message();
  EXPECT_EQ(sim->backendName(), "opencl");
  const std::vector<double> x = runToEnd(sim.value());
  ASSERT_EQ(x.size(), expected.size());
  EXPECT_EQ(sim->backendName(), "reference");
  // PCG tolerance 1e-10 (relative) on the device steps before the failure: the tip moves ~1 cm, so
  // 1e-9 m leaves two orders of margin over the measured difference.
  double worst = 0;
  for (std::size_t i = 0; i < x.size(); ++i) worst = std::max(worst, std::abs(x[i] - expected[i]));
  EXPECT_LT(worst, 1e-9);
  std::cout << "[ measured ] OpenCL -> reference fallback: largest position difference " << worst << " m\n";
  const auto report = nlohmann::json::parse(sim->schedulerReport());
  ASSERT_EQ(report["fallbacks"].size(), 1u);
  EXPECT_EQ(report["fallbacks"][0]["to"], "reference");
}
#endif

}  // namespace
}  // namespace corofem::test
