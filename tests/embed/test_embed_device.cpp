// DeviceSurface (kernels/opencl/surface_update.cl) against the host reference deformSurface, on every
// OpenCL device present (PoCL in CI), in float and (where the device has fp64) double.
#include <corofem/embed.hpp>
#include <corofem/mesh.hpp>

#include "embed/embed_test_util.hpp"
#ifdef COROFEM_WITH_OPENCL
#include "common/gpu_handles.hpp"
#endif

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <map>
#include <numeric>
#include <random>
#include <string>

#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/device_surface.hpp"

#include <CL/cl.h>
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

void PrintTo(const DeviceCase& c, std::ostream* os) { *os << c.name; }

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
struct EmbedCase {
  TetMesh tets;
  SurfaceMesh surface;
  SurfaceBinding binding;
};

/// `shuffled`: the sphere's vertices renumbered at random, so that no ring slot of a block of
/// vertices holds consecutive vertices (the normal pass gathers every neighbour lane by lane);
/// otherwise the row-by-row numbering, where most do (vector loads from the block's run start).
EmbedCase makeEmbedCase(bool shuffled = false) {
  EmbedCase s;
  BoxSpec spec;
  spec.cells = {6, 6, 6};
  s.tets = *generateBox(spec);
  s.surface = test::uvSphere({0.5, 0.5, 0.5}, 0.42, 37, 53);
  // Three stray vertices (no triangle, normal 0): two outside the box (extrapolated), one inside,
  // so that the 1,913 vertices end in a partial block at every vector width (8 and 16).
  s.surface.vertices.insert(s.surface.vertices.end(), {1.02, 0.5, 0.5, 0.5, -0.03, 0.5, 0.5, 0.5, 0.5});
  if (shuffled) {
    const std::size_t n = s.surface.vertexCount();
    std::vector<std::uint32_t> to(n);
    std::iota(to.begin(), to.end(), 0u);
    std::shuffle(to.begin(), to.end(), std::mt19937(5));
    std::vector<double> moved(3 * n);
    for (std::size_t v = 0; v < n; ++v)
      for (int c = 0; c < 3; ++c) moved[3 * to[v] + c] = s.surface.vertices[3 * v + c];
    s.surface.vertices = moved;
    for (std::uint32_t& t : s.surface.triangles) t = to[t];
  }
  s.binding = *bindSurface(s.tets, s.surface);
  return s;
}

TEST_P(EmbedDevice, MatchesHostReference) {
  const EmbedCase s = makeEmbedCase();
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

/// Pass 2's vertices per work-item (DeviceSurfaceOptions::normalPassLanes: 1 on GPUs, 8 or 16 vectors
/// on CPUs) change
/// how the work is cut, not the mathematics: every width matches the host reference within the
/// tolerances of MatchesHostReference, including the vertices of the last, partial block. Both
/// numberings of the sphere: row by row, where some ring slots of a block of vertices hold
/// consecutive vertices and others do not (rows of 53 vertices cut the blocks of 8 and 16), and
/// shuffled, where none do, so that both of the normal pass's ways of reading a slot (vector loads
/// from the run's start, or the slot's entries gathered lane by lane) are checked at every width. A
/// width the kernels do not have is refused with the fix.
TEST_P(EmbedDevice, EveryLaneWidthMatchesHostReference) {
  for (bool shuffled : {false, true}) {
    SCOPED_TRACE(shuffled ? "vertices shuffled" : "vertices row by row");
    const EmbedCase s = makeEmbedCase(shuffled);
    const std::size_t n = s.binding.vertexCount();
    ASSERT_NE(n % 8, 0u) << "the last block must be partial at every width";
    for (std::size_t lanes : {8, 16}) {  // the layout the kernels get: runs in some slots, or in none
      const detail::DeviceSurfaceLayout layout = detail::deviceSurfaceLayout(s.binding, lanes);
      const std::size_t all = layout.slots * ((n + 63) / 64 * 64);
      if (shuffled) EXPECT_GT(layout.ringEntriesRead, all * 9 / 10) << lanes << " lanes";
      else EXPECT_LT(layout.ringEntriesRead, all / 2) << lanes << " lanes";
      EXPECT_GT(layout.ringEntriesRead, 0u) << lanes << " lanes";
      EXPECT_EQ(layout.runWords, all / layout.slots / lanes * (layout.slots + 1)) << lanes << " lanes";
    }
    std::mt19937 rng(29);
    const std::vector<double> x = test::SmoothDeformation::random(rng, 1.0, true).apply(s.tets.nodes);
    std::vector<float> host(6 * n);
    SurfaceOutput o;
    o.interleaved = host.data();
    ASSERT_TRUE(deformSurface(s.binding, x.data(), s.tets.nodeCount(), o).isOk());
    const bool dbl = GetParam().doublePrecision;
    const float posTol = dbl ? 5e-7f : 4e-6f, nTol = dbl ? 1e-6f : 2e-4f;
    for (std::size_t lanes : {1, 8, 16}) {
      DeviceSurfaceOptions lanesOptions = options();
      lanesOptions.normalPassLanes = lanes;
      auto device = DeviceSurface::create(s.binding, lanesOptions);
      ASSERT_TRUE(device.isOk()) << lanes << " lanes: " << device.message();
      std::vector<float> dev(6 * n, NAN);
      ASSERT_TRUE(device->update(x.data(), s.tets.nodeCount()).isOk());
      ASSERT_TRUE(device->read(dev.data()).isOk());
      float worstPos = 0, worstNormal = 0;
      for (std::size_t v = 0; v < n; ++v)
        for (int c = 0; c < 3; ++c) {
          worstPos = std::max(worstPos, std::abs(dev[6 * v + c] - host[6 * v + c]));  // NaN fails below
          worstNormal = std::max(worstNormal, std::abs(dev[6 * v + 3 + c] - host[6 * v + 3 + c]));
          ASSERT_TRUE(std::isfinite(dev[6 * v + c]) && std::isfinite(dev[6 * v + 3 + c]))
              << lanes << " lanes, vertex " << v;
        }
      std::printf("[ device   ] %s, %zu lanes: worst |position| difference %.3g, worst |normal| difference %.3g\n",
                  shuffled ? "shuffled" : "row by row", lanes, worstPos, worstNormal);
      EXPECT_LE(worstPos, posTol) << lanes << " lanes";
      EXPECT_LE(worstNormal, nTol) << lanes << " lanes";
    }
  }
  const EmbedCase s = makeEmbedCase();
  DeviceSurfaceOptions four = options();
  four.normalPassLanes = 4;
  auto refused = DeviceSurface::create(s.binding, four);
  ASSERT_FALSE(refused.isOk());
  EXPECT_EQ(refused.status().code(), ErrorCode::BadInput);
  EXPECT_NE(refused.message().find("normalPassLanes = 4: give 1, 8 or 16"), std::string::npos) << refused.message();
}

/// DeviceSurfaceOptions::separateStreams writes the same values as the interleaved layout, bit for bit,
/// into two buffers of 3 floats per vertex, at every lane width and for both numberings (runs and
/// gathers, the last block partial); each layout reads back as either (read(interleaved) and
/// read(positions, normals)), and a null pointer is refused.
TEST_P(EmbedDevice, SeparateStreamsHoldTheInterleavedValues) {
  for (bool shuffled : {false, true}) {
    const EmbedCase s = makeEmbedCase(shuffled);
    const std::size_t n = s.binding.vertexCount();
    std::mt19937 rng(31);
    const std::vector<double> x = test::SmoothDeformation::random(rng, 1.0, true).apply(s.tets.nodes);
    for (std::size_t lanes : {1, 8, 16}) {
      SCOPED_TRACE(std::string(shuffled ? "shuffled, " : "row by row, ") + std::to_string(lanes) + " lanes");
      DeviceSurfaceOptions o = options();
      o.normalPassLanes = lanes;
      auto interleaved = DeviceSurface::create(s.binding, o);
      o.separateStreams = true;
      auto separate = DeviceSurface::create(s.binding, o);
      ASSERT_TRUE(interleaved.isOk()) << interleaved.message();
      ASSERT_TRUE(separate.isOk()) << separate.message();
      EXPECT_FALSE(interleaved->separateStreams());
      EXPECT_TRUE(separate->separateStreams());
      EXPECT_FALSE(interleaved->normalBuffer());
      ASSERT_TRUE(separate->normalBuffer());
      EXPECT_EQ(interleaved->vertexBuffer().stride, 24u);
      EXPECT_EQ(separate->vertexBuffer().stride, 12u);
      EXPECT_EQ(separate->normalBuffer().bytes, 12 * n);
      for (auto [buffer, floats] : {std::pair{interleaved->vertexBuffer(), 6 * n},
                                    std::pair{separate->vertexBuffer(), 3 * n},
                                    std::pair{separate->normalBuffer(), 3 * n}}) {
        std::size_t bytes = 0;
        ASSERT_EQ(clGetMemObjectInfo(test::clMem(buffer), CL_MEM_SIZE, sizeof(bytes), &bytes, nullptr), CL_SUCCESS);
        EXPECT_EQ(bytes, floats * sizeof(float));
        EXPECT_EQ(buffer.bytes, bytes);
      }
      ASSERT_TRUE(interleaved->update(x.data(), s.tets.nodeCount()).isOk());
      ASSERT_TRUE(separate->update(x.data(), s.tets.nodeCount()).isOk());
      std::vector<float> whole(6 * n, NAN), wholeFromSeparate(6 * n, NAN);
      std::vector<float> p(3 * n, NAN), m(3 * n, NAN), pFromWhole(3 * n, NAN), mFromWhole(3 * n, NAN);
      ASSERT_TRUE(interleaved->read(whole.data()).isOk());
      ASSERT_TRUE(separate->read(p.data(), m.data()).isOk());
      ASSERT_TRUE(separate->read(wholeFromSeparate.data()).isOk());
      ASSERT_TRUE(interleaved->read(pFromWhole.data(), mFromWhole.data()).isOk());
      std::size_t differ = 0;
      for (std::size_t v = 0; v < n; ++v)
        for (int c = 0; c < 3; ++c) {
          ASSERT_TRUE(std::isfinite(whole[6 * v + c]) && std::isfinite(whole[6 * v + 3 + c])) << "vertex " << v;
          differ += std::memcmp(&p[3 * v + c], &whole[6 * v + c], sizeof(float)) != 0;
          differ += std::memcmp(&m[3 * v + c], &whole[6 * v + 3 + c], sizeof(float)) != 0;
        }
      EXPECT_EQ(differ, 0u) << "of " << 6 * n << " floats";
      EXPECT_EQ(std::memcmp(wholeFromSeparate.data(), whole.data(), whole.size() * sizeof(float)), 0);
      EXPECT_EQ(std::memcmp(pFromWhole.data(), p.data(), p.size() * sizeof(float)), 0);
      EXPECT_EQ(std::memcmp(mFromWhole.data(), m.data(), m.size() * sizeof(float)), 0);
      const Status refused = separate->read(p.data(), nullptr);
      EXPECT_EQ(refused.code(), ErrorCode::BadInput);
      EXPECT_NE(refused.message().find("normals pointer is null"), std::string::npos) << refused.message();
    }
  }
}

/// buffers() lists what was allocated, with the sizes OpenCL reports; the upload buffer of host node
/// positions appears with the first update() (a surface fed from device positions never has it).
TEST_P(EmbedDevice, ListsItsBuffersAsAllocated) {
  const EmbedCase s = makeEmbedCase();
  auto device = DeviceSurface::create(s.binding, options());
  ASSERT_TRUE(device.isOk()) << device.message();
  auto sizes = [&] {
    std::map<std::string, std::size_t> out;
    std::size_t total = 0;
    for (const DeviceSurfaceBuffer& b : device->buffers()) {
      EXPECT_EQ(out.count(b.name), 0u) << b.name << " listed twice";
      out[b.name] = b.bytes;
      total += b.bytes;
    }
    EXPECT_EQ(total, device->allocatedBytes());
    return out;
  };
  std::map<std::string, std::size_t> before = sizes();
  EXPECT_EQ(before.count("node positions"), 0u);
  std::size_t bytes = 0;
  ASSERT_EQ(clGetMemObjectInfo(test::clMem(device->vertexBuffer()), CL_MEM_SIZE, sizeof(bytes), &bytes, nullptr), CL_SUCCESS);
  EXPECT_EQ(before["output vertex"], bytes);
  EXPECT_EQ(bytes, 6 * sizeof(float) * s.binding.vertexCount());
  ASSERT_TRUE(device->update(s.tets.nodes.data(), s.tets.nodeCount()).isOk());
  ASSERT_TRUE(device->update(s.tets.nodes.data(), s.tets.nodeCount()).isOk());  // made once
  std::map<std::string, std::size_t> after = sizes();
  EXPECT_EQ(after["node positions"], 3 * s.tets.nodeCount() * (GetParam().doublePrecision ? 8 : 4));
  after.erase("node positions");
  EXPECT_EQ(after, before);
}

TEST_P(EmbedDevice, IsDeterministicAndRejectsWrongNodeCount) {
  const EmbedCase s = makeEmbedCase();
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
  ASSERT_TRUE(device->vertexBuffer());
}

/// Stores `value` as real number `index` of a device-precision byte array (double or float).
void storeReal(std::vector<unsigned char>& bytes, std::size_t index, double value, bool dbl) {
  if (dbl) {
    std::memcpy(&bytes[8 * index], &value, 8);
  } else {
    const float f = static_cast<float>(value);
    std::memcpy(&bytes[4 * index], &f, 4);
  }
}

/// updateFromDevice with node positions relative to an offset c (the OpenCL backend's centroid-relative
/// buffer) writes the same surface as absolute positions: x_v = sum_k w_vk (x_k - c) + c.
TEST_P(EmbedDevice, RelativePositionsWithOffsetMatchAbsolute) {
  const EmbedCase s = makeEmbedCase();
  const bool dbl = GetParam().doublePrecision;
  auto ctx = detail::cl::Context::shared(std::to_string(GetParam().device));
  DeviceSurfaceOptions o = options();
  o.external = test::externalOf(*ctx);
  auto device = DeviceSurface::create(s.binding, o);
  ASSERT_TRUE(device.isOk()) << device.message();
  std::mt19937 rng(23);
  // The body far from the origin (c ~ 100), where the absolute positions carry ~100x the rounding.
  std::vector<double> x = test::SmoothDeformation::random(rng, 1.0, true).apply(s.tets.nodes);
  const double c[3] = {100.25, -37.5, 64.125};
  for (std::size_t i = 0; i < x.size(); ++i) x[i] += c[i % 3];
  const std::size_t nodes = s.tets.nodeCount(), n = s.binding.vertexCount();
  // Both inputs in the device precision, as device buffers; `lead` nodes of another body (far
  // away) before the surface's own, as in a batch's shared buffer.
  auto upload = [&](bool relative, std::size_t lead = 0) {
    std::vector<unsigned char> bytes(3 * (lead + nodes) * (dbl ? 8 : 4));
    for (std::size_t i = 0; i < 3 * (lead + nodes); ++i)
      storeReal(bytes, i, i < 3 * lead ? 1e4 + static_cast<double>(i) : relative ? x[i - 3 * lead] - c[i % 3] : x[i - 3 * lead],
                dbl);
    cl_int status = CL_SUCCESS;
    cl_mem m = clCreateBuffer(ctx->context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, bytes.size(), bytes.data(),
                              &status);
    EXPECT_EQ(status, CL_SUCCESS);
    return m;
  };
  cl_mem absolute = upload(false), relative = upload(true);
  std::vector<float> a(6 * n, NAN), r(6 * n, NAN), r0(6 * n, NAN), host(6 * n);
  ASSERT_TRUE(device->updateFromDevice(test::gpuBuffer(absolute)).isOk());
  ASSERT_TRUE(device->read(a.data()).isOk());
  ASSERT_TRUE(device->updateFromDevice(test::gpuBuffer(relative), c).isOk());
  ASSERT_TRUE(device->read(r.data()).isOk());
  ASSERT_TRUE(device->updateFromDevice(test::gpuBuffer(relative), nullptr).isOk());  // offset 0: the relative surface
  ASSERT_TRUE(device->read(r0.data()).isOk());
  ASSERT_TRUE(device->updateFromDevice(test::gpuBuffer(relative)).isOk());  // the defaults: no offset either
  std::vector<float> r1(6 * n, NAN);
  ASSERT_TRUE(device->read(r1.data()).isOk());
  // The same nodes after 7 nodes of another body (firstNode 7, or the buffer's offset 7 nodes on):
  // the same bits as r.
  cl_mem shared = upload(true, 7);
  const std::size_t nodeBytes = 3 * (dbl ? sizeof(double) : sizeof(float));
  std::vector<float> rs(6 * n, NAN), ro(6 * n, NAN);
  ASSERT_TRUE(device->updateFromDevice(test::gpuBuffer(shared), c, 7).isOk());
  ASSERT_TRUE(device->read(rs.data()).isOk());
  EXPECT_EQ(std::memcmp(rs.data(), r.data(), r.size() * sizeof(float)), 0);
  ASSERT_TRUE(device->updateFromDevice(test::gpuBuffer(shared, 7 * nodeBytes), c).isOk());
  ASSERT_TRUE(device->read(ro.data()).isOk());
  EXPECT_EQ(std::memcmp(ro.data(), r.data(), r.size() * sizeof(float)), 0);
  // An offset inside a node, an empty handle and another API's handle are refused.
  EXPECT_EQ(device->updateFromDevice(test::gpuBuffer(shared, nodeBytes + 4), c).code(), ErrorCode::BadInput);
  EXPECT_EQ(device->updateFromDevice(GpuBuffer{}, c).code(), ErrorCode::BadInput);
  GpuBuffer vulkan = test::gpuBuffer(shared);
  vulkan.api = GpuApi::Vulkan;
  const Status other = device->updateFromDevice(vulkan, c);
  EXPECT_EQ(other.code(), ErrorCode::BadInput);
  EXPECT_NE(other.message().find("not an OpenCL one"), std::string::npos) << other.message();
  // Nodes past the buffer's end are refused, not read.
  const Status tooFar = device->updateFromDevice(test::gpuBuffer(shared), c, 8);
  EXPECT_EQ(tooFar.code(), ErrorCode::BadInput);
  EXPECT_NE(tooFar.message().find("holds " + std::to_string(3 * (7 + nodes) * (dbl ? 8 : 4)) + " bytes (350 nodes of 3 " + (dbl ? "doubles" : "floats") + "), but the surface reads 343 nodes from node 8 on"), std::string::npos) << "message: " << tooFar.message();
  EXPECT_EQ(device->updateFromDevice(test::gpuBuffer(relative), c, 1).code(), ErrorCode::BadInput);
  // A first node whose byte offset would wrap around, and one past 32 bits: refused, not read.
  EXPECT_EQ(device->updateFromDevice(test::gpuBuffer(shared), c, (~std::size_t{0}) / 12 - 100).code(), ErrorCode::BadInput);
  EXPECT_EQ(device->updateFromDevice(test::gpuBuffer(shared), c, std::size_t{1} << 33).code(), ErrorCode::BadInput);
  clReleaseMemObject(shared);
  clReleaseMemObject(absolute);
  clReleaseMemObject(relative);
  SurfaceOutput out;
  out.interleaved = host.data();
  ASSERT_TRUE(deformSurface(s.binding, x.data(), nodes, out).isOk());
  // Tolerances: a float ulp at |x| ~ 100 is 7.6e-6. Absolute float input: each node position rounds by
  // half an ulp of ~100 and the weighted sum (|w| sum <= ~1.5) adds a few more: ~4e-5. Relative input +
  // offset: rounding of ~1 plus the final float rounding at ~100: <= ~1e-5. Double arithmetic only
  // rounds the float output (half an ulp, 3.8e-6). Normals: relative float positions lose about
  // eps * 1 / edge(0.05) ~ 1e-5 in direction (2e-4 as in MatchesHostReference); absolute float input
  // loses ~eps * 100 / 0.05 ~ 2.4e-4 per edge (a few edges per normal: 5e-3) -- the reason the backend
  // keeps positions relative to the centroid.
  const float posAbs = dbl ? 4e-6f : 6e-5f, posRel = dbl ? 4e-6f : 2e-5f;
  const float nAbs = dbl ? 1e-6f : 5e-3f, nRel = dbl ? 1e-6f : 2e-4f;
  float worstAbsPos = 0, worstRelPos = 0, worstAbsN = 0, worstRelN = 0, worstShift = 0, worstOldApi = 0;
  for (std::size_t v = 0; v < n; ++v)
    for (int k = 0; k < 3; ++k) {
      worstAbsPos = std::max(worstAbsPos, std::abs(a[6 * v + k] - host[6 * v + k]));
      worstRelPos = std::max(worstRelPos, std::abs(r[6 * v + k] - host[6 * v + k]));
      worstAbsN = std::max(worstAbsN, std::abs(a[6 * v + 3 + k] - host[6 * v + 3 + k]));
      worstRelN = std::max(worstRelN, std::abs(r[6 * v + 3 + k] - host[6 * v + 3 + k]));
      // Without the offset the positions are the relative ones (shifted by -c); normals are the same bits.
      worstShift = std::max(worstShift, std::abs(r0[6 * v + k] + static_cast<float>(c[k]) - r[6 * v + k]));
      EXPECT_EQ(r0[6 * v + 3 + k], r[6 * v + 3 + k]);
      worstOldApi = std::max(worstOldApi, std::abs(r1[6 * v + k] - r0[6 * v + k]));
    }
  std::printf("[ device   ] worst |position| difference: absolute input %.3g, relative + offset %.3g; normals "
              "%.3g, %.3g\n",
              worstAbsPos, worstRelPos, worstAbsN, worstRelN);
  EXPECT_LE(worstAbsPos, posAbs);
  EXPECT_LE(worstRelPos, posRel);
  EXPECT_LE(worstAbsN, nAbs);
  EXPECT_LE(worstRelN, nRel);
  EXPECT_LE(worstShift, 2e-5f);  // two float roundings at |x| ~ 100 (ulp 7.6e-6)
  EXPECT_EQ(worstOldApi, 0.0f);
}

/// DeviceSurfaceGroup (many bodies' surfaces in one set of launches) gives every body the bits of a
/// DeviceSurface of its own fed from the same shared buffer: three bodies (row-numbered, shuffled,
/// row-numbered) at first nodes 0, 400 and 1000 of one position buffer, each relative to its own
/// centroid far from the origin, at every lane width, in both output layouts. Each body's output is
/// a sub-buffer holding exactly its vertices.
TEST_P(EmbedDevice, GroupOfBodiesMatchesOneSurfaceEach) {
  const bool dbl = GetParam().doublePrecision;
  auto ctx = detail::cl::Context::shared(std::to_string(GetParam().device));
  const EmbedCase rows = makeEmbedCase(false), shuffled = makeEmbedCase(true);
  const EmbedCase* scenes[3] = {&rows, &shuffled, &rows};
  const std::size_t first[3] = {0, 400, 1000}, total = 1400, nodes = rows.tets.nodeCount();
  ASSERT_LE(nodes, 400u);
  const double centroid[3][3] = {{100.25, -37.5, 64.125}, {-20.0, 3.5, 0.25}, {0.0, 0.0, 0.0}};
  std::mt19937 rng(41);
  std::vector<unsigned char> bytes(3 * total * (dbl ? 8 : 4), 0);
  for (int m = 0; m < 3; ++m) {
    const std::vector<double> x = test::SmoothDeformation::random(rng, 1.0, true).apply(scenes[m]->tets.nodes);
    for (std::size_t i = 0; i < x.size(); ++i)
      storeReal(bytes, 3 * first[m] + i, x[i] - 0.5, dbl);  // relative to the centroid (the box's middle)
  }
  cl_int status = CL_SUCCESS;
  cl_mem shared = clCreateBuffer(ctx->context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, bytes.size(), bytes.data(),
                                 &status);
  ASSERT_EQ(status, CL_SUCCESS);
  DeviceSurfaceOptions o = options();
  o.external = test::externalOf(*ctx);
  // The device's lane width in both layouts, and one lane (the GPU configuration); each case builds
  // two programs, so not every combination.
  const std::pair<std::size_t, bool> cases[] = {{0, false}, {0, true}, {1, false}};
  for (const auto& [lanes, separate] : cases) {
    SCOPED_TRACE((lanes ? std::to_string(lanes) : std::string("default")) + " lanes, " +
                 (separate ? "separate" : "interleaved"));
    o.normalPassLanes = lanes;
    o.separateStreams = separate;
    std::vector<detail::DeviceSurfaceGroup::Member> members;
    for (int m = 0; m < 3; ++m) members.push_back({&scenes[m]->binding, first[m]});
    detail::DeviceSurfaceGroup group(members, total, o);
    ASSERT_EQ(group.size(), 3u);
    group.update(shared, {centroid[0], centroid[1], centroid[2]});
    for (int m = 0; m < 3; ++m) {
      SCOPED_TRACE("body " + std::to_string(m));
      const std::size_t n = scenes[m]->binding.vertexCount();
      auto alone = DeviceSurface::create(scenes[m]->binding, o);
      ASSERT_TRUE(alone.isOk()) << alone.message();
      ASSERT_TRUE(alone->updateFromDevice(test::gpuBuffer(shared), centroid[m], first[m]).isOk());
      std::vector<float> p(3 * n, NAN), q(3 * n, NAN), ap(3 * n, NAN), aq(3 * n, NAN);
      group.read(m, p.data(), q.data());
      ASSERT_TRUE(alone->read(ap.data(), aq.data()).isOk());
      EXPECT_EQ(std::memcmp(p.data(), ap.data(), p.size() * sizeof(float)), 0);
      EXPECT_EQ(std::memcmp(q.data(), aq.data(), q.size() * sizeof(float)), 0);
      EXPECT_TRUE(std::isfinite(p[0]) && std::abs(p[0] - centroid[m][0]) < 2.0) << p[0];
      std::size_t size = 0;
      ASSERT_EQ(clGetMemObjectInfo(test::clMem(group.vertexBuffer(m)), CL_MEM_SIZE, sizeof(size), &size, nullptr), CL_SUCCESS);
      EXPECT_EQ(size, (separate ? 3 : 6) * n * sizeof(float));
      EXPECT_EQ(static_cast<bool>(group.normalBuffer(m)), separate);
    }
  }
  clReleaseMemObject(shared);
}

INSTANTIATE_TEST_SUITE_P(Devices, EmbedDevice, ::testing::ValuesIn(deviceCases()),
                         [](const ::testing::TestParamInfo<DeviceCase>& info) { return info.param.name; });

#endif

}  // namespace
}  // namespace corofem
