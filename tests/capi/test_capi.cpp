// The C API (corofem/corofem.h) against the C++ API it wraps: the same scene driven through both
// with every run-time control call gives the same state bit for bit, frame by frame; the render
// surface reads back as Simulation::readSurface gives it (and on OpenCL from a device buffer in the
// application's own context); every entry point refuses a NULL handle with BadInput naming
// itself; the last error is the calling thread's; and libcorofem_c exports every function the
// header declares and none of the C++ library's symbols. (tests/capi_c/capi_test.c drives the
// API from C.)
#include <corofem/corofem.h>
#include <corofem/simulation.hpp>

#include "common/box_surface.hpp"
#include "common/test_data.hpp"

#include <gtest/gtest.h>

#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/cl_context.hpp"
#endif
#ifdef COROFEM_WITH_VULKAN
#include "common/vulkan_app.hpp"
#endif
#ifdef COROFEM_C_LIBRARY
#include <dlfcn.h>
#endif

#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace corofem::test {
namespace {

/// The closed surface of the box [lo, hi] as an OBJ: each face 2 x 2 quads, split in triangles.
void writeBoxSurface(const std::string& path, const std::array<double, 3>& lo, const std::array<double, 3>& hi) {
  ASSERT_TRUE(writeSurfaceMesh(path, boxSurface(lo, hi, 2)));
}

/// Two bodies at 60 Hz, backward Euler: a clamped beam under gravity with a render surface
/// ("box.obj" in the scene's folder), and a free block beside it.
std::string twoBodies(const std::string& backend, const std::string& layout = "interleaved") {
  return R"({"bodies": [
    {"name": "beam", "mesh": {"box": {"min": [0, 0, 0], "max": [0.5, 0.1, 0.1], "cells": [10, 2, 2]}},
     "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3, "density": 1000},
     "fixed": [{"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}}],
     "loads": [{"type": "gravity", "vector": [0, -9.81, 0]}],
     "surface": "box.obj", "surface_layout": ")" + layout + R"("},
    {"name": "block", "mesh": {"box": {"min": [1, 0, 0], "max": [1.2, 0.1, 0.1], "cells": [2, 1, 1]}},
     "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3, "density": 1000}}],
   "analysis": {"type": "dynamic", "integrator": "backward_euler", "time_step": 0.016666666666666666, "steps": 50},
   "solver": {"tolerance": 1e-10, "max_iterations": 2000},
   "backend": ")" + backend + R"("})";
}

std::string message() { return corofem_last_error_message(); }

/// The C API's handles, freed with the test.
struct CSim {
  corofem_simulation* sim = nullptr;
  ~CSim() { corofem_simulation_destroy(sim); }
};
struct CScene {
  corofem_scene* scene = nullptr;
  ~CScene() { corofem_scene_destroy(scene); }
};

CSim createC(const std::string& json, const std::string& dir, const corofem_options* options = nullptr) {
  CScene scene;
  CSim sim;
  EXPECT_EQ(corofem_scene_parse(json.c_str(), dir.c_str(), nullptr, 0, &scene.scene), COROFEM_OK) << message();
  if (scene.scene) EXPECT_EQ(corofem_simulation_create(scene.scene, options, &sim.sim), COROFEM_OK) << message();
  return sim;
}

Simulation createCpp(const std::string& json, const std::string& dir, const SimulationOptions& options = {}) {
  Result<Scene> scene = parseScene(json, dir);
  if (!scene) throw std::runtime_error(scene.message());
  Result<Simulation> sim = Simulation::create(scene.value(), options);
  if (!sim) throw std::runtime_error(sim.message());
  return std::move(sim.value());
}

std::vector<double> positionsC(const corofem_simulation* sim, int body) {
  std::size_t needed = 0;
  EXPECT_EQ(corofem_simulation_read_positions(sim, body, nullptr, 0, &needed), COROFEM_OK) << message();
  std::vector<double> x(needed);
  EXPECT_EQ(corofem_simulation_read_positions(sim, body, x.data(), x.size(), &needed), COROFEM_OK) << message();
  return x;
}
std::vector<double> velocitiesC(const corofem_simulation* sim, int body) {
  std::size_t needed = 0;
  EXPECT_EQ(corofem_simulation_read_velocities(sim, body, nullptr, 0, &needed), COROFEM_OK) << message();
  std::vector<double> v(needed);
  EXPECT_EQ(corofem_simulation_read_velocities(sim, body, v.data(), v.size(), &needed), COROFEM_OK) << message();
  return v;
}

#define C_OK(call) ASSERT_EQ((call), COROFEM_OK) << #call << ": " << message()
#define CPP_OK(call)                      \
  do {                                    \
    const Status st_ = (call);            \
    ASSERT_TRUE(st_) << #call << ": " << st_.message(); \
  } while (0)

TEST(CApi, EveryControlCallLeavesTheStateTheCppApiLeaves) {
  const std::string dir = tempDir().string();
  writeBoxSurface(dir + "/box.obj", {0.02, 0.02, 0.02}, {0.48, 0.08, 0.08});
  const std::string json = twoBodies("reference");
  CSim c = createC(json, dir);
  ASSERT_NE(c.sim, nullptr);
  Simulation cpp = createCpp(json, dir);
  const TetMesh& beam = cpp.restMesh(0);
  std::vector<std::uint32_t> tip, middle;
  for (std::uint32_t n = 0; n < beam.nodeCount(); ++n) {
    if (std::abs(beam.nodes[3 * n] - 0.5) < 1e-9) tip.push_back(n);
    if (std::abs(beam.nodes[3 * n] - 0.25) < 1e-9) middle.push_back(n);
  }
  ASSERT_EQ(tip.size(), 9u);
  const double c10 = std::cos(0.2), s10 = std::sin(0.2);
  const double rotX[9] = {1, 0, 0, 0, c10, -s10, 0, s10, c10};
  const double rotZ[9] = {0, -1, 0, 1, 0, 0, 0, 0, 1};

  int frame = 0;
  auto stepBoth = [&](const char* what) {
    ++frame;
    SCOPED_TRACE(std::string("frame ") + std::to_string(frame) + ", after " + what);
    corofem_step_report rc{};
    StepReport rp;
    ASSERT_EQ(corofem_simulation_step_dt(c.sim, 1.0 / 60.0, &rc), COROFEM_OK) << message();
    CPP_OK(cpp.step(1.0 / 60.0, &rp));
    EXPECT_EQ(rc.step, rp.step);
    EXPECT_EQ(rc.time, rp.time);
    EXPECT_EQ(rc.newton_iterations, rp.newtonIterations);
    EXPECT_EQ(rc.linear_iterations, rp.linearIterations);
    EXPECT_EQ(rc.residual, rp.residual);
    EXPECT_EQ(rc.linear_residual, rp.linearResidual);
    EXPECT_EQ(rc.converged, rp.converged ? 1 : 0);
    for (int b = 0; b < 2; ++b) {
      std::vector<double> x, v;
      CPP_OK(cpp.readPositions(b, x));
      CPP_OK(cpp.readVelocities(b, v));
      EXPECT_EQ(positionsC(c.sim, b), x) << "body " << b;
      EXPECT_EQ(velocitiesC(c.sim, b), v) << "body " << b;
      corofem_energies e{};
      ASSERT_EQ(corofem_simulation_energies(c.sim, b, &e), COROFEM_OK);
      EXPECT_EQ(e.kinetic, cpp.energies(b).kinetic);
      EXPECT_EQ(e.elastic, cpp.energies(b).elastic);
      EXPECT_EQ(e.external_work, cpp.energies(b).externalWork);
    }
  };

  // A handle on the tip, lifted and twisted.
  int hc = 0;
  C_OK(corofem_simulation_add_handle_nodes(c.sim, 0, tip.data(), tip.size(), &hc));
  HandleDesc tipHandle;
  tipHandle.nodes = tip;
  Result<int> hp = cpp.addHandle(tipHandle);
  ASSERT_TRUE(hp) << hp.message();
  EXPECT_EQ(hc, hp.value());
  const double lifted[3] = {0.5, 0.08, 0.05};
  C_OK(corofem_simulation_move_handle(c.sim, hc, lifted, rotX));
  CPP_OK(cpp.moveHandle(hp.value(), lifted, rotX));
  stepBoth("a handle moved and turned");

  // A handle at a point of the block, with a radius.
  const double corner[3] = {1.2, 0.1, 0.1}, pulled[3] = {1.25, 0.12, 0.1};
  int gc = 0;
  C_OK(corofem_simulation_add_handle_point(c.sim, 1, corner, 0.06, &gc));
  HandleDesc pointHandle;
  pointHandle.body = 1;
  std::copy(corner, corner + 3, pointHandle.point);
  pointHandle.radius = 0.06;
  Result<int> gp = cpp.addHandle(pointHandle);
  ASSERT_TRUE(gp) << gp.message();
  C_OK(corofem_simulation_move_handle(c.sim, gc, pulled, nullptr));
  CPP_OK(cpp.moveHandle(gp.value(), pulled));
  stepBoth("a handle at a point");
  C_OK(corofem_simulation_set_handle_stiffness(c.sim, gc, 300.0));
  CPP_OK(cpp.setHandleStiffness(gp.value(), 300.0));
  stepBoth("the point's handle made a spring");

  // Pins and forces at a node and at a point.
  C_OK(corofem_simulation_pin_nodes(c.sim, 0, middle.data(), middle.size()));
  CPP_OK(cpp.pinNodes(0, middle));
  corofem_force fc[2] = {};
  fc[0].node = static_cast<int>(tip[4]);
  fc[0].force[2] = 3.0;
  fc[1].node = -1;
  fc[1].point[0] = 0.4;
  fc[1].point[1] = 0.05;
  fc[1].point[2] = 0.05;
  fc[1].force[0] = -2.0;
  fc[1].force[1] = 1.0;
  C_OK(corofem_simulation_set_forces(c.sim, 0, fc, 2));
  std::vector<AppliedForce> fp(2);
  fp[0].node = fc[0].node;
  fp[0].force[2] = 3.0;
  fp[1].node = -1;
  std::copy(fc[1].point, fc[1].point + 3, fp[1].point);
  std::copy(fc[1].force, fc[1].force + 3, fp[1].force);
  CPP_OK(cpp.setForces(0, fp));
  stepBoth("pins and forces");

  // Unpinned, under another gravity, the clamp released.
  const std::vector<std::uint32_t> clamp = {0, 1, 2};
  C_OK(corofem_simulation_unpin_nodes(c.sim, 0, middle.data(), middle.size()));
  CPP_OK(cpp.unpinNodes(0, middle));
  C_OK(corofem_simulation_unpin_nodes(c.sim, 0, clamp.data(), clamp.size()));
  CPP_OK(cpp.unpinNodes(0, clamp));
  const double g[3] = {0.0, 0.0, -5.0};
  C_OK(corofem_simulation_set_gravity(c.sim, g));
  CPP_OK(cpp.setGravity(g));
  stepBoth("unpinned, another gravity");

  // The block released, spun, moved rigidly.
  C_OK(corofem_simulation_remove_handle(c.sim, gc));
  CPP_OK(cpp.removeHandle(gp.value()));
  std::vector<double> spin = positionsC(c.sim, 1);
  for (std::size_t n = 0; n < spin.size() / 3; ++n) {
    const double x = spin[3 * n] - 1.1, y = spin[3 * n + 1] - 0.05;
    spin[3 * n] = -2.0 * y;
    spin[3 * n + 1] = 2.0 * x;
    spin[3 * n + 2] = 0.1;
  }
  C_OK(corofem_simulation_set_velocities(c.sim, 1, spin.data(), spin.size()));
  CPP_OK(cpp.setVelocities(1, spin));
  const double away[3] = {0.5, -0.2, 0.3};
  C_OK(corofem_simulation_teleport(c.sim, 1, rotZ, away));
  CPP_OK(cpp.teleport(1, rotZ, away));
  stepBoth("spun and teleported");

  // Positions set; forces removed; the block back at rest.
  std::vector<double> bent = positionsC(c.sim, 0);
  for (std::size_t i = 1; i < bent.size(); i += 3) bent[i] += 0.001 * bent[i - 1];
  C_OK(corofem_simulation_set_positions(c.sim, 0, bent.data(), bent.size()));
  CPP_OK(cpp.setPositions(0, bent));
  C_OK(corofem_simulation_set_forces(c.sim, 0, nullptr, 0));
  CPP_OK(cpp.setForces(0, {}));
  C_OK(corofem_simulation_reset_body(c.sim, 1));
  CPP_OK(cpp.resetBody(1));
  stepBoth("positions set, forces removed, a body reset");
  C_OK(corofem_simulation_step(c.sim, nullptr));
  CPP_OK(cpp.step());
  stepBoth("the scene's own time step");

  // The surface reads back as the C++ API gives it (host path: exact).
  std::size_t vertices = 0, triangles = 0, needed = 0;
  C_OK(corofem_simulation_surface_size(c.sim, 0, &vertices, &triangles));
  ASSERT_EQ(vertices, cpp.restSurface(0)->vertexCount());
  ASSERT_EQ(triangles, cpp.restSurface(0)->triangleCount());
  std::vector<std::uint32_t> tris(3 * triangles);
  C_OK(corofem_simulation_read_surface_triangles(c.sim, 0, tris.data(), tris.size(), &needed));
  EXPECT_EQ(tris, cpp.restSurface(0)->triangles);
  std::vector<double> p(3 * vertices), pp;
  std::vector<float> n(3 * vertices), np;
  C_OK(corofem_simulation_read_surface(c.sim, 0, p.data(), p.size(), n.data(), n.size(), &needed));
  EXPECT_EQ(needed, 3 * vertices);
  CPP_OK(cpp.readSurface(0, pp, &np));
  EXPECT_EQ(p, pp);
  EXPECT_EQ(n, np);
  std::vector<double> positionsOnly(3 * vertices);
  C_OK(corofem_simulation_read_surface(c.sim, 0, positionsOnly.data(), positionsOnly.size(), nullptr, 0, nullptr));
  EXPECT_EQ(positionsOnly, pp);
  EXPECT_EQ(corofem_simulation_read_surface(c.sim, 0, p.data(), p.size(), n.data(), 5, &needed), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("normals holds 5 floats"), std::string::npos) << message();
}

/// A step whose solve fails is COROFEM_SOLVE_FAILED with its report filled, the state kept, and not
/// terminal: a force of 1e300 N on a corner node makes the step's forces overflow; taken away, the
/// beam steps on.
TEST(CApi, AFailedStepIsSolveFailedAndTheNextStepGoesOn) {
  const std::string dir = tempDir().string();
  writeBoxSurface(dir + "/box.obj", {0.02, 0.02, 0.02}, {0.48, 0.08, 0.08});
  CSim c = createC(twoBodies("reference"), dir);
  ASSERT_NE(c.sim, nullptr);
  const std::vector<double> before = positionsC(c.sim, 0);
  corofem_force huge{};
  huge.node = 10;  // (0.5, 0, 0)
  huge.force[1] = 1e300;
  C_OK(corofem_simulation_set_forces(c.sim, 0, &huge, 1));
  corofem_step_report report{};
  report.converged = 1;
  EXPECT_EQ(corofem_simulation_step_dt(c.sim, 1.0 / 60.0, &report), COROFEM_SOLVE_FAILED) << message();
  EXPECT_EQ(corofem_last_status(), COROFEM_SOLVE_FAILED);
  EXPECT_NE(message().find("non-finite"), std::string::npos) << message();
  EXPECT_EQ(report.converged, 0);
  EXPECT_GT(report.wall_seconds, 0.0);
  int steps = -1;
  C_OK(corofem_simulation_steps_taken(c.sim, &steps));
  EXPECT_EQ(steps, 0);
  EXPECT_EQ(positionsC(c.sim, 0), before);  // the state before the step
  C_OK(corofem_simulation_set_forces(c.sim, 0, nullptr, 0));
  C_OK(corofem_simulation_step_dt(c.sim, 1.0 / 60.0, &report));
  C_OK(corofem_simulation_steps_taken(c.sim, &steps));
  double time = 0;
  C_OK(corofem_simulation_time(c.sim, &time));
  EXPECT_EQ(steps, 1);
  EXPECT_EQ(time, 1.0 / 60.0);
  EXPECT_EQ(report.step, 1);
  EXPECT_EQ(report.converged, 1);
}

TEST(CApi, AStaticAnalysisRefusesControlAndATimeStep) {
  const std::string json = R"({"bodies": [{"mesh": {"box": {"max": [0.4, 0.1, 0.1], "cells": [4, 1, 1]}},
      "fixed": [{"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}}],
      "loads": [{"type": "gravity"}]}], "analysis": {"type": "static", "increments": 2}, "backend": "reference"})";
  CScene scene;
  C_OK(corofem_scene_parse(json.c_str(), "", nullptr, 0, &scene.scene));
  EXPECT_EQ(corofem_scene_set_step_count(scene.scene, 0), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("static analysis takes >= 1 load increments"), std::string::npos) << message();
  C_OK(corofem_scene_set_step_count(scene.scene, 3));
  CSim sim;
  C_OK(corofem_simulation_create(scene.scene, nullptr, &sim.sim));
  int steps = 0, finished = 1;
  C_OK(corofem_simulation_step_count(sim.sim, &steps));
  EXPECT_EQ(steps, 3);
  const std::uint32_t node = 5;
  int handle = 0;
  EXPECT_EQ(corofem_simulation_add_handle_nodes(sim.sim, 0, &node, 1, &handle), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("run-time control acts on a dynamic analysis"), std::string::npos) << message();
  EXPECT_EQ(handle, 0);  // not written on failure
  EXPECT_EQ(corofem_simulation_step_dt(sim.sim, 0.01, nullptr), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("call step() instead"), std::string::npos) << message();
  for (int k = 1; k <= 3; ++k) C_OK(corofem_simulation_step(sim.sim, nullptr));
  C_OK(corofem_simulation_finished(sim.sim, &finished));
  EXPECT_EQ(finished, 1);
  double time = 0;
  C_OK(corofem_simulation_time(sim.sim, &time));
  EXPECT_EQ(time, 1.0);
  EXPECT_EQ(corofem_simulation_step(sim.sim, nullptr), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("the analysis is finished"), std::string::npos) << message();
}

TEST(CApi, TheOptionsAreChecked) {
  const std::string dir = tempDir().string();
  writeBoxSurface(dir + "/box.obj", {0.02, 0.02, 0.02}, {0.48, 0.08, 0.08});
  CScene scene;
  C_OK(corofem_scene_parse(twoBodies("auto").c_str(), dir.c_str(), nullptr, 0, &scene.scene));
  CSim sim;
  corofem_options o = corofem_default_options();
  EXPECT_EQ(o.devices, nullptr);
  EXPECT_EQ(o.device_count, 0u);
  EXPECT_EQ(o.device.api, COROFEM_GPU_NONE);
  o.device_count = 1;
  EXPECT_EQ(corofem_simulation_create(scene.scene, &o, &sim.sim), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("options->devices is NULL"), std::string::npos) << message();
  const char* devices[2] = {"reference", nullptr};
  o.devices = devices;
  o.device_count = 2;
  EXPECT_EQ(corofem_simulation_create(scene.scene, &o, &sim.sim), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("options->devices[1] is NULL"), std::string::npos) << message();
  o = corofem_default_options();
  o.device.api = static_cast<corofem_gpu_api>(7);
  EXPECT_EQ(corofem_simulation_create(scene.scene, &o, &sim.sim), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("options->device.api is 7"), std::string::npos) << message();
  devices[0] = "auto";
  o = corofem_default_options();
  o.devices = devices;
  o.device_count = 1;
  EXPECT_EQ(corofem_simulation_create(scene.scene, &o, &sim.sim), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("\"auto\" cannot be part of an order"), std::string::npos) << message();
  EXPECT_EQ(sim.sim, nullptr);
  devices[0] = "reference";
  C_OK(corofem_simulation_create(scene.scene, &o, &sim.sim));
  char backend[16];
  C_OK(corofem_simulation_backend_name(sim.sim, backend, sizeof backend, nullptr));
  EXPECT_STREQ(backend, "reference");

  // The surface file is looked for in the scene's folder, the base_dir given to corofem_scene_parse.
  CScene elsewhere;
  CSim none;
  C_OK(corofem_scene_parse(twoBodies("reference").c_str(), (dir + "/elsewhere").c_str(), nullptr, 0, &elsewhere.scene));
  EXPECT_EQ(corofem_simulation_create(elsewhere.scene, nullptr, &none.sim), COROFEM_IO_ERROR);
  EXPECT_NE(message().find(dir + "/elsewhere/box.obj"), std::string::npos) << message();
  EXPECT_EQ(none.sim, nullptr);
}

/// The input limits (corofem_input_limits, corofem::InputLimits): the defaults are the C++ API's, a
/// zeroed field takes its default, and each limit holds where the C++ one does, in the scene calls
/// and in a simulation's options (creation and added bodies), with messages naming the C field.
TEST(CApi, TheInputLimitsHoldAndCanBeRaised) {
  const InputLimits cpp;
  const corofem_input_limits defaults = corofem_default_input_limits();
  EXPECT_EQ(defaults.max_input_bytes, cpp.maxInputBytes);
  EXPECT_EQ(defaults.max_scene_bytes, cpp.maxSceneBytes);
  EXPECT_EQ(defaults.max_box_tets, cpp.maxBoxTets);
  const corofem_options options = corofem_default_options();
  EXPECT_EQ(options.limits.max_input_bytes, cpp.maxInputBytes);
  EXPECT_EQ(options.limits.max_scene_bytes, cpp.maxSceneBytes);
  EXPECT_EQ(options.limits.max_box_tets, cpp.maxBoxTets);

  const std::string dir = tempDir().string();
  writeBoxSurface(dir + "/box.obj", {0.02, 0.02, 0.02}, {0.48, 0.08, 0.08});  // over 1 KiB
  const std::string json = twoBodies("reference");  // boxes of 200 and 10 tetrahedra
  // Parsing: a box over max_box_tets.
  corofem_input_limits limits{};  // zeroed: the defaults
  CScene scene;
  C_OK(corofem_scene_parse_with_limits(json.c_str(), dir.c_str(), nullptr, 0, &limits, &scene.scene));
  limits.max_box_tets = 199;
  corofem_scene* refused = nullptr;
  EXPECT_EQ(corofem_scene_parse_with_limits(json.c_str(), dir.c_str(), nullptr, 0, &limits, &refused),
            COROFEM_BAD_INPUT);
  EXPECT_EQ(refused, nullptr);
  EXPECT_EQ(message().rfind("corofem_scene_parse_with_limits: ", 0), 0u) << message();
  EXPECT_NE(message().find("give 200 tetrahedra, more than the limit of 199 (InputLimits::maxBoxTets)"),
            std::string::npos)
      << message();
  EXPECT_NE(message().find("corofem_input_limits.max_box_tets"), std::string::npos) << message();
  // Loading: a scene file over max_scene_bytes.
  const std::string path = dir + "/scene.json";
  std::ofstream(path) << json;
  limits = corofem_input_limits{};
  limits.max_scene_bytes = 100;
  EXPECT_EQ(corofem_scene_load_with_limits(path.c_str(), nullptr, 0, &limits, &refused), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("more than the limit of 100 bytes (InputLimits::maxSceneBytes)"), std::string::npos)
      << message();
  EXPECT_NE(message().find("corofem_input_limits.max_scene_bytes"), std::string::npos) << message();
  limits.max_scene_bytes = 4096;
  CScene loaded;
  C_OK(corofem_scene_load_with_limits(path.c_str(), nullptr, 0, &limits, &loaded.scene));
  CScene plain;
  C_OK(corofem_scene_load(path.c_str(), nullptr, 0, &plain.scene));

  // Creation: the render surface over max_input_bytes, then a box over max_box_tets.
  corofem_options o = corofem_default_options();
  o.limits.max_input_bytes = 100;
  CSim sim;
  EXPECT_EQ(corofem_simulation_create(scene.scene, &o, &sim.sim), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("box.obj: it has "), std::string::npos) << message();
  EXPECT_NE(message().find("more than the limit of 100 bytes (InputLimits::maxInputBytes)"), std::string::npos)
      << message();
  EXPECT_EQ(corofem_warm_up(scene.scene, &o, nullptr), COROFEM_BAD_INPUT);
  o = corofem_options{};  // zeroed: no devices, no device lent, the default limits
  o.limits.max_box_tets = 199;
  EXPECT_EQ(corofem_simulation_create(scene.scene, &o, &sim.sim), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("more than the limit of 199 (InputLimits::maxBoxTets)"), std::string::npos) << message();
  EXPECT_EQ(sim.sim, nullptr);
  o.limits.max_box_tets = 200;
  C_OK(corofem_simulation_create(scene.scene, &o, &sim.sim));
  // An added body: under the simulation's limits (a box of 5 x 10 x 1 cells: 250 tetrahedra).
  const std::string one = R"({"bodies": [{"name": "slab", "mesh": {"box": {"min": [2, 0, 0], "max": [2.5, 1, 0.1],
      "cells": [5, 10, 1]}}}]})";
  CScene extra;
  C_OK(corofem_scene_parse(one.c_str(), dir.c_str(), nullptr, 0, &extra.scene));
  int index = -1;
  EXPECT_EQ(corofem_simulation_add_body(sim.sim, extra.scene, 0, &index), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("give 250 tetrahedra, more than the limit of 200"), std::string::npos) << message();
  EXPECT_EQ(index, -1);
}

/// Every entry point with a NULL handle: BadInput, with a message that starts with its name.
TEST(CApi, EveryCallRefusesANullHandleByName) {
  const double v3[3] = {0, 0, 0};
  const std::uint32_t node = 0;
  double d = 0;
  int i = 0;
  std::size_t z = 0;
  char text[8];
  corofem_step_report report;
  corofem_energies energies;
  corofem_gpu_buffer buffer;
  corofem_scene* scene = nullptr;
  corofem_simulation* sim = nullptr;
  const corofem_force force{};
  const std::vector<std::pair<std::string, std::function<corofem_status()>>> calls = {
      {"corofem_scene_load", [&] { return corofem_scene_load(nullptr, nullptr, 0, &scene); }},
      {"corofem_scene_parse", [&] { return corofem_scene_parse(nullptr, "", nullptr, 0, &scene); }},
      {"corofem_scene_load_with_limits",
       [&] { return corofem_scene_load_with_limits(nullptr, nullptr, 0, nullptr, &scene); }},
      {"corofem_scene_parse_with_limits",
       [&] { return corofem_scene_parse_with_limits(nullptr, "", nullptr, 0, nullptr, &scene); }},
      {"corofem_scene_body_count", [&] { return corofem_scene_body_count(nullptr, &i); }},
      {"corofem_scene_set_step_count", [&] { return corofem_scene_set_step_count(nullptr, 1); }},
      {"corofem_scene_set_body_mesh", [&] { return corofem_scene_set_body_mesh(nullptr, 0, &d, 4, &node, 1); }},
      {"corofem_simulation_create", [&] { return corofem_simulation_create(nullptr, nullptr, &sim); }},
      {"corofem_warm_up", [&] { return corofem_warm_up(nullptr, nullptr, nullptr); }},
      {"corofem_simulation_step", [&] { return corofem_simulation_step(nullptr, &report); }},
      {"corofem_simulation_step_dt", [&] { return corofem_simulation_step_dt(nullptr, 0.01, &report); }},
      {"corofem_simulation_finished", [&] { return corofem_simulation_finished(nullptr, &i); }},
      {"corofem_simulation_steps_taken", [&] { return corofem_simulation_steps_taken(nullptr, &i); }},
      {"corofem_simulation_step_count", [&] { return corofem_simulation_step_count(nullptr, &i); }},
      {"corofem_simulation_time", [&] { return corofem_simulation_time(nullptr, &d); }},
      {"corofem_simulation_body_count", [&] { return corofem_simulation_body_count(nullptr, &i); }},
      {"corofem_simulation_find_body", [&] { return corofem_simulation_find_body(nullptr, "beam", &i); }},
      {"corofem_simulation_node_count", [&] { return corofem_simulation_node_count(nullptr, 0, &z); }},
      {"corofem_simulation_element_count", [&] { return corofem_simulation_element_count(nullptr, 0, &z); }},
      {"corofem_simulation_read_rest_positions", [&] { return corofem_simulation_read_rest_positions(nullptr, 0, &d, 1, &z); }},
      {"corofem_simulation_read_elements", [&] { return corofem_simulation_read_elements(nullptr, 0, nullptr, 0, &z); }},
      {"corofem_simulation_read_positions", [&] { return corofem_simulation_read_positions(nullptr, 0, &d, 1, &z); }},
      {"corofem_simulation_read_velocities", [&] { return corofem_simulation_read_velocities(nullptr, 0, &d, 1, &z); }},
      {"corofem_simulation_energies", [&] { return corofem_simulation_energies(nullptr, 0, &energies); }},
      {"corofem_simulation_surface_size", [&] { return corofem_simulation_surface_size(nullptr, 0, &z, &z); }},
      {"corofem_simulation_read_surface_triangles",
       [&] { return corofem_simulation_read_surface_triangles(nullptr, 0, nullptr, 0, &z); }},
      {"corofem_simulation_read_surface",
       [&] { return corofem_simulation_read_surface(nullptr, 0, &d, 1, nullptr, 0, &z); }},
      {"corofem_simulation_surface_buffer", [&] { return corofem_simulation_surface_buffer(nullptr, 0, &buffer); }},
      {"corofem_simulation_surface_normal_buffer",
       [&] { return corofem_simulation_surface_normal_buffer(nullptr, 0, &buffer); }},
      {"corofem_simulation_update_surface", [&] { return corofem_simulation_update_surface(nullptr, 0); }},
      {"corofem_simulation_add_handle_nodes",
       [&] { return corofem_simulation_add_handle_nodes(nullptr, 0, &node, 1, &i); }},
      {"corofem_simulation_add_handle_point",
       [&] { return corofem_simulation_add_handle_point(nullptr, 0, v3, 0.1, &i); }},
      {"corofem_simulation_add_handle_surface_vertex",
       [&] { return corofem_simulation_add_handle_surface_vertex(nullptr, 0, 0, &i); }},
      {"corofem_simulation_move_handle", [&] { return corofem_simulation_move_handle(nullptr, 1, v3, nullptr); }},
      {"corofem_simulation_set_material", [&] { return corofem_simulation_set_material(nullptr, 0, 1e6, 0.3, 0, 0); }},
      {"corofem_simulation_add_body", [&] { return corofem_simulation_add_body(nullptr, nullptr, 0, &i); }},
      {"corofem_simulation_remove_body", [&] { return corofem_simulation_remove_body(nullptr, 0); }},
      {"corofem_simulation_remove_handle", [&] { return corofem_simulation_remove_handle(nullptr, 1); }},
      {"corofem_simulation_set_handle_stiffness",
       [&] { return corofem_simulation_set_handle_stiffness(nullptr, 1, 1.0); }},
      {"corofem_simulation_pin_nodes", [&] { return corofem_simulation_pin_nodes(nullptr, 0, &node, 1); }},
      {"corofem_simulation_unpin_nodes", [&] { return corofem_simulation_unpin_nodes(nullptr, 0, &node, 1); }},
      {"corofem_simulation_set_forces", [&] { return corofem_simulation_set_forces(nullptr, 0, &force, 1); }},
      {"corofem_simulation_set_gravity", [&] { return corofem_simulation_set_gravity(nullptr, v3); }},
      {"corofem_simulation_set_positions", [&] { return corofem_simulation_set_positions(nullptr, 0, &d, 1); }},
      {"corofem_simulation_set_velocities", [&] { return corofem_simulation_set_velocities(nullptr, 0, &d, 1); }},
      {"corofem_simulation_reset_body", [&] { return corofem_simulation_reset_body(nullptr, 0); }},
      {"corofem_simulation_teleport", [&] { return corofem_simulation_teleport(nullptr, 0, nullptr, v3); }},
      {"corofem_simulation_backend_name", [&] { return corofem_simulation_backend_name(nullptr, text, 8, &z); }},
      {"corofem_simulation_device_name", [&] { return corofem_simulation_device_name(nullptr, text, 8, &z); }},
      {"corofem_simulation_scheduler_report",
       [&] { return corofem_simulation_scheduler_report(nullptr, text, 8, &z); }},
      {"corofem_simulation_plan_report", [&] { return corofem_simulation_plan_report(nullptr, text, 8, &z); }},
  };
  // Every function of the header that returns a corofem_status is in the list.
  std::ifstream header(std::string(COROFEM_SOURCE_DIR) + "/host/include/corofem/corofem.h");
  std::stringstream all;
  all << header.rdbuf();
  const std::string source = all.str();
  std::set<std::string> declared, listed;
  const std::regex statusCall(R"(corofem_status (corofem_\w+)\()");
  for (auto it = std::sregex_iterator(source.begin(), source.end(), statusCall); it != std::sregex_iterator(); ++it)
    declared.insert((*it)[1]);
  declared.erase("corofem_last_status");  // the error query itself
  for (const auto& call : calls) listed.insert(call.first);
  EXPECT_EQ(declared, listed);
  EXPECT_GT(declared.size(), 40u);

  for (const auto& [name, call] : calls) {
    SCOPED_TRACE(name);
    EXPECT_EQ(call(), COROFEM_BAD_INPUT);
    EXPECT_EQ(corofem_last_status(), COROFEM_BAD_INPUT);
    EXPECT_EQ(message().rfind(name + ": ", 0), 0u) << message();
    EXPECT_NE(message().find("is NULL"), std::string::npos) << message();
  }
  EXPECT_EQ(scene, nullptr);
  EXPECT_EQ(sim, nullptr);
}

TEST(CApi, NullResultsAndArraysAreRefusedWithoutTouchingTheSimulation) {
  const std::string dir = tempDir().string();
  writeBoxSurface(dir + "/box.obj", {0.02, 0.02, 0.02}, {0.48, 0.08, 0.08});
  CSim c = createC(twoBodies("reference"), dir);
  ASSERT_NE(c.sim, nullptr);
  EXPECT_EQ(corofem_simulation_time(c.sim, nullptr), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("corofem_simulation_time: the result pointer is NULL"), std::string::npos) << message();
  EXPECT_EQ(corofem_simulation_energies(c.sim, 0, nullptr), COROFEM_BAD_INPUT);
  EXPECT_EQ(corofem_simulation_surface_buffer(c.sim, 0, nullptr), COROFEM_BAD_INPUT);
  EXPECT_EQ(corofem_simulation_add_handle_point(c.sim, 0, nullptr, 0.1, nullptr), COROFEM_BAD_INPUT);
  EXPECT_EQ(corofem_simulation_move_handle(c.sim, 1, nullptr, nullptr), COROFEM_BAD_INPUT);
  EXPECT_EQ(corofem_simulation_set_positions(c.sim, 0, nullptr, 3), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("positions is NULL"), std::string::npos) << message();
  std::size_t needed = 0;
  EXPECT_EQ(corofem_simulation_read_surface(c.sim, 0, nullptr, 0, nullptr, 0, &needed), COROFEM_OK);  // a size query
  EXPECT_EQ(needed, 3u * 6 * 9);
  float normals[3];
  EXPECT_EQ(corofem_simulation_read_surface(c.sim, 0, nullptr, 0, normals, 3, &needed), COROFEM_BAD_INPUT);
  int steps = -1;
  C_OK(corofem_simulation_steps_taken(c.sim, &steps));
  EXPECT_EQ(steps, 0);
  char small[3] = {'x', 'y', 'z'};
  EXPECT_EQ(corofem_simulation_backend_name(c.sim, small, sizeof small, &needed), COROFEM_BAD_INPUT);
  EXPECT_EQ(needed, std::string("reference").size() + 1);
  EXPECT_EQ(small[0], 'x');  // nothing written
}

TEST(CApi, TheLastErrorIsTheCallingThreads) {
  corofem_scene* scene = nullptr;
  ASSERT_EQ(corofem_scene_parse("{", "", nullptr, 0, &scene), COROFEM_BAD_INPUT);
  const std::string mine = message();
  std::string theirs;
  corofem_status theirStatus = COROFEM_OK;
  std::thread other([&] {
    EXPECT_EQ(corofem_last_status(), COROFEM_OK);  // a new thread starts clean
    EXPECT_STREQ(corofem_last_error_message(), "");
    corofem_scene_load("no/such/file.json", nullptr, 0, &scene);
    theirStatus = corofem_last_status();
    theirs = corofem_last_error_message();
  });
  other.join();
  EXPECT_EQ(theirStatus, COROFEM_IO_ERROR);
  EXPECT_NE(theirs.find("no/such/file.json"), std::string::npos) << theirs;
  EXPECT_EQ(corofem_last_status(), COROFEM_BAD_INPUT);
  EXPECT_EQ(message(), mine);
  EXPECT_NE(mine.find("invalid JSON"), std::string::npos) << mine;
  EXPECT_EQ(scene, nullptr);
}

TEST(CApi, TheVersionIsTheProjects) {
  EXPECT_STREQ(corofem_version(), COROFEM_VERSION_STRING);
  EXPECT_EQ(std::to_string(COROFEM_VERSION_MAJOR) + "." + std::to_string(COROFEM_VERSION_MINOR) + "." +
                std::to_string(COROFEM_VERSION_PATCH),
            COROFEM_VERSION_STRING);
  std::ifstream cmake(std::string(COROFEM_SOURCE_DIR) + "/CMakeLists.txt");
  std::stringstream all;
  all << cmake.rdbuf();
  std::smatch m;
  const std::string text = all.str();
  ASSERT_TRUE(std::regex_search(text, m, std::regex(R"(project\(corofem VERSION ([0-9.]+))")));
  EXPECT_EQ(m[1].str(), corofem_version());
}

#ifdef COROFEM_WITH_OPENCL
/// On the application's own OpenCL context (corofem_options::device): every body runs there, the
/// surface's buffer belongs to that context with the layout's stride, and the state and surface
/// are those of the C++ API on the same context, bit for bit.
TEST(CApi, TheApplicationsOpenCLContextHoldsTheSurfaceBuffer) {
  if (detail::cl::listDevices().empty()) GTEST_SKIP() << "no OpenCL device";
  const detail::cl::DeviceInfo info = detail::cl::selectDevice("");
  cl_int status = CL_SUCCESS;
  cl_context context = clCreateContext(nullptr, 1, &info.device, nullptr, nullptr, &status);
  ASSERT_EQ(status, CL_SUCCESS);
  cl_command_queue queue = clCreateCommandQueue(context, info.device, 0, &status);
  ASSERT_EQ(status, CL_SUCCESS);
  const std::string dir = tempDir().string();
  writeBoxSurface(dir + "/box.obj", {0.02, 0.02, 0.02}, {0.48, 0.08, 0.08});
  for (const std::string layout : {"interleaved", "separate"}) {
    SCOPED_TRACE(layout);
    const std::string json = twoBodies("opencl", layout);
    corofem_options o = corofem_default_options();
    o.device = {COROFEM_GPU_OPENCL, context, queue, info.device};
    CSim c = createC(json, dir, &o);
    ASSERT_NE(c.sim, nullptr);
    SimulationOptions lent;
    lent.device = {GpuApi::OpenCL, context, queue, info.device};
    Simulation cpp = createCpp(json, dir, lent);
    char backend[32];
    C_OK(corofem_simulation_backend_name(c.sim, backend, sizeof backend, nullptr));
    EXPECT_STREQ(backend, "opencl");
    const double target[3] = {0.5, 0.055, 0.05};  // the tip's centroid 5 mm up
    std::vector<std::uint32_t> tip;
    for (std::uint32_t n = 0; n < cpp.restMesh(0).nodeCount(); ++n)
      if (std::abs(cpp.restMesh(0).nodes[3 * n] - 0.5) < 1e-9) tip.push_back(n);
    int h = 0;
    C_OK(corofem_simulation_add_handle_nodes(c.sim, 0, tip.data(), tip.size(), &h));
    HandleDesc desc;
    desc.nodes = tip;
    ASSERT_TRUE(cpp.addHandle(desc));
    C_OK(corofem_simulation_move_handle(c.sim, h, target, nullptr));
    CPP_OK(cpp.moveHandle(h, target));
    for (int k = 0; k < 3; ++k) {
      C_OK(corofem_simulation_step(c.sim, nullptr));
      CPP_OK(cpp.step());
    }
    std::vector<double> x;
    CPP_OK(cpp.readPositions(0, x));
    EXPECT_EQ(positionsC(c.sim, 0), x);
    corofem_gpu_buffer b{};
    C_OK(corofem_simulation_surface_buffer(c.sim, 0, &b));
    const GpuBuffer ref = cpp.surfaceBuffer(0);
    std::size_t vertices = 0, triangles = 0;
    C_OK(corofem_simulation_surface_size(c.sim, 0, &vertices, &triangles));
    EXPECT_EQ(b.api, COROFEM_GPU_OPENCL);
    ASSERT_NE(b.handle, 0u);
    EXPECT_EQ(b.stride, ref.stride);
    EXPECT_EQ(b.stride, layout == "interleaved" ? 24u : 12u);
    EXPECT_EQ(b.bytes, vertices * b.stride);
    EXPECT_EQ(b.offset, ref.offset);
    cl_context owner = nullptr;
    ASSERT_EQ(clGetMemObjectInfo(reinterpret_cast<cl_mem>(static_cast<std::uintptr_t>(b.handle)), CL_MEM_CONTEXT,
                                 sizeof owner, &owner, nullptr),
              CL_SUCCESS);
    EXPECT_EQ(owner, context);
    corofem_gpu_buffer normals{};
    C_OK(corofem_simulation_surface_normal_buffer(c.sim, 0, &normals));
    EXPECT_EQ(normals.handle != 0, layout == "separate");
    C_OK(corofem_simulation_update_surface(c.sim, 0));
    std::vector<double> p(3 * vertices), pp;
    std::vector<float> n(3 * vertices), np;
    C_OK(corofem_simulation_read_surface(c.sim, 0, p.data(), p.size(), n.data(), n.size(), nullptr));
    CPP_OK(cpp.readSurface(0, pp, &np));
    EXPECT_EQ(p, pp);
    EXPECT_EQ(n, np);
  }
  clReleaseCommandQueue(queue);
  clReleaseContext(context);
}
#endif

#ifdef COROFEM_WITH_VULKAN
/// corofem_external_device with COROFEM_GPU_VULKAN: the bodies run on the application's VkDevice, the
/// same states as the C++ API given the same handles, and the surface buffer is a VkBuffer of that
/// device that the application reads on its queue: the numbers corofem_simulation_read_surface gives.
TEST(CApi, TheApplicationsVulkanDeviceHoldsTheSurfaceBuffer) {
  test::VulkanApp app(false);
  if (!app.ok()) GTEST_SKIP() << app.why;
  const std::string dir = tempDir().string();
  writeBoxSurface(dir + "/box.obj", {0.02, 0.02, 0.02}, {0.48, 0.08, 0.08});
  std::string json = twoBodies("vulkan");
  const std::string solver = R"("solver": {)";
  json.replace(json.find(solver), solver.size(), R"("solver": {"precision": "float", "preconditioner": "diagonal", )");
  json.replace(json.find("1e-10"), 5, "1e-6");
  corofem_options o = corofem_default_options();
  o.device.api = COROFEM_GPU_VULKAN;
  o.device.instance = app.instance;
  o.device.physical_device = app.physical;
  o.device.device = app.device;
  o.device.queue = app.queue;
  o.device.queue_family = app.family;
  CSim c = createC(json, dir, &o);
  ASSERT_NE(c.sim, nullptr);
  SimulationOptions lent;
  lent.device = app.external();
  Simulation cpp = createCpp(json, dir, lent);
  char backend[32];
  C_OK(corofem_simulation_backend_name(c.sim, backend, sizeof backend, nullptr));
  EXPECT_STREQ(backend, "vulkan");
  for (int k = 0; k < 3; ++k) {
    C_OK(corofem_simulation_step(c.sim, nullptr));
    CPP_OK(cpp.step());
  }
  std::vector<double> x;
  CPP_OK(cpp.readPositions(0, x));
  EXPECT_EQ(positionsC(c.sim, 0), x);
  corofem_gpu_buffer b{};
  C_OK(corofem_simulation_surface_buffer(c.sim, 0, &b));
  std::size_t vertices = 0, triangles = 0;
  C_OK(corofem_simulation_surface_size(c.sim, 0, &vertices, &triangles));
  EXPECT_EQ(b.api, COROFEM_GPU_VULKAN);
  ASSERT_NE(b.handle, 0u);
  EXPECT_EQ(b.stride, 24u);
  EXPECT_EQ(b.bytes, vertices * 24);
  GpuBuffer g;
  g.api = GpuApi::Vulkan;
  g.handle = b.handle;
  g.offset = b.offset;
  g.stride = b.stride;
  g.bytes = b.bytes;
  const std::vector<float> drawn = app.read(g);
  std::vector<double> p(3 * vertices);
  std::vector<float> n(3 * vertices);
  C_OK(corofem_simulation_read_surface(c.sim, 0, p.data(), p.size(), n.data(), n.size(), nullptr));
  ASSERT_EQ(drawn.size(), 6 * vertices);
  for (std::size_t v = 0; v < vertices; ++v)
    for (std::size_t a = 0; a < 3; ++a) {
      EXPECT_EQ(double{drawn[6 * v + a]}, p[3 * v + a]) << "vertex " << v;
      EXPECT_EQ(drawn[6 * v + 3 + a], n[3 * v + a]) << "vertex " << v;
    }
  // A handle the C layer does not pass on is refused by name.
  o.device.physical_device = nullptr;
  CScene scene;
  CSim none;
  C_OK(corofem_scene_parse(json.c_str(), dir.c_str(), nullptr, 0, &scene.scene));
  EXPECT_EQ(corofem_simulation_create(scene.scene, &o, &none.sim), COROFEM_BAD_INPUT);
  EXPECT_NE(message().find("physicalDevice is null"), std::string::npos) << message();
}
#endif

#ifdef COROFEM_C_LIBRARY
/// libcorofem_c.so exports every function corofem.h declares, and none of the C++ library's
/// symbols (the version script, cmake/corofem_c.map).
TEST(CApi, TheSharedLibraryExportsTheCApiAlone) {
  void* lib = dlopen(COROFEM_C_LIBRARY, RTLD_NOW | RTLD_LOCAL);
  ASSERT_NE(lib, nullptr) << dlerror();
  std::ifstream header(std::string(COROFEM_SOURCE_DIR) + "/host/include/corofem/corofem.h");
  std::stringstream all;
  all << header.rdbuf();
  const std::string source = all.str();
  const std::regex function(R"(\b(corofem_\w+)\((void|const|corofem|int|double|char|uint32_t))");
  std::set<std::string> names;
  for (auto it = std::sregex_iterator(source.begin(), source.end(), function); it != std::sregex_iterator(); ++it)
    names.insert((*it)[1]);
  EXPECT_GT(names.size(), 45u);
  for (const std::string& name : names) EXPECT_NE(dlsym(lib, name.c_str()), nullptr) << name << " is not exported";
  // Nothing else is exported (the C++ library inside stays hidden), as binutils' nm lists the
  // library's dynamic symbols.
  std::set<std::string> exported;
  if (FILE* nm = popen("nm -D --defined-only '" COROFEM_C_LIBRARY "' 2>/dev/null", "r")) {
    char line[1024];
    while (std::fgets(line, sizeof line, nm)) {
      std::istringstream fields(line);
      std::string address, type, symbol;
      if (fields >> address >> type >> symbol) exported.insert(symbol);
    }
    pclose(nm);
  }
  if (exported.empty()) {
    std::printf("[ note     ] nm is not available: the check that nothing but the C API is exported was left out\n");
  } else {
    EXPECT_EQ(exported, names);
  }
  // What a loader sees works: the version.
  using Version = const char* (*)();
  auto version = reinterpret_cast<Version>(dlsym(lib, "corofem_version"));
  ASSERT_NE(version, nullptr);
  EXPECT_STREQ(version(), COROFEM_VERSION_STRING);
  dlclose(lib);
}
#endif

}  // namespace
}  // namespace corofem::test

namespace corofem::test {
namespace {

/// A handle on a render-surface vertex places that vertex on its target, as the C++ API does; a
/// warm-up of the scene succeeds and says how long it took.
TEST(CApi, ASurfaceVertexHandleAndAWarmUp) {
  const std::string dir = tempDir().string();
  writeBoxSurface(dir + "/box.obj", {0.02, 0.02, 0.02}, {0.48, 0.08, 0.08});
  CScene scene;
  C_OK(corofem_scene_parse(twoBodies("reference").c_str(), dir.c_str(), nullptr, 0, &scene.scene));
  double seconds = -1.0;
  C_OK(corofem_warm_up(scene.scene, nullptr, &seconds));
  EXPECT_GE(seconds, 0.0);
  CSim c;
  C_OK(corofem_simulation_create(scene.scene, nullptr, &c.sim));
  size_t vertices = 0, triangles = 0;
  C_OK(corofem_simulation_surface_size(c.sim, 0, &vertices, &triangles));
  ASSERT_GT(vertices, 3u);
  std::vector<double> rest(3 * vertices);
  size_t needed = 0;
  C_OK(corofem_simulation_read_surface(c.sim, 0, rest.data(), rest.size(), nullptr, 0, &needed));
  const int vertex = static_cast<int>(vertices - 1);
  int h = 0;
  C_OK(corofem_simulation_add_handle_surface_vertex(c.sim, 0, vertex, &h));
  const double target[3] = {rest[3 * vertex], rest[3 * vertex + 1] + 0.01, rest[3 * vertex + 2]};
  C_OK(corofem_simulation_move_handle(c.sim, h, target, nullptr));
  corofem_step_report report{};
  C_OK(corofem_simulation_step_dt(c.sim, 1.0 / 60.0, &report));
  std::vector<double> now(3 * vertices);
  C_OK(corofem_simulation_read_surface(c.sim, 0, now.data(), now.size(), nullptr, 0, &needed));
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(now[3 * vertex + a], target[a], 1e-9) << "axis " << a;
  EXPECT_EQ(corofem_simulation_add_handle_surface_vertex(c.sim, 1, 0, &h), COROFEM_BAD_INPUT);  // no surface
  EXPECT_NE(message().find("no render surface"), std::string::npos) << message();
  EXPECT_EQ(corofem_simulation_add_handle_surface_vertex(c.sim, 0, -2, &h), COROFEM_BAD_INPUT);
  // A body added from a scene handle of one body steps; removed, the simulation goes on without it.
  {
    const std::string one = R"({"bodies": [{"name": "cube", "mesh": {"box": {"min": [2, 0, 0], "max": [2.1, 0.1, 0.1]}},
        "loads": [{"type": "gravity"}]}]})";
    CScene extra;
    C_OK(corofem_scene_parse(one.c_str(), dir.c_str(), nullptr, 0, &extra.scene));
    int index = -1;
    C_OK(corofem_simulation_add_body(c.sim, extra.scene, 0, &index));
    EXPECT_EQ(index, 2);
    C_OK(corofem_simulation_step_dt(c.sim, 1.0 / 60.0, &report));
    const std::vector<double> fallen = positionsC(c.sim, 2);
    EXPECT_LT(fallen[1], 0.0);  // the cube fell under gravity
    EXPECT_EQ(corofem_simulation_add_body(c.sim, extra.scene, 0, &index), COROFEM_BAD_INPUT);  // same name
    EXPECT_EQ(corofem_simulation_add_body(c.sim, extra.scene, 1, &index), COROFEM_BAD_INPUT);  // no body 1
    C_OK(corofem_simulation_remove_body(c.sim, 2));
    int count = 0;
    C_OK(corofem_simulation_body_count(c.sim, &count));
    EXPECT_EQ(count, 2);
    C_OK(corofem_simulation_step_dt(c.sim, 1.0 / 60.0, &report));
  }
  // A material change: accepted in range, refused out of it with the C function's name.
  C_OK(corofem_simulation_set_material(c.sim, 1, 2e6, 0.3, 1.0, 0.0));
  C_OK(corofem_simulation_step_dt(c.sim, 1.0 / 60.0, &report));
  EXPECT_EQ(corofem_simulation_set_material(c.sim, 1, 2e6, 0.7, 1.0, 0.0), COROFEM_BAD_INPUT);
  EXPECT_EQ(message().rfind("corofem_simulation_set_material", 0), 0u) << message();
}

}  // namespace
}  // namespace corofem::test
