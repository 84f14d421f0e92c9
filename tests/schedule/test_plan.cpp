// Plans (Simulation::planReport, `corofem run --plan`): a scene's plan lists only what its step
// needs.
#include "schedule_support.hpp"

#include "backends/reference/reference_device.hpp"
#include "common/morton.hpp"
#include "common/test_problems.hpp"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>

namespace corofem::test {
namespace {

using nlohmann::json;

bool anyBufferContains(const json& body, const std::string& word) {
  for (const auto& b : body["buffers"])
    if (b["name"].get<std::string>().find(word) != std::string::npos) return true;
  return false;
}

bool anyContains(const json& list, const std::string& word) {
  for (const auto& t : list)
    if (t.get<std::string>().find(word) != std::string::npos) return true;
  return false;
}

/// Plans of a scene on the reference backend and on an "opencl" device that is a fake (the plan is
/// a host estimate; the fake device underneath is a reference one).
std::vector<json> plans(const Scene& scene) {
  std::vector<json> out;
  for (bool device : {false, true}) {
    std::vector<detail::BackendEntry> fakes;
    SimulationOptions options;
    if (device) {
      fakes.push_back(fakeBackend("opencl", {fakeCandidate("opencl", "fake-gpu", "0", true)},
                                  [](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                                     const detail::Candidate&) { return detail::createReferenceDevice(problems, s); }));
      options.devices = {"opencl"};
    }
    HookScope scope(std::move(fakes));
    Scene sc = scene;
    if (!device) sc.backend.kind = BackendKind::Reference;
    auto sim = Simulation::create(sc, options);
    EXPECT_TRUE(sim) << sim.message();
    if (!sim) return out;
    const json plan = json::parse(sim->planReport());
    EXPECT_EQ(plan["bodies"].size(), 1u);
    out.push_back(plan["bodies"][0]);
    EXPECT_EQ(out.back()["backend"], device ? "opencl" : "reference");
  }
  return out;
}

/// Whether this build and machine have an OpenCL device.
bool haveOpenCL() {
  for (const detail::Candidate& c : detail::listCandidates())
    if (c.backend == "opencl") return true;
  return false;
}

TEST(Plan, StaticSceneHasNoDynamicBuffersOrTerms) {
  for (const json& body : plans(staticScene(boxBeam(), 2))) {
    SCOPED_TRACE(body["backend"].get<std::string>());
    EXPECT_FALSE(anyBufferContains(body, "velocit")) << body["buffers"].dump(1);
    EXPECT_FALSE(anyBufferContains(body, "mass")) << body["buffers"].dump(1);
    EXPECT_FALSE(anyContains(body["terms"], "mass")) << body["terms"];
    EXPECT_FALSE(anyContains(body["kernels"], "M,")) << body["kernels"];
    EXPECT_EQ(body["features"]["mass_terms"], false);
    EXPECT_EQ(body["features"]["damping"], false);
    EXPECT_GT(body["bytes_moved"]["per_pcg_iteration"].get<double>(), 0);
  }
}

TEST(Plan, DynamicSceneListsMassAndVelocities) {
  for (const json& body : plans(dynamicScene(boxBeam(), 2))) {
    SCOPED_TRACE(body["backend"].get<std::string>());
    EXPECT_TRUE(anyBufferContains(body, "velocit")) << body["buffers"].dump(1);
    EXPECT_TRUE(anyContains(body["terms"], "mass")) << body["terms"];
    EXPECT_EQ(body["features"]["mass_terms"], true);
    // Damping-free scene: no damping term anywhere.
    EXPECT_EQ(body["features"]["damping"], false);
    EXPECT_FALSE(anyContains(body["terms"], "amping")) << body["terms"];
    EXPECT_FALSE(anyContains(body["kernels"], "C,")) << body["kernels"];
  }
}

TEST(Plan, DampedSceneListsTheDampingTerm) {
  BodyDesc body = boxBeam();
  body.material.rayleighMass = 0.5;
  for (const json& b : plans(dynamicScene(body, 2))) {
    SCOPED_TRACE(b["backend"].get<std::string>());
    EXPECT_EQ(b["features"]["damping"], true);
    EXPECT_TRUE(anyContains(b["terms"], "damping")) << b["terms"];
  }
}

/// A body on the Vulkan backend: the plan names the backend's shaders (its registry entry's passes),
/// with the product's terms of the scene, and none of the OpenCL kernels.
TEST(Plan, AVulkanBodyListsItsShaders) {
  bool vulkan = false;
  for (const detail::Candidate& c : detail::listCandidates()) vulkan = vulkan || c.backend == "vulkan";
  if (!vulkan) GTEST_SKIP() << "no Vulkan device here";
  BodyDesc body = boxBeam();
  body.material.rayleighMass = 0.5;
  Scene scene = dynamicScene(body, 2);
  scene.backend.kind = BackendKind::Vulkan;
  scene.solver.preconditioner = PreconditionerKind::BlockDiagonal;
  scene.solver.precision = Precision::Float;  // every Vulkan device has float
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  const json kernels = json::parse(sim->planReport())["bodies"][0]["kernels"];
  EXPECT_TRUE(anyContains(kernels, "rotations.comp (polar)")) << kernels;
  EXPECT_TRUE(anyContains(kernels, "product of M, C, K_t")) << kernels;
  EXPECT_TRUE(anyContains(kernels, "3x3 blocks")) << kernels;
  EXPECT_FALSE(anyContains(kernels, "pcg_iterate")) << kernels;
  EXPECT_FALSE(anyContains(kernels, "compute_rotations")) << kernels;
  // Its buffers are the Vulkan device's (its registry entry's), in float: 7 PCG vectors of 3 N reals.
  const json body0 = json::parse(sim->planReport())["bodies"][0];
  const long long nodes = body0["nodes"].get<long long>();
  bool corners = false, pcgVectors = false;
  for (const json& b : body0["buffers"]) {
    corners = corners || b["name"] == "element_corners";
    if (b["name"] == "pcg_vectors (b x r u p s w)") pcgVectors = b["bytes"].get<long long>() == 7 * 3 * nodes * 4;
    EXPECT_NE(b["name"], "element_nodes") << "the OpenCL layout's name";
  }
  EXPECT_TRUE(corners && pcgVectors) << body0["buffers"];
  // With the multigrid: its shader and its buffers.
  scene.solver.preconditioner = PreconditionerKind::Amg;
  auto amg = Simulation::create(scene);
  ASSERT_TRUE(amg) << amg.message();
  const json amgBody = json::parse(amg->planReport())["bodies"][0];
  EXPECT_TRUE(anyContains(amgBody["kernels"], "amg.comp")) << amgBody["kernels"];
  bool amgBuffers = false;
  for (const json& b : amgBody["buffers"]) amgBuffers = amgBuffers || b["name"] == "amg level-0 vectors";
  EXPECT_TRUE(amgBuffers) << amgBody["buffers"];
}

TEST(Plan, SizesFollowTheModel) {
  // 400 elements, 21 x 3 x 3 = 189 nodes. On the device in double: element nodes 16 B/element,
  // positions 3 x 189 x 8 B; in float the reals halve.
  Scene scene = staticScene(boxBeam(), 1);
  const std::vector<json> p = plans(scene);
  ASSERT_EQ(p.size(), 2u);
  const json& dev = p[1];
  EXPECT_EQ(dev["elements"], 400);
  EXPECT_EQ(dev["nodes"], 189);
  auto bytesOf = [](const json& body, const std::string& name) -> long long {
    for (const auto& b : body["buffers"])
      if (b["name"] == name) return b["bytes"].get<long long>();
    return -1;
  };
  EXPECT_EQ(bytesOf(dev, "element_nodes"), 16 * 400);
  EXPECT_EQ(bytesOf(dev, "positions"), 3 * 189 * 8);
  EXPECT_EQ(bytesOf(dev, "rotated_gradients"), 9 * 400 * 8);
  EXPECT_EQ(bytesOf(dev, "rotations"), -1) << "the polar method's kernels never read R";
  scene.solver.precision = Precision::Float;
  const std::vector<json> pf = plans(scene);
  ASSERT_EQ(pf.size(), 2u);
  EXPECT_EQ(bytesOf(pf[1], "positions"), 3 * 189 * 4);
  EXPECT_EQ(pf[1]["features"]["precision"], "float");
  EXPECT_EQ(pf[0]["features"]["precision"], "double");  // the reference backend computes in double
  // Linear formulation: no rotations.
  scene.bodies[0].formulation = Formulation::Linear;
  for (const json& b : plans(scene)) EXPECT_FALSE(anyBufferContains(b, "rotation")) << b["buffers"].dump(1);
}

// On a real OpenCL device the plan also lists what the backend allocated, buffer by buffer (the
// engine's own list, each at its clCreateBuffer size): only what the scene reads.
TEST(Plan, DeviceBuffersAllocatedAreListedAndOnlyWhatTheSceneReads) {
  if (!haveOpenCL()) GTEST_SKIP() << "no OpenCL device (or built without COROFEM_WITH_OPENCL)";
  HookScope scope;
  auto allocated = [](const Scene& scene) {
    auto sim = Simulation::create(scene);
    EXPECT_TRUE(sim) << sim.message();
    return sim ? json::parse(sim->planReport()) : json();
  };
  auto names = [](const json& list) {
    std::set<std::string> out;
    for (const auto& b : list) out.insert(b["name"].get<std::string>());
    return out;
  };
  auto total = [](const json& list) {
    long long sum = 0;
    for (const auto& b : list) sum += b["bytes"].get<long long>();
    return sum;
  };
  Scene stat = staticScene(boxBeam(), 1), dyn = dynamicScene(boxBeam(), 2);
  for (Scene* sc : {&stat, &dyn}) {
    sc->backend.kind = BackendKind::OpenCL;
    sc->solver.precision = Precision::Float;
  }
  const json ps = allocated(stat), pd = allocated(dyn);
  ASSERT_FALSE(ps.is_null() || pd.is_null());
  const json& bs = ps["bodies"][0];
  const json& bd = pd["bodies"][0];
  ASSERT_TRUE(bs.contains("device_buffers_allocated")) << bs.dump(1);
  ASSERT_TRUE(bd.contains("device_buffers_allocated")) << bd.dump(1);
  EXPECT_EQ(total(bs["device_buffers_allocated"]), bs["device_bytes_allocated"].get<long long>());
  EXPECT_EQ(total(bd["device_buffers_allocated"]), bd["device_bytes_allocated"].get<long long>());
  const std::set<std::string> s = names(bs["device_buffers_allocated"]), d = names(bd["device_buffers_allocated"]);
  EXPECT_EQ(s.count("lumped_mass"), 0u) << "a static scene allocates no mass";
  EXPECT_EQ(d.count("lumped_mass"), 1u);
  EXPECT_EQ(d.size(), s.size() + 1) << "the mass buffer is all a dynamic scene adds";
  EXPECT_EQ(s.count("quaternions") + s.count("stored_stiffness_Ke"), 0u) << "not used by this scene";
  // The polar method's kernels read the rotated gradients a_i, never R itself.
  EXPECT_EQ(d.count("rotated_gradients"), 1u);
  EXPECT_EQ(d.count("rotations"), 0u) << "R is read by no kernel of this scene";
  // 400 float elements padded to 512 (WG 64 x 8 per work-item on CPUs, 64 x 1 on GPUs: 448), 189 nodes.
  long long positions = -1;
  for (const auto& b : bd["device_buffers_allocated"])
    if (b["name"] == "positions") positions = b["bytes"].get<long long>();
  EXPECT_GE(positions, 3 * 189 * 4);
  // The quaternion method adds exactly its warm-start buffer and R (which its passes always write:
  // one cannot be run again to read R back, it advances the warm start).
  Scene quatScene = dyn;
  quatScene.solver.rotation = RotationMethod::Quaternion;
  const json pq = allocated(quatScene);
  ASSERT_FALSE(pq.is_null());
  const std::set<std::string> q = names(pq["bodies"][0]["device_buffers_allocated"]);
  EXPECT_EQ(q.size(), d.size() + 2);
  EXPECT_EQ(q.count("quaternions"), 1u);
  EXPECT_EQ(q.count("rotations"), 1u);
  // The linear formulation rotates nothing: no R, and its kernels read the rest gradients in
  // element_geometry instead of a copy.
  Scene linearScene = dyn;
  linearScene.bodies[0].formulation = Formulation::Linear;
  const json pl = allocated(linearScene);
  ASSERT_FALSE(pl.is_null());
  const std::set<std::string> l = names(pl["bodies"][0]["device_buffers_allocated"]);
  EXPECT_EQ(l.size(), d.size() - 1);
  EXPECT_EQ(l.count("rotated_gradients") + l.count("rotations"), 0u);
  // Nor with the Quaternion method named: a linear body has no rotations to warm-start.
  linearScene.solver.rotation = RotationMethod::Quaternion;
  const json plq = allocated(linearScene);
  ASSERT_FALSE(plq.is_null());
  EXPECT_EQ(names(plq["bodies"][0]["device_buffers_allocated"]), l);
  // Two bodies sharing the device: their buffers are the batch's, listed once, summing to its total.
  Scene two = dynamicScene(boxBeam(), 2);
  two.bodies.push_back(boxBeam({8, 2, 2}));
  two.bodies[1].name = "second";
  two.backend.kind = BackendKind::OpenCL;
  two.solver.precision = Precision::Float;
  const json p2 = allocated(two);
  ASSERT_FALSE(p2.is_null());
  ASSERT_EQ(p2["batches"].size(), 1u) << p2.dump(1);
  EXPECT_EQ(total(p2["batches"][0]["buffers"]), p2["batches"][0]["allocated_bytes"].get<long long>());
  EXPECT_FALSE(p2["bodies"][0].contains("device_buffers_allocated"));
}

TEST(Plan, DeviceNumberingIsTheMeshsForABoxAndMortonForAMeshFile) {
  // The OpenCL backend lays a body out in a Morton order of its own where the mesh's numbering is
  // less local (mesh/locality_order.hpp): a Gmsh file's is, the box generator's is not.
  if (!haveOpenCL()) GTEST_SKIP() << "no OpenCL device (or built without COROFEM_WITH_OPENCL)";
  if (mortonEverywhere()) GTEST_SKIP() << "--corofem_morton lays every body out in Morton order";
  COROFEM_REQUIRE_DATA("meshes/ipc/bar-2523.msh");
  HookScope scope;
  Scene box = dynamicScene(boxBeam({20, 4, 4}), 1), file = box;
  file.bodies[0].mesh.box.reset();
  file.bodies[0].mesh.file = dataPath("meshes/ipc/bar-2523.msh");  // 10 x 0.5 x 1: the clamp at x = 0 holds
  file.bodies[0].loads[1].nodes.planePoint = {10, 0, 0};             // the tip load at its end
  for (Scene* sc : {&box, &file}) sc->backend.kind = BackendKind::OpenCL;
  for (auto [scene, numbering] : {std::pair{&box, std::string("mesh")}, std::pair{&file, std::string("morton")}}) {
    auto sim = Simulation::create(*scene);
    ASSERT_TRUE(sim) << sim.message();
    const json plan = json::parse(sim->planReport());
    EXPECT_EQ(plan["bodies"][0].value("device_numbering", std::string()), numbering) << plan["bodies"][0].dump(1);
  }
  Scene ref = box;
  ref.backend.kind = BackendKind::Reference;
  auto sim = Simulation::create(ref);
  ASSERT_TRUE(sim) << sim.message();
  EXPECT_FALSE(json::parse(sim->planReport())["bodies"][0].contains("device_numbering")) << "host backends have none";
}

// `corofem run --plan` prints the plan and runs nothing (no output folder).
TEST(Plan, CommandPrintsThePlanWithoutRunning) {
  const std::string cli = COROFEM_CLI_PATH;
  if (cli.empty()) GTEST_SKIP() << "the corofem command is not built";
  const auto dir = tempDir();
  const std::string scene = (dir / "s.json").string();
  std::ofstream(scene) << R"({"name": "p", "bodies": [{"mesh": {"box": {"cells": [4, 2, 2]}},
      "fixed": [{"box": {"min": [0, 0, 0], "max": [0, 1, 1]}}]}],
      "analysis": {"type": "static"}, "backend": "auto"})";
  const std::string out = (dir / "out").string();
  const std::string jsonPath = (dir / "plan.json").string();
  const std::string cmd = "COROFEM_CACHE_DIR=" + dir.string() + " " + cli + " run " + scene + " --plan --json --out " +
                          out + " > " + jsonPath;
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  EXPECT_FALSE(std::filesystem::exists(out));
  std::ifstream in(jsonPath);
  const json plan = json::parse(in);
  ASSERT_EQ(plan["bodies"].size(), 1u);
  EXPECT_EQ(plan["analysis"], "static");
  EXPECT_FALSE(anyBufferContains(plan["bodies"][0], "velocit"));
  // The text form names the backend and the buffers.
  const std::string textPath = (dir / "plan.txt").string();
  ASSERT_EQ(std::system((cli + " run " + scene + " --plan > " + textPath).c_str()), 0);
  std::ifstream tin(textPath);
  const std::string text((std::istreambuf_iterator<char>(tin)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("buffers"), std::string::npos) << text;
  EXPECT_NE(text.find("on reference"), std::string::npos) << text;  // 80 elements: the reference
}

// summary.json of a run has the scheduler's decision.
TEST(Plan, RunSummaryHasTheScheduler) {
  const std::string cli = COROFEM_CLI_PATH;
  if (cli.empty()) GTEST_SKIP() << "the corofem command is not built";
  const auto dir = tempDir();
  const std::string scene = (dir / "s.json").string();
  std::ofstream(scene) << R"({"name": "p", "bodies": [{"mesh": {"box": {"cells": [4, 2, 2]}},
      "fixed": [{"box": {"min": [0, 0, 0], "max": [0, 1, 1]}}]}],
      "analysis": {"type": "dynamic", "steps": 2}, "output": {"vtk": false}})";
  const std::string out = (dir / "out").string();
  const std::string cmd = "COROFEM_CACHE_DIR=" + dir.string() + " " + cli + " run " + scene + " --quiet --out " + out;
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::ifstream in(out + "/summary.json");
  const json s = json::parse(in);
  ASSERT_TRUE(s.contains("scheduler")) << s.dump(1);
  for (const char* k : {"choice", "reason", "candidates", "from_cache"}) EXPECT_TRUE(s["scheduler"].contains(k)) << k;
  EXPECT_EQ(s["scheduler"]["choice"], "reference");
  EXPECT_TRUE(s["fallbacks"].empty());
}


TEST(AutoPreconditioner, AmgForLargeSlenderCorotationalOrLinearBodiesDiagonalElsewhere) {
  // The rule (docs/performance.md, "The default preconditioner"): amg measured faster from about
  // 3,000 elements on slender bodies, slower on compact ones (the Armadillo, 3.8) and on small
  // ones; the rigorous models keep the diagonal.
  SolverDesc s;
  ASSERT_EQ(s.preconditioner, PreconditionerKind::Auto);
  const double beam = 10.0, armadillo = 3.8;
  EXPECT_EQ(preconditionerOf(s, kAutoAmgElements, kAutoAmgSlenderness, Formulation::Corotational), PreconditionerKind::Amg);
  EXPECT_EQ(preconditionerOf(s, 12960, beam, Formulation::Linear), PreconditionerKind::Amg);
  EXPECT_EQ(preconditionerOf(s, kAutoAmgElements - 1, beam, Formulation::Corotational), PreconditionerKind::Diagonal);
  EXPECT_EQ(preconditionerOf(s, 54985, armadillo, Formulation::Corotational), PreconditionerKind::Diagonal);
  EXPECT_EQ(preconditionerOf(s, 12960, beam, Formulation::NeoHookean), PreconditionerKind::Diagonal);
  EXPECT_EQ(preconditionerOf(s, 12960, beam, Formulation::StVenantKirchhoff), PreconditionerKind::Diagonal);
  s.linearSolver = LinearSolverKind::Cholesky;
  EXPECT_EQ(preconditionerOf(s, 12960, beam, Formulation::Corotational), PreconditionerKind::Diagonal);
  s.linearSolver = LinearSolverKind::Pcg;
  s.preconditioner = PreconditionerKind::BlockDiagonal;  // a choice the scene makes stays
  EXPECT_EQ(preconditionerOf(s, 12960, beam, Formulation::Corotational), PreconditionerKind::BlockDiagonal);

  // Slenderness from the rest mesh: L / sqrt(V / L) of a 1 x 0.1 x 0.1 beam is 10, of a cube 1.
  const detail::Problem longBeam = makeProblem(cellBox(40, 4, 4, 1.0 / 40, 0.1 / 4, 0.1 / 4));  // cell sizes
  const detail::Problem cube = makeProblem(cellBox(16, 16, 16, 0.1, 0.1, 0.1));
  const detail::Problem small = makeProblem(cellBox(10, 2, 2, 1.0 / 10, 0.1 / 2, 0.1 / 2));
  EXPECT_NEAR(detail::slendernessOf(longBeam), 10.0, 1e-9);
  EXPECT_NEAR(detail::slendernessOf(cube), 1.0, 1e-9);
  ASSERT_GE(longBeam.mesh.tetCount(), kAutoAmgElements);
  ASSERT_GE(cube.mesh.tetCount(), kAutoAmgElements);
  EXPECT_EQ(detail::preconditionerOf(SolverDesc{}, longBeam), PreconditionerKind::Amg);
  EXPECT_EQ(detail::preconditionerOf(SolverDesc{}, cube), PreconditionerKind::Diagonal);
  // A device of several bodies gets amg only where every body would alone.
  EXPECT_EQ(detail::resolvedSolver(SolverDesc{}, {&longBeam, &longBeam}).preconditioner, PreconditionerKind::Amg);
  EXPECT_EQ(detail::resolvedSolver(SolverDesc{}, {&longBeam, &small}).preconditioner, PreconditionerKind::Diagonal);
}

TEST(AutoPreconditioner, ThePlanSaysWhatEachBodyGotAndBatchesDoNotMixThem) {
  // Two small cantilevers and a large one on one (fake) device that batches: the small ones batch
  // together with the diagonal, the large one runs alone with amg; each plan says which and that
  // "auto" chose it.
  std::vector<detail::BackendEntry> fakes;
  fakes.push_back(fakeBackend("opencl", {fakeCandidate("opencl", "fake-gpu", "0", true)},
                              [](const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                                 const detail::Candidate&) { return detail::createReferenceDevice(problems, s); },
                              /*batches=*/true));
  HookScope scope(std::move(fakes));
  Scene scene;
  scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.steps = 2;
  for (const auto& [name, cells] : std::vector<std::pair<std::string, std::array<int, 3>>>{
           {"small1", {12, 3, 3}}, {"large", {40, 4, 4}}, {"small2", {12, 3, 3}}}) {
    BodyDesc b;
    b.name = name;
    BoxSpec box;
    box.min = {0.0, 0.0, 0.0};
    box.max = {1.0, 0.1, 0.1};
    box.cells = cells;
    b.mesh.box = box;
    NodeSetDesc clamp;
    clamp.boxMin = {-1e-9, -1.0, -1.0};
    clamp.boxMax = {1e-9, 1.0, 1.0};
    b.fixed.push_back(clamp);
    scene.bodies.push_back(b);
  }
  scene.backend.minDeviceElements = 0;
  SimulationOptions options;
  options.devices = {"opencl"};
  auto sim = Simulation::create(scene, options);
  ASSERT_TRUE(sim) << sim.message();
  const json plan = json::parse(sim->planReport());
  ASSERT_EQ(plan["bodies"].size(), 3u);
  for (const json& b : plan["bodies"]) {
    const bool large = b["body"] == "large";
    EXPECT_EQ(b["features"]["preconditioner"], large ? "amg" : "diagonal") << b.dump();
    EXPECT_EQ(b["features"]["preconditioner_chosen_by"], "auto");
  }
  ASSERT_EQ(plan["batches"].size(), 1u) << plan["batches"].dump();
  EXPECT_EQ(plan["batches"][0]["bodies"], json({"small1", "small2"}));
  ASSERT_EQ(plan["unbatched"].size(), 1u) << plan["unbatched"].dump();  // and says why the large one is not in it
  EXPECT_EQ(plan["unbatched"][0]["bodies"], json({"large"}));
  EXPECT_NE(plan["unbatched"][0]["reason"].get<std::string>().find("preconditioner \"amg\""), std::string::npos);
  ASSERT_TRUE(sim->step());
}

}  // namespace
}  // namespace corofem::test
