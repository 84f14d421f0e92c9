// "backend": "auto": explicit requests (scene, COROFEM_DEVICE), the rules that need no
// calibration, calibration on fake candidates, and the cache file.
#include "schedule_support.hpp"

#include "backends/reference/reference_device.hpp"
#include "util/error.hpp"

#include <nlohmann/json.hpp>

#include <chrono>
#include <fstream>
#include <thread>

namespace corofem::test {
namespace {

std::string parseError(const std::string& spec) {
  try {
    detail::parseDeviceSpec(spec, "COROFEM_DEVICE");
  } catch (const detail::Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::BadInput);
    return e.what();
  }
  return "";
}

TEST(DeviceSpec, AcceptedForms) {
  EXPECT_EQ(detail::parseDeviceSpec("reference", "x").backend, "reference");
  EXPECT_EQ(detail::parseDeviceSpec("auto", "x").backend, "") << "no explicit request";
  auto r = detail::parseDeviceSpec("opencl", "x");
  EXPECT_EQ(r.backend, "opencl");
  EXPECT_EQ(r.device, "");
  r = detail::parseDeviceSpec("opencl:1", "x");
  EXPECT_EQ(r.device, "1");
  r = detail::parseDeviceSpec("OpenCL:pthread", "x");  // the name keeps its case, the backend does not matter
  EXPECT_EQ(r.backend, "opencl");
  EXPECT_EQ(r.device, "pthread");
}

TEST(DeviceSpec, BadValuesListTheChoices) {
  for (const char* bad : {"cuda", "opencl:", "reference:0", "", "gpu"}) {
    const std::string m = parseError(bad);
    EXPECT_NE(m.find("COROFEM_DEVICE=\""), std::string::npos) << bad << ": " << m;
    EXPECT_NE(m.find("\"reference\""), std::string::npos) << m;
    EXPECT_NE(m.find("\"opencl:<index>\""), std::string::npos) << m;
  }
}

TEST(DeviceSpec, EnvironmentOverridesAutoAndABadValueIsBadInput) {
  HookScope scope;
  Scene scene = dynamicScene(boxBeam(), 1);
  setenv("COROFEM_DEVICE", "reference", 1);
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  auto rep = nlohmann::json::parse(sim->schedulerReport());
  EXPECT_EQ(rep["choice"], "reference");
  EXPECT_NE(rep["reason"].get<std::string>().find("COROFEM_DEVICE"), std::string::npos) << rep.dump();

  setenv("COROFEM_DEVICE", "cuda", 1);
  auto bad = Simulation::create(scene);
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.status().code(), ErrorCode::BadInput);
  EXPECT_NE(bad.message().find("cuda"), std::string::npos) << bad.message();

  // The scene's explicit choice wins over the environment.
  scene.backend.kind = BackendKind::Reference;
  auto sceneWins = Simulation::create(scene);
  ASSERT_TRUE(sceneWins) << sceneWins.message();
  rep = nlohmann::json::parse(sceneWins->schedulerReport());
  EXPECT_NE(rep["reason"].get<std::string>().find("scene"), std::string::npos) << rep.dump();
}

/// Sleeps 50 ms in every solve: far beyond the whole step of a 400-element body (about 1 ms),
/// whatever the load.
class SlowDevice : public ForwardingDevice {
 public:
  using ForwardingDevice::ForwardingDevice;
  std::vector<detail::PcgStart> pcgBegin(const detail::BodySet& bodies, const std::vector<detail::SystemCoeffs>& c,
                                         const detail::ConstVectors& b, const detail::ConstVectors& x, double tolerance,
                                         int maxIterations) override {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    return ForwardingDevice::pcgBegin(bodies, c, b, x, tolerance, maxIterations);
  }
};

/// Candidates: a fake GPU of a fake "opencl" backend and the reference, both reference devices
/// underneath; the one whose device is named `slow` sleeps in every solve, so calibration must
/// rank it last. The fake refuses what the real OpenCL backend refuses (hyperelastic bodies, the
/// Cholesky solver); `created` counts the devices of both.
std::vector<detail::BackendEntry> fakeDevices(const std::string& slow, int* created) {
  auto make = [slow, created](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                              const detail::Candidate& c) -> std::unique_ptr<detail::Device> {
    ++*created;
    auto inner = detail::createReferenceDevice(problems, s);
    if (c.device != slow) return inner;
    return std::make_unique<SlowDevice>(std::move(inner));
  };
  detail::BackendEntry gpu = fakeBackend("opencl", {fakeCandidate("opencl", "fake-gpu", "0", true)}, make);
  gpu.refuses = [](const detail::Problem& p, const SolverDesc& s) -> std::string {
    if (p.formulation != Formulation::Corotational && p.formulation != Formulation::Linear)
      return std::string("the fake device cannot run the ") + toString(p.formulation) + " formulation";
    if (s.linearSolver == LinearSolverKind::Cholesky) return "the fake device has no Cholesky solver";
    return detail::hostOnlyFeature(p, s);  // what the real ones refuse besides
  };
  detail::BackendEntry reference = *detail::findBackend("reference");
  reference.create = [make](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                            const detail::Candidate& c, const detail::DeviceOptions&) { return make(problems, s, c); };
  return {gpu, reference};
}

/// `scene` with every body calibrated, however small (the fake devices' bodies have 400 elements).
Scene calibrated(Scene scene) {
  scene.backend.minDeviceElements = 0;
  return scene;
}

TEST(Scheduler, CalibrationPicksTheFasterCandidateAndCachesIt) {
  for (const std::string slow : {"host (Eigen, double)", "fake-gpu"}) {
    SCOPED_TRACE("slow: " + slow);
    int created = 0;
    HookScope scope(fakeDevices(slow, &created));
    const Scene scene = calibrated(dynamicScene(boxBeam(), 4));
    auto sim = Simulation::create(scene);
    ASSERT_TRUE(sim) << sim.message();
    auto rep = nlohmann::json::parse(sim->schedulerReport());
    const std::string fast = slow == "fake-gpu" ? "reference" : "opencl:0 (fake-gpu)";
    EXPECT_EQ(rep["choice"], fast) << rep.dump(1);
    EXPECT_EQ(rep["from_cache"], false);
    ASSERT_EQ(rep["candidates"].size(), 2u);
    for (const auto& c : rep["candidates"]) EXPECT_TRUE(c["ms_per_step"].is_number()) << c.dump();
    EXPECT_NE(rep["reason"].get<std::string>().find("calibration"), std::string::npos);
    EXPECT_EQ(created, 3);  // one calibration backend per candidate + the body's own
    // The fallback order ends with the reference backend.
    EXPECT_EQ(rep["bodies"][0]["fallback_order"].back(), "reference");

    // The cache file has one entry per candidate...
    std::ifstream in(scope.cacheDir() + "/scheduler.json");
    ASSERT_TRUE(in);
    const auto cache = nlohmann::json::parse(in);
    EXPECT_EQ(cache["entries"].size(), 2u) << cache.dump(1);

    // ...and the next run decides from it without calibrating.
    created = 0;
    auto again = Simulation::create(scene);
    ASSERT_TRUE(again) << again.message();
    auto rep2 = nlohmann::json::parse(again->schedulerReport());
    EXPECT_EQ(rep2["choice"], fast);
    EXPECT_EQ(rep2["from_cache"], true);
    EXPECT_EQ(created, 1);
    // Same answer whichever backend ran it (both are reference backends underneath).
    EXPECT_EQ(runToEnd(sim.value()), runToEnd(again.value()));
  }
}

TEST(Scheduler, CacheIsKeyedBySizeAndAnalysis) {
  int created = 0;
  HookScope scope(fakeDevices("", &created));  // no slow candidate: only the counts matter here
  ASSERT_TRUE(Simulation::create(calibrated(dynamicScene(boxBeam(), 2))));
  EXPECT_EQ(created, 3);
  created = 0;
  ASSERT_TRUE(Simulation::create(calibrated(staticScene(boxBeam(), 1))));  // other analysis: calibrates again
  EXPECT_EQ(created, 3);
  created = 0;
  ASSERT_TRUE(Simulation::create(calibrated(dynamicScene(boxBeam({40, 2, 2}), 2))));  // 800 elements: next log2 bucket
  EXPECT_EQ(created, 3);
  created = 0;
  ASSERT_TRUE(Simulation::create(calibrated(dynamicScene(boxBeam({21, 2, 2}), 2))));  // 420 elements: same bucket as 400
  EXPECT_EQ(created, 1);
  EXPECT_EQ(detail::sizeBucket(400), 8);
  EXPECT_EQ(detail::sizeBucket(420), 8);
  EXPECT_EQ(detail::sizeBucket(800), 9);
}

TEST(Scheduler, CachedNumbersDecide) {
  // A cache written by hand: the decision follows it, with no calibration at all.
  int created = 0;
  HookScope scope(fakeDevices("", &created));
  nlohmann::json cache;
  // Keys: backend|device|driver|analysis|precision|solver|preconditioner|size bucket|build.
  const std::string tail = "|dynamic|double|pcg|diagonal|log2e=8|build=" + detail::calibrationBuild();
  const std::string gpuKey = "opencl|fake-gpu|test" + tail, referenceKey = "reference|host (Eigen, double)|corofem" + tail;
  cache["version"] = 1;
  cache["entries"][gpuKey] = {{"ms_per_step", 0.5}};
  cache["entries"][referenceKey] = {{"ms_per_step", 7.0}};
  std::ofstream(scope.cacheDir() + "/scheduler.json") << cache.dump();
  auto sim = Simulation::create(calibrated(dynamicScene(boxBeam(), 2)));
  ASSERT_TRUE(sim) << sim.message();
  auto rep = nlohmann::json::parse(sim->schedulerReport());
  EXPECT_EQ(rep["choice"], "opencl:0 (fake-gpu)") << rep.dump(1);
  EXPECT_EQ(rep["from_cache"], true);
  EXPECT_EQ(created, 1);
  // A cached device error excludes the candidate.
  cache["entries"][gpuKey] = {{"error", "DeviceError: no fp64"}};
  std::ofstream(scope.cacheDir() + "/scheduler.json") << cache.dump();
  auto sim2 = Simulation::create(calibrated(dynamicScene(boxBeam(), 2)));
  ASSERT_TRUE(sim2) << sim2.message();
  rep = nlohmann::json::parse(sim2->schedulerReport());
  EXPECT_EQ(rep["choice"], "reference") << rep.dump(1);
  EXPECT_EQ(rep["candidates"][0]["error"], "DeviceError: no fp64");
  // A damaged cache file is recalibrated and rewritten.
  std::ofstream(scope.cacheDir() + "/scheduler.json") << "{not json";
  created = 0;
  ASSERT_TRUE(Simulation::create(calibrated(dynamicScene(boxBeam(), 2))));
  EXPECT_EQ(created, 3);
  std::ifstream in(scope.cacheDir() + "/scheduler.json");
  EXPECT_NO_THROW(nlohmann::json::parse(in));
}

TEST(Scheduler, ACacheOfAnotherBuildIsMeasuredAgain) {
  // Times measured by another corofem build (an older release, other kernels) may rank the
  // candidates wrongly now: they do not decide, the candidates are calibrated again and this
  // build's times join the file beside the other build's (two builds sharing a cache keep both);
  // the next run then decides from them. A file of the format before builds were recorded has no
  // "|build=" in its keys: the same.
  for (const std::string other : {"|build=corofem 0.0.1, kernels 0", ""}) {
    SCOPED_TRACE(other.empty() ? "keys without a build" : "keys of another build");
    int created = 0;
    HookScope scope(fakeDevices("", &created));
    nlohmann::json cache;
    const std::string tail = "|test|dynamic|double|pcg|diagonal|log2e=8";
    cache["version"] = 1;
    cache["entries"]["opencl|fake-gpu" + tail + other] = {{"ms_per_step", 0.5}};
    cache["entries"]["reference|host (Eigen, double)|corofem|dynamic|double|pcg|diagonal|log2e=8" + other] = {{"ms_per_step", 7.0}};
    std::ofstream(scope.cacheDir() + "/scheduler.json") << cache.dump();
    auto sim = Simulation::create(calibrated(dynamicScene(boxBeam(), 2)));
    ASSERT_TRUE(sim) << sim.message();
    EXPECT_EQ(nlohmann::json::parse(sim->schedulerReport())["from_cache"], false);
    EXPECT_EQ(created, 3) << "both candidates calibrated again";
    std::ifstream in(scope.cacheDir() + "/scheduler.json");
    const auto rewritten = nlohmann::json::parse(in);
    EXPECT_EQ(rewritten["entries"].size(), 4u) << rewritten.dump(1);
    EXPECT_TRUE(rewritten["entries"].contains("opencl|fake-gpu" + tail + other)) << "the other build's entry stays";
    EXPECT_TRUE(rewritten["entries"].contains("opencl|fake-gpu" + tail + "|build=" + detail::calibrationBuild()));
    EXPECT_NE(detail::calibrationBuild().find("corofem "), std::string::npos);
    created = 0;
    auto again = Simulation::create(calibrated(dynamicScene(boxBeam(), 2)));
    ASSERT_TRUE(again) << again.message();
    EXPECT_EQ(nlohmann::json::parse(again->schedulerReport())["from_cache"], true);
    EXPECT_EQ(created, 1);
  }
}

TEST(Scheduler, HyperelasticAndCholeskyGoToTheReferenceWithoutCalibration) {
  int created = 0;
  HookScope scope(fakeDevices("", &created));
  BodyDesc body = boxBeam();
  body.formulation = Formulation::NeoHookean;
  auto sim = Simulation::create(calibrated(dynamicScene(body, 1)));
  ASSERT_TRUE(sim) << sim.message();
  auto rep = nlohmann::json::parse(sim->schedulerReport());
  EXPECT_EQ(rep["choice"], "reference");
  EXPECT_NE(rep["reason"].get<std::string>().find("neo"), std::string::npos) << rep["reason"];
  EXPECT_EQ(created, 1);

  created = 0;
  Scene chol = calibrated(staticScene(boxBeam(), 1));
  chol.solver.linearSolver = LinearSolverKind::Cholesky;
  auto sim2 = Simulation::create(chol);
  ASSERT_TRUE(sim2) << sim2.message();
  rep = nlohmann::json::parse(sim2->schedulerReport());
  EXPECT_EQ(rep["choice"], "reference");
  EXPECT_NE(rep["reason"].get<std::string>().find("Cholesky"), std::string::npos);
  EXPECT_EQ(created, 1);
}

// "warped_cholesky" runs on the reference and OpenCL backends: the Vulkan backend refuses it with
// the fix, the OpenCL one takes it. A body whose device candidates all refuse it (the fake one
// below, as Vulkan does) goes to the reference without creating a device of another backend, and
// steps.
TEST(Scheduler, WarpedCholeskyGoesToTheReferenceWhereNoDeviceRunsIt) {
  SolverDesc s;
  s.preconditioner = PreconditionerKind::WarpedCholesky;
  for (const detail::BackendEntry& e : detail::registeredBackends()) {
    if (e.name == "reference") continue;
    ASSERT_TRUE(e.refuses) << e.name << " refuses nothing";
    std::string why;
    try {
      why = e.refuses(detail::Problem{}, s);
    } catch (const detail::Error& error) {  // a backend this build leaves out
      EXPECT_EQ(error.code(), ErrorCode::NotCompiledIn) << e.name;
      continue;
    }
    if (e.name == "opencl") EXPECT_EQ(why, "") << e.name;
    if (e.name == "vulkan")
      EXPECT_NE(why.find("\"warped_cholesky\" runs on the reference and opencl backends"), std::string::npos) << why;
  }
  int created = 0;
  std::vector<detail::BackendEntry> fakes = fakeDevices("", &created);
  fakes[0].refuses = [](const detail::Problem&, const SolverDesc& solver) -> std::string {
    return solver.preconditioner == PreconditionerKind::WarpedCholesky ? "the fake device has no \"warped_cholesky\""
                                                                        : "";
  };
  HookScope scope(fakes);
  Scene scene = calibrated(dynamicScene(boxBeam(), 2));
  scene.solver.preconditioner = PreconditionerKind::WarpedCholesky;
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  const auto rep = nlohmann::json::parse(sim->schedulerReport());
  EXPECT_EQ(rep["choice"], "reference");
  EXPECT_NE(rep["reason"].get<std::string>().find("warped_cholesky"), std::string::npos) << rep["reason"];
  EXPECT_EQ(created, 1);
  ASSERT_TRUE(sim->step().isOk());
  ASSERT_TRUE(sim->step().isOk());
}

// "amg" runs on every backend of this build: "auto" calibrates the candidates as for any solver,
// and the body steps on the one chosen.
TEST(Scheduler, AmgOnRealCandidatesIsCalibrated) {
  HookScope scope;  // real candidates of this build
  bool haveOpenCL = false;
  for (const detail::Candidate& c : detail::listCandidates()) haveOpenCL = haveOpenCL || c.backend == "opencl";
  Scene scene = calibrated(dynamicScene(boxBeam(), 2));
  scene.solver.preconditioner = PreconditionerKind::Amg;
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  auto rep = nlohmann::json::parse(sim->schedulerReport());
  if (haveOpenCL) EXPECT_GE(rep["candidates"].size(), 2u) << "calibrated between the backends: " << rep.dump(1);
  StepReport r;
  ASSERT_TRUE(sim->step(&r));
  EXPECT_TRUE(r.converged);
}

TEST(Scheduler, SmallBodiesOnRealCandidatesStayOnTheReference) {
  HookScope scope;  // real candidates of this build
  auto sim = Simulation::create(dynamicScene(boxBeam({4, 2, 2}), 1));  // 80 elements
  ASSERT_TRUE(sim) << sim.message();
  auto rep = nlohmann::json::parse(sim->schedulerReport());
  EXPECT_EQ(rep["choice"], "reference");
  EXPECT_EQ(sim->backendName(), "reference");
  EXPECT_TRUE(rep["candidates"].empty());
}

}  // namespace
}  // namespace corofem::test
