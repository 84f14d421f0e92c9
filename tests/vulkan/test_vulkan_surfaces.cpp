// The render surface on the Vulkan backend (kernels/vulkan/surface.comp, vulkan_surfaces.cpp): the
// coupled mesh recomputed on the device from the device's own centroid-relative positions, into a
// VkBuffer with vertex-buffer usage; and the backend on an application's own VkDevice
// (SimulationOptions::device), where a renderer reads that buffer on its queue with no other
// synchronisation. Checked against the host's deformSurface of the run's own nodes, and the buffer
// as the application reads it against readSurface, bit for bit.
#include <corofem/embed.hpp>
#include <corofem/simulation.hpp>

#include "common/box_surface.hpp"
#include "common/test_data.hpp"
#include "common/vulkan_app.hpp"
#include "solve/beam_helpers.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace corofem {

inline void PrintTo(Precision p, std::ostream* os) { *os << toString(p); }

namespace {

using namespace corofem::test;

/// The Fig. 8 beam (0.8 x 0.1 x 0.1 m, E = 2e5 Pa) 50 m from the origin (where float needs the
/// centroid-relative positions) under gravity, with a finely divided sub-box as its render surface,
/// on the Vulkan backend; `bodies` copies of it 2 m apart (one batch), the last with separate
/// streams when there are several.
Scene vulkanSurfaceScene(Precision precision, int bodies = 1) {
  const std::filesystem::path dir = tempDir();
  const std::string obj = (dir / "inner_box.obj").string();
  const Status written = writeSurfaceMesh(obj, boxSurface({0.02, 0.01, 0.01}, {0.78, 0.09, 0.09}, 8));
  EXPECT_TRUE(written) << written.message();
  BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {0.8, 0.1, 0.1}, {8, 1, 1}), 50.0, 2e5, 0.3, 1000.0,
                                 Formulation::Corotational);
  body.mesh.translate = {50.0, 20.0, -30.0};
  body.surface = "inner_box.obj";
  body.loads.push_back(gravity({0, -9.81, 0}));
  Scene scene = staticScene(body, 1, LinearSolverKind::Pcg);
  scene.bodies.clear();
  for (int i = 0; i < bodies; ++i) {
    BodyDesc b = body;
    b.name = "body" + std::to_string(i);
    b.mesh.translate[1] += 2.0 * i;
    b.material.youngsModulus *= 1.0 + 0.5 * i;
    if (bodies > 1 && i == bodies - 1) b.surfaceLayout = SurfaceLayout::Separate;
    scene.bodies.push_back(b);
  }
  scene.baseDir = dir.string();
  scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.timeStep = 0.01;
  scene.analysis.dynamics.steps = 0;
  scene.solver.tolerance = precision == Precision::Double ? 1e-10 : 1e-6;
  scene.solver.maxIterations = 5000;
  scene.solver.precision = precision;
  scene.solver.preconditioner = PreconditionerKind::Diagonal;
  scene.backend.kind = BackendKind::Vulkan;
  scene.backend.batch = true;
  return scene;
}

double worst(const std::vector<double>& a, const std::vector<double>& b) {
  double w = 0;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i) w = std::max(w, std::abs(a[i] - b[i]));
  return a.size() == b.size() ? w : INFINITY;
}
double worst(const std::vector<float>& a, const std::vector<float>& b) {
  double w = 0;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i) w = std::max(w, double{std::abs(a[i] - b[i])});
  return a.size() == b.size() ? w : INFINITY;
}

/// Body i's surface read back against deformSurface of its own committed nodes: the float output
/// rounds |x| ~ 50 m to half an ulp (1.9e-6 m, once: the centroid goes in as a float pair); float
/// arithmetic on the centroid-relative positions adds a few ulps of 0.5 m. Normals: float face
/// vectors of 0.01 m edges lose about 6e-6 in direction, a few per normal; in double only the
/// output rounds.
void expectTheHostsSurface(const Simulation& sim, int i, bool isDouble) {
  SCOPED_TRACE("body " + std::to_string(i));
  std::vector<double> positions, nodes;
  std::vector<float> normals;
  ASSERT_TRUE(sim.readSurface(i, positions, &normals));
  ASSERT_TRUE(sim.readPositions(i, nodes));
  const SurfaceBinding binding = *bindSurface(sim.restMesh(i), *sim.restSurface(i));
  std::vector<double> own(3 * binding.vertexCount());
  std::vector<float> ownNormals(own.size());
  SurfaceOutput out;
  out.positionsDouble = own.data();
  out.normals = ownNormals.data();
  ASSERT_TRUE(deformSurface(binding, nodes.data(), sim.restMesh(i).nodeCount(), out));
  EXPECT_LE(worst(positions, own), 2.5e-6);
  EXPECT_LE(worst(normals, ownNormals), isDouble ? 1e-6 : 1e-4);
  // The surface did move (gravity): not the rest surface.
  const SurfaceMesh& rest = *sim.restSurface(i);
  EXPECT_GT(worst(positions, rest.vertices), 1e-4);
}

class VulkanSurfaces : public ::testing::TestWithParam<Precision> {
 protected:
  bool isDouble() const { return GetParam() == Precision::Double; }
  /// Skips where no Vulkan device runs this precision.
  static void skipUnless(const Result<Simulation>& sim) {
    if (!sim && (sim.status().code() == ErrorCode::DeviceError || sim.status().code() == ErrorCode::NotCompiledIn))
      GTEST_SKIP() << "no Vulkan device for this precision: " << sim.message();
  }
};

TEST_P(VulkanSurfaces, TheDeviceSurfaceIsTheHostsDeformationOfTheRunsOwnNodes) {
  auto sim = Simulation::create(vulkanSurfaceScene(GetParam()));
  skipUnless(sim);
  if (IsSkipped()) return;
  ASSERT_TRUE(sim) << sim.message();
  ASSERT_EQ(sim->backendName(), "vulkan");
  const std::size_t n = sim->restSurface(0)->vertexCount();
  for (int k = 1; k <= 10; ++k) ASSERT_TRUE(sim->step()) << "step " << k;
  expectTheHostsSurface(sim.value(), 0, isDouble());
  const GpuBuffer b = sim->surfaceBuffer(0);
  EXPECT_EQ(b.api, GpuApi::Vulkan);
  EXPECT_NE(b.handle, 0u);
  EXPECT_EQ(b.offset, 0u);
  EXPECT_EQ(b.stride, 24u);
  EXPECT_EQ(b.bytes, 24 * n);
  EXPECT_FALSE(sim->surfaceNormalBuffer(0));
  const nlohmann::json plan = nlohmann::json::parse(sim->planReport())["bodies"][0]["surface"];
  EXPECT_EQ(plan["where"], "device") << plan.dump(1);
  // Two runs give the same bits.
  auto again = Simulation::create(vulkanSurfaceScene(GetParam()));
  ASSERT_TRUE(again) << again.message();
  for (int k = 1; k <= 10; ++k) ASSERT_TRUE(again->step()) << "step " << k;
  std::vector<double> p1, p2;
  std::vector<float> n1, n2;
  ASSERT_TRUE(sim->readSurface(0, p1, &n1));
  ASSERT_TRUE(again->readSurface(0, p2, &n2));
  EXPECT_EQ(p1, p2);
  EXPECT_EQ(n1, n2);
}

/// The same with the dynamics' vectors in the device's memory (VulkanTuning::deviceStore = 1): the
/// device's positions come from the store's buffers, relative to the store's origin, and the
/// surface is still the host's deformation of the positions the run reads back.
TEST_P(VulkanSurfaces, WithTheStateOnTheDeviceTheSurfaceIsTheHostsDeformationToo) {
  SimulationOptions o;
  o.vulkan.deviceStore = 1;
  auto sim = Simulation::create(vulkanSurfaceScene(GetParam()), o);
  skipUnless(sim);
  if (IsSkipped()) return;
  ASSERT_TRUE(sim) << sim.message();
  for (int k = 1; k <= 10; ++k) ASSERT_TRUE(sim->step()) << "step " << k;
  expectTheHostsSurface(sim.value(), 0, isDouble());
  const nlohmann::json report = nlohmann::json::parse(sim->schedulerReport());
  EXPECT_EQ(report.value("device_counters", nlohmann::json::object()).value("step_stores_made", 0LL), 1);
}

TEST_P(VulkanSurfaces, ABatchsSurfacesShareTheirBuffersAndEachIsItsBodys) {
  auto sim = Simulation::create(vulkanSurfaceScene(GetParam(), 3));
  skipUnless(sim);
  if (IsSkipped()) return;
  ASSERT_TRUE(sim) << sim.message();
  ASSERT_EQ(nlohmann::json::parse(sim->schedulerReport())["batches"].size(), 1u);
  for (int k = 1; k <= 4; ++k) ASSERT_TRUE(sim->step()) << "step " << k;
  const std::size_t n = sim->restSurface(0)->vertexCount();
  for (int i = 0; i < 3; ++i) expectTheHostsSurface(sim.value(), i, isDouble());
  // Bodies 0 and 1 (interleaved) are regions of one buffer; body 2 has two streams of its own.
  const GpuBuffer b0 = sim->surfaceBuffer(0), b1 = sim->surfaceBuffer(1), b2 = sim->surfaceBuffer(2);
  EXPECT_EQ(b0.handle, b1.handle);
  EXPECT_EQ(b1.offset, b0.offset + b0.bytes);
  EXPECT_NE(b2.handle, b0.handle);
  EXPECT_EQ(b2.stride, 12u);
  EXPECT_EQ(b2.bytes, 12 * n);
  const GpuBuffer n2 = sim->surfaceNormalBuffer(2);
  EXPECT_EQ(n2.api, GpuApi::Vulkan);
  EXPECT_EQ(n2.bytes, 12 * n);
}

/// The application's device: every body runs there, and the renderer reads the surface buffer on
/// its own queue right after surfaceBuffer() (no updateSurface, no wait of corofem's): the bits
/// readSurface gives, frame after frame, for a batch of three bodies in both layouts.
TEST_P(VulkanSurfaces, OnTheApplicationsDeviceTheRendererReadsTheCurrentSurfaceOnItsQueue) {
  VulkanApp app(isDouble());
  if (!app.ok()) GTEST_SKIP() << app.why;
  if (isDouble() && !app.hasFloat64) GTEST_SKIP() << "the device has no shaderFloat64";
  SimulationOptions options;
  options.device = app.external();
  auto sim = Simulation::create(vulkanSurfaceScene(GetParam(), 3), options);
  ASSERT_TRUE(sim) << sim.message();
  EXPECT_EQ(sim->backendName(), "vulkan");
  const std::size_t n = sim->restSurface(0)->vertexCount();
  std::vector<float> previous;
  for (int frame = 1; frame <= 3; ++frame) {
    ASSERT_TRUE(sim->step()) << "frame " << frame;
    for (int i = 0; i < 3; ++i) {
      SCOPED_TRACE("frame " + std::to_string(frame) + ", body " + std::to_string(i));
      const GpuBuffer b = sim->surfaceBuffer(i);
      ASSERT_EQ(b.api, GpuApi::Vulkan);
      const std::vector<float> drawn = app.read(b);
      std::vector<float> normals;
      if (i == 2) normals = app.read(sim->surfaceNormalBuffer(i));
      std::vector<double> positions;
      std::vector<float> readNormals;
      ASSERT_TRUE(sim->readSurface(i, positions, &readNormals));
      const std::size_t stride = i == 2 ? 3 : 6;
      ASSERT_EQ(drawn.size(), stride * n);
      for (std::size_t v = 0; v < n; ++v)
        for (std::size_t a = 0; a < 3; ++a) {
          ASSERT_EQ(double{drawn[stride * v + a]}, positions[3 * v + a]) << "vertex " << v;
          ASSERT_EQ(i == 2 ? normals[3 * v + a] : drawn[6 * v + 3 + a], readNormals[3 * v + a]) << "vertex " << v;
        }
      if (i == 0) {
        EXPECT_NE(drawn, previous);  // the body falls: each frame's surface is new
        previous = drawn;
      }
    }
  }
  expectTheHostsSurface(sim.value(), 1, isDouble());
  sim = Result<Simulation>(ErrorCode::Internal, "destroyed");  // corofem's objects go before the checks
  // Where the validation layer is installed, it saw no misuse of the device, corofem's or ours.
  EXPECT_TRUE(app.messages().empty()) << app.messages().size() << " validation messages, the first: "
                                      << app.messages().front();
  std::printf("[ vulkan   ] validation layer: %s\n", app.validated ? "on" : "absent (Debian: vulkan-validationlayers)");
}

INSTANTIATE_TEST_SUITE_P(Precisions, VulkanSurfaces, ::testing::Values(Precision::Float, Precision::Double),
                         [](const ::testing::TestParamInfo<Precision>& info) {
                           return std::string(info.param == Precision::Double ? "Double" : "Float");
                         });

/// What cannot work with the application's handles is said at create(), naming the field.
TEST(VulkanExternalDevice, BadHandlesAreRefusedByName) {
  VulkanApp app(false);
  if (!app.ok()) GTEST_SKIP() << app.why;
  const Scene scene = vulkanSurfaceScene(Precision::Float);
  auto refused = [&](ExternalDevice e, const char* words) {
    SimulationOptions o;
    o.device = e;
    auto sim = Simulation::create(scene, o);
    ASSERT_FALSE(sim);
    EXPECT_EQ(sim.status().code(), ErrorCode::BadInput) << sim.message();
    EXPECT_NE(sim.message().find(words), std::string::npos) << sim.message();
  };
  ExternalDevice e = app.external();
  e.instance = nullptr;
  refused(e, "instance is null");
  e = app.external();
  e.physicalDevice = nullptr;
  refused(e, "physicalDevice is null");
  e = app.external();
  e.device = nullptr;
  refused(e, "device is null");
  e = app.external();
  e.queue = nullptr;
  refused(e, "queue is null");
  e = app.external();
  e.queueFamily = 99;
  refused(e, "queue family 99");
  e = app.external();
  e.shaderFloat64 = false;
  Scene dbl = scene;
  dbl.solver.precision = Precision::Double;
  SimulationOptions o;
  o.device = e;
  auto sim = Simulation::create(dbl, o);
  ASSERT_FALSE(sim);
  EXPECT_EQ(sim.status().code(), ErrorCode::BadInput) << sim.message();
  EXPECT_NE(sim.message().find("shaderFloat64"), std::string::npos) << sim.message();
}

}  // namespace
}  // namespace corofem
