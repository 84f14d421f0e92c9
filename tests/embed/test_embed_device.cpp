// DeviceSurface (kernels/opencl/surface_update.cl) against the host reference deformSurface, on every
// OpenCL device present (PoCL in CI), in float and (where the device has fp64) double.
#include <corofem/embed.hpp>
#include <corofem/mesh.hpp>

#include "embed/embed_test_util.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/cl_context.hpp"
#endif

namespace corofem {
namespace {

#ifndef COROFEM_WITH_OPENCL

TEST(EmbedDevice, ReportsNotCompiledIn) {
  SurfaceBinding empty;
  auto d = DeviceSurface::create(empty);
  ASSERT_FALSE(d.isOk());
  EXPECT_EQ(d.status().code(), ErrorCode::NotCompiledIn);
  EXPECT_NE(d.message().find("-DCOROFEM_WITH_OPENCL=ON"), std::string::npos) << d.message();
}

#else

struct DeviceCase {
  int device = -1;  // index into listDevices(), -1: none present
  bool doublePrecision = false;
  std::string name;
};

std::vector<DeviceCase> deviceCases() {
  std::vector<DeviceCase> out;
  const auto devices = detail::cl::listDevices();
  for (std::size_t i = 0; i < devices.size(); ++i) {
    std::string clean;
    for (char c : devices[i].name) clean += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
    clean = "dev" + std::to_string(i) + "_" + clean.substr(0, 24);
    out.push_back({static_cast<int>(i), false, clean + "_float"});
    if (devices[i].fp64) out.push_back({static_cast<int>(i), true, clean + "_double"});
  }
  if (out.empty()) out.push_back({-1, false, "no_opencl_device"});
  return out;
}

class EmbedDevice : public ::testing::TestWithParam<DeviceCase> {
 protected:
  void SetUp() override {
    if (GetParam().device < 0)
      GTEST_SKIP() << "no OpenCL device found on any platform (install a GPU driver or pocl-opencl-icd)";
  }
  DeviceSurfaceOptions options() const {
    DeviceSurfaceOptions o;
    o.device = std::to_string(GetParam().device);
    o.doublePrecision = GetParam().doublePrecision;
    return o;
  }
};

/// A 6x6x6-cell box with a UV sphere inside plus a few vertices outside the box (extrapolated), with
/// a vertex count that is not a multiple of any work-group size.
struct Scene {
  TetMesh tets;
  SurfaceMesh surface;
  SurfaceBinding binding;
};

Scene makeScene() {
  Scene s;
  BoxSpec spec;
  spec.cells = {6, 6, 6};
  s.tets = *generateBox(spec);
  s.surface = test::uvSphere({0.5, 0.5, 0.5}, 0.42, 37, 53);
  s.surface.vertices.insert(s.surface.vertices.end(), {1.02, 0.5, 0.5, 0.5, -0.03, 0.5});
  s.binding = *bindSurface(s.tets, s.surface);
  return s;
}

TEST_P(EmbedDevice, MatchesHostReference) {
  const Scene s = makeScene();
  auto device = DeviceSurface::create(s.binding, options());
  ASSERT_TRUE(device.isOk()) << device.message();
  EXPECT_EQ(device->vertexCount(), s.binding.vertexCount());
  std::printf("[ device   ] %s\n", device->deviceName().c_str());
  std::mt19937 rng(17);
  const std::size_t n = s.binding.vertexCount();
  for (int frame = 0; frame < 3; ++frame) {
    const std::vector<double> x = test::SmoothDeformation::random(rng, 1.0, frame > 0).apply(s.tets.nodes);
    std::vector<float> host(6 * n), dev(6 * n, NAN);
    SurfaceOutput o;
    o.interleaved = host.data();
    ASSERT_TRUE(deformSurface(s.binding, x.data(), s.tets.nodeCount(), o).isOk());
    ASSERT_TRUE(device->update(x.data(), s.tets.nodeCount()).isOk());
    ASSERT_TRUE(device->read(dev.data()).isOk());
    // Positions: float output either way (a float ulp at |x| ~ 2 is 2.4e-7); in float arithmetic the
    // weighted sum adds a few ulps of |x| times |w| (<= ~1.5 here). Normals: float faces of edge
    // ~0.05 lose about eps |x| / edge ~ 1e-5 in direction; double arithmetic only rounds the output.
    const bool dbl = GetParam().doublePrecision;
    const float posTol = dbl ? 5e-7f : 4e-6f, nTol = dbl ? 1e-6f : 2e-4f;
    float worstPos = 0, worstNormal = 0;
    for (std::size_t v = 0; v < n; ++v)
      for (int c = 0; c < 3; ++c) {
        worstPos = std::max(worstPos, std::abs(dev[6 * v + c] - host[6 * v + c]));
        worstNormal = std::max(worstNormal, std::abs(dev[6 * v + 3 + c] - host[6 * v + 3 + c]));
      }
    std::printf("[ device   ] frame %d: worst |position| difference %.3g, worst |normal| difference %.3g\n", frame,
                worstPos, worstNormal);
    EXPECT_LE(worstPos, posTol);
    EXPECT_LE(worstNormal, nTol);
  }
}

TEST_P(EmbedDevice, IsDeterministicAndRejectsWrongNodeCount) {
  const Scene s = makeScene();
  auto device = DeviceSurface::create(s.binding, options());
  ASSERT_TRUE(device.isOk()) << device.message();
  std::mt19937 rng(19);
  const std::vector<double> x = test::SmoothDeformation::random(rng, 1.0, true).apply(s.tets.nodes);
  const std::size_t n = s.binding.vertexCount();
  std::vector<float> a(6 * n), b(6 * n);
  ASSERT_TRUE(device->update(x.data(), s.tets.nodeCount()).isOk());
  ASSERT_TRUE(device->read(a.data()).isOk());
  ASSERT_TRUE(device->update(s.tets.nodes.data(), s.tets.nodeCount()).isOk());  // another frame between
  ASSERT_TRUE(device->update(x.data(), s.tets.nodeCount()).isOk());
  ASSERT_TRUE(device->read(b.data()).isOk());
  EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * sizeof(float)));  // same bits: no atomics
  const Status wrong = device->update(x.data(), s.tets.nodeCount() + 1);
  EXPECT_EQ(wrong.code(), ErrorCode::BadInput);
  EXPECT_NE(wrong.message().find("344 node positions given"), std::string::npos) << wrong.message();
  ASSERT_NE(device->vertexBuffer(), nullptr);
}

INSTANTIATE_TEST_SUITE_P(Devices, EmbedDevice, ::testing::ValuesIn(deviceCases()),
                         [](const ::testing::TestParamInfo<DeviceCase>& info) { return info.param.name; });

#endif

}  // namespace
}  // namespace corofem
