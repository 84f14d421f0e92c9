// The coupled surface through the Simulation: on the OpenCL backend it is recomputed on the device
// from the backend's own (centroid-relative) position buffer, with no host round trip of the tet
// nodes, and read back explicitly (readSurface) or drawn from surfaceBuffer(); on the
// reference backend it is computed on the host. Both must describe the same deformed surface.
#include <corofem/embed.hpp>
#include <corofem/simulation.hpp>

#include "common/box_surface.hpp"
#include "common/test_data.hpp"
#include "backends/opencl/device_surface.hpp"
#include "common/device_fakes.hpp"
#ifdef COROFEM_WITH_OPENCL
#include "common/gpu_handles.hpp"
#include "backends/opencl/cl_context.hpp"
#endif
#include "solve/beam_helpers.hpp"
#include "util/error.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#ifdef COROFEM_WITH_OPENCL
#include <CL/cl.h>
#endif

namespace corofem {

/// How GoogleTest (and so CTest's test list) prints a precision: its name.
inline void PrintTo(Precision p, std::ostream* os) { *os << toString(p); }

namespace {

using namespace corofem::test;

/// The Fig. 8 beam (0.8 x 0.1 x 0.1 m, E = 2e5 Pa) under gravity, 50 m from the origin (where the
/// backend's centroid-relative positions matter in float), with a sub-box render surface written
/// to a temporary folder. 20 Newmark steps.
Scene surfaceScene(BackendKind backend, Precision precision) {
  const std::array<double, 3> offset{50.0, 20.0, -30.0};
  // The test's own folder (per process: ctest -j runs the tests, and the Morton-forced suite the
  // same tests, as concurrent processes that would rewrite one file).
  const std::filesystem::path dir = test::tempDir();
  const std::string obj = (dir / "inner_box.obj").string();
  const Status written = writeSurfaceMesh(obj, boxSurface({0.02, 0.01, 0.01}, {0.78, 0.09, 0.09}, 8));
  EXPECT_TRUE(written) << written.message();
  BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {0.8, 0.1, 0.1}, {8, 1, 1}), offset[0], 2e5, 0.3, 1000.0,
                                 Formulation::Corotational);
  body.mesh.translate = offset;  // the surface moves with the mesh (scale, then translate)
  body.surface = "inner_box.obj";
  body.loads.push_back(gravity({0, -9.81, 0}));
  body.material.rayleighMass = 4.0;
  Scene scene = staticScene(body, 1, LinearSolverKind::Pcg);
  scene.baseDir = dir.string();
  scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.timeStep = 0.01;
  scene.analysis.dynamics.steps = 20;
  scene.analysis.dynamics.newmarkGamma = 0.6;
  scene.analysis.dynamics.newmarkBeta = 0.3025;
  // Tight in double (the comparison is about the surface, not PCG noise); float reaches ~1e-6.
  scene.solver.tolerance = precision == Precision::Double ? 1e-10 : 1e-6;
  scene.solver.maxIterations = 5000;
  scene.solver.precision = precision;
  scene.backend.kind = backend;
  return scene;
}

struct SurfaceState {
  std::vector<double> positions, nodes;
  std::vector<float> normals;
};

SurfaceState readState(const Simulation& sim) {
  SurfaceState s;
  const Status st = sim.readSurface(0, s.positions, &s.normals);
  EXPECT_TRUE(st) << st.message();
  EXPECT_TRUE(sim.readPositions(0, s.nodes));
  return s;
}

double worstDifference(const std::vector<double>& a, const std::vector<double>& b) {
  double worst = 0;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i) worst = std::max(worst, std::abs(a[i] - b[i]));
  return a.size() == b.size() ? worst : INFINITY;
}
double worstDifference(const std::vector<float>& a, const std::vector<float>& b) {
  double worst = 0;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    worst = std::max(worst, static_cast<double>(std::abs(a[i] - b[i])));
  return a.size() == b.size() ? worst : INFINITY;
}

TEST(EmbedSimulation, ReferenceBackendKeepsTheSurfaceOnTheHost) {
  auto sim = Simulation::create(surfaceScene(BackendKind::Reference, Precision::Double));
  ASSERT_TRUE(sim) << sim.message();
  EXPECT_FALSE(sim->surfaceBuffer(0));
  EXPECT_EQ(sim->surfaceBuffer(0).api, GpuApi::None);
  EXPECT_FALSE(sim->surfaceBuffer(5));  // out of range: empty, no crash
  EXPECT_FALSE(sim->surfaceNormalBuffer(0));
  EXPECT_FALSE(sim->surfaceNormalBuffer(-1));
  const nlohmann::json plan = nlohmann::json::parse(sim->planReport())["bodies"][0]["surface"];
  EXPECT_EQ(plan["where"], "host") << plan.dump(1);
  EXPECT_FALSE(plan.contains("device_buffers_allocated"));
  EXPECT_TRUE(sim->updateSurface(0)) << "nothing to do on the host path";
  EXPECT_EQ(sim->updateSurface(7).code(), ErrorCode::BadInput);
  ASSERT_TRUE(sim->step());
  const SurfaceState s = readState(sim.value());
  EXPECT_EQ(s.positions.size(), 3 * sim->restSurface(0)->vertexCount());
  // The host path is deformSurface of the committed positions, exactly.
  std::vector<double> expected(s.positions.size());
  SurfaceBinding binding = *bindSurface(sim->restMesh(0), *sim->restSurface(0));
  SurfaceOutput out;
  out.positionsDouble = expected.data();
  ASSERT_TRUE(deformSurface(binding, s.nodes.data(), sim->restMesh(0).nodeCount(), out));
  EXPECT_EQ(s.positions, expected);
}

#ifdef COROFEM_WITH_OPENCL

/// The size of a device buffer, as OpenCL reports it.
std::size_t bufferBytes(cl_mem buffer) {
  std::size_t bytes = 0;
  EXPECT_EQ(clGetMemObjectInfo(buffer, CL_MEM_SIZE, sizeof(bytes), &bytes, nullptr), CL_SUCCESS);
  return bytes;
}

/// `count` floats of a device buffer as a renderer would see them: read on a queue of our own, made
/// on the buffer's context (NaN where the read fails).
std::vector<float> drawnFloats(cl_mem buffer, std::size_t count) {
  std::vector<float> out(count, NAN);
  cl_context context = nullptr;
  cl_device_id device = nullptr;
  cl_int status = CL_SUCCESS;
  EXPECT_EQ(clGetMemObjectInfo(buffer, CL_MEM_CONTEXT, sizeof(context), &context, nullptr), CL_SUCCESS);
  EXPECT_EQ(clGetContextInfo(context, CL_CONTEXT_DEVICES, sizeof(device), &device, nullptr), CL_SUCCESS);
  cl_command_queue queue = clCreateCommandQueue(context, device, 0, &status);
  EXPECT_EQ(status, CL_SUCCESS);
  if (status != CL_SUCCESS) return out;
  EXPECT_EQ(clEnqueueReadBuffer(queue, buffer, CL_TRUE, 0, count * sizeof(float), out.data(), 0, nullptr, nullptr),
            CL_SUCCESS);
  clReleaseCommandQueue(queue);
  return out;
}

class EmbedSimulationOpenCL : public ::testing::TestWithParam<Precision> {};

TEST_P(EmbedSimulationOpenCL, DeviceSurfaceMatchesTheReferenceRun) {
  const Precision precision = GetParam();
  const bool dbl = precision == Precision::Double;
  auto sim = Simulation::create(surfaceScene(BackendKind::OpenCL, precision));
  if (!sim && (sim.status().code() == ErrorCode::DeviceError || sim.status().code() == ErrorCode::BadInput))
    GTEST_SKIP() << "no OpenCL device for this precision: " << sim.message();
  ASSERT_TRUE(sim) << sim.message();
  ASSERT_EQ(sim->backendName(), "opencl");
  auto ref = Simulation::create(surfaceScene(BackendKind::Reference, precision));
  ASSERT_TRUE(ref) << ref.message();
  ASSERT_TRUE(sim->surfaceBuffer(0));  // made at create()
  const std::size_t n = sim->restSurface(0)->vertexCount();
  const SurfaceBinding binding = *bindSurface(sim->restMesh(0), *sim->restSurface(0));

  for (int k = 1; k <= 20; ++k) {
    ASSERT_TRUE(sim->step()) << "step " << k;
    ASSERT_TRUE(ref->step()) << "step " << k;
    if (k % 10 != 0) continue;  // lazily: no surface work on the other steps
    const SurfaceState dev = readState(sim.value()), host = readState(ref.value());
    ASSERT_EQ(dev.positions.size(), 3 * n);
    ASSERT_EQ(dev.normals.size(), 3 * n);

    // (a) The device path against deformSurface of the OpenCL run's own committed positions: the
    // float output rounds |x| ~ 50 m to half an ulp (1.9e-6 m, once: the centroid goes in as a
    // float pair, surface_update.cl); float arithmetic on the centroid-relative positions
    // (|x - c| <= 0.5 m) adds a few ulps of 0.5 (~1e-7). Normals: float face
    // vectors of edges ~0.01 m lose eps * 0.5 / 0.01 ~ 6e-6 in direction, a few of them per normal;
    // in double only the float output rounds (6e-8).
    std::vector<double> own(3 * n);
    std::vector<float> ownNormals(3 * n);
    SurfaceOutput out;
    out.positionsDouble = own.data();
    out.normals = ownNormals.data();
    ASSERT_TRUE(deformSurface(binding, dev.nodes.data(), sim->restMesh(0).nodeCount(), out));
    const double ownPos = worstDifference(dev.positions, own), ownN = worstDifference(dev.normals, ownNormals);
    EXPECT_LE(ownPos, 2.5e-6);
    EXPECT_LE(ownN, dbl ? 1e-6 : 1e-4);

    // (b) Against the reference backend's run: the drivers' difference plus the output rounding of
    // (a). The drivers keep the committed positions in double on the host; the device only computes
    // forces and solves, so the node positions differ by the linear solves' error: BackendAgreement
    // < 1e-6 m in double at PCG 1e-10; in float and mixed PCG stops at 1e-6 of a step's ~1 cm
    // displacement, ~1e-8 m per step, a few 1e-7 m over 20 steps at most. Hence 3e-6 m (double) and
    // 5e-6 m (float: half an ulp at 50 m, 1.9e-6, plus that). Normals: the float kernel error of (a)
    // plus the position difference over the edge length (0.01 m): 1e-4 in float; double: 1e-5.
    const double nodes = worstDifference(dev.nodes, host.nodes);
    const double pos = worstDifference(dev.positions, host.positions);
    const double nrm = worstDifference(dev.normals, host.normals);
    std::printf("[ surface  ] %s step %d: nodes %.3g m; surface vs own nodes %.3g m, normals %.3g; vs reference "
                "%.3g m, normals %.3g\n",
                dbl ? "double" : precision == Precision::Mixed ? "mixed" : "float", k, nodes, ownPos, ownN, pos, nrm);
    EXPECT_LE(pos, dbl ? 3e-6 : 5e-6);
    EXPECT_LE(nrm, dbl ? 1e-5 : 1e-4);
  }

  // The buffer as a renderer sees it after explicit synchronisation, read on a queue of our own:
  // 6 floats per vertex, the same numbers readSurface returned.
  ASSERT_TRUE(sim->updateSurface(0));
  const GpuBuffer handle = sim->surfaceBuffer(0);
  EXPECT_EQ(handle.api, GpuApi::OpenCL);
  EXPECT_EQ(handle.offset, 0u);
  EXPECT_EQ(handle.stride, 24u);
  EXPECT_EQ(handle.bytes, 24 * n);
  cl_mem buffer = test::clMem(handle);
  ASSERT_NE(buffer, nullptr);
  EXPECT_FALSE(sim->surfaceNormalBuffer(0));  // interleaved: one buffer
  EXPECT_EQ(bufferBytes(buffer), 6 * sizeof(float) * n);  // 24-byte stride
  const std::vector<float> drawn = drawnFloats(buffer, 6 * n);
  const SurfaceState last = readState(sim.value());
  for (std::size_t v = 0; v < n; ++v)
    for (std::size_t a = 0; a < 3; ++a) {
      EXPECT_EQ(static_cast<double>(drawn[6 * v + a]), last.positions[3 * v + a]) << "vertex " << v;
      EXPECT_EQ(drawn[6 * v + 3 + a], last.normals[3 * v + a]) << "vertex " << v;
    }
}

/// "surface_layout": "separate" gives the renderer two buffers, positions and normals, 3 float32 per
/// vertex, holding bit for bit what the interleaved buffer holds for the same run (both runs are on
/// one device, deterministic: the same node positions). The plan names the layout and lists the
/// surface's device buffers as allocated; readSurface returns the same arrays for both layouts.
TEST(EmbedSimulation, SeparateLayoutHoldsTheInterleavedValuesInTwoBuffers) {
  const Scene one = surfaceScene(BackendKind::OpenCL, Precision::Float);
  Scene two = one;
  two.bodies[0].surfaceLayout = SurfaceLayout::Separate;
  auto interleaved = Simulation::create(one);
  if (!interleaved && interleaved.status().code() == ErrorCode::DeviceError)
    GTEST_SKIP() << "no OpenCL device: " << interleaved.message();
  ASSERT_TRUE(interleaved) << interleaved.message();
  auto separate = Simulation::create(two);
  ASSERT_TRUE(separate) << separate.message();
  for (int k = 1; k <= 5; ++k) {
    ASSERT_TRUE(interleaved->step()) << "interleaved, step " << k;
    ASSERT_TRUE(separate->step()) << "separate, step " << k;
  }
  const std::size_t n = separate->restSurface(0)->vertexCount();

  ASSERT_TRUE(interleaved->updateSurface(0));
  ASSERT_TRUE(separate->updateSurface(0));
  cl_mem both = test::clMem(interleaved->surfaceBuffer(0)), positions = test::clMem(separate->surfaceBuffer(0)),
         normals = test::clMem(separate->surfaceNormalBuffer(0));
  EXPECT_EQ(separate->surfaceBuffer(0).stride, 12u);
  EXPECT_EQ(separate->surfaceNormalBuffer(0).stride, 12u);
  ASSERT_NE(both, nullptr);
  ASSERT_NE(positions, nullptr);
  ASSERT_NE(normals, nullptr);
  EXPECT_NE(positions, normals);
  EXPECT_EQ(bufferBytes(positions), 3 * sizeof(float) * n);  // 12-byte strides
  EXPECT_EQ(bufferBytes(normals), 3 * sizeof(float) * n);
  const std::vector<float> b = drawnFloats(both, 6 * n), p = drawnFloats(positions, 3 * n),
                           q = drawnFloats(normals, 3 * n);
  std::size_t differ = 0;
  for (std::size_t v = 0; v < n; ++v)
    for (std::size_t a = 0; a < 3; ++a) {
      differ += std::memcmp(&b[6 * v + a], &p[3 * v + a], sizeof(float)) != 0;
      differ += std::memcmp(&b[6 * v + 3 + a], &q[3 * v + a], sizeof(float)) != 0;
    }
  EXPECT_EQ(differ, 0u) << "of " << 6 * n << " floats";
  const SurfaceState si = readState(interleaved.value()), ss = readState(separate.value());
  EXPECT_EQ(si.positions, ss.positions);
  EXPECT_EQ(si.normals, ss.normals);
  EXPECT_FALSE(std::isnan(ss.normals.front()));

  // The plan: the layout, the buffers as allocated (their sizes add up, the outputs are the
  // buffers above), and no upload buffer for host positions (the surface reads the solver's own).
  const nlohmann::json plan = nlohmann::json::parse(separate->planReport())["bodies"][0]["surface"];
  EXPECT_EQ(plan["where"], "device") << plan.dump(1);
  EXPECT_EQ(plan["layout"], "separate");
  EXPECT_EQ(plan["vertices"], n);
  std::size_t total = 0;
  std::map<std::string, std::size_t> byName;
  for (const auto& x : plan["device_buffers_allocated"]) {
    total += x["bytes"].get<std::size_t>();
    byName[x["name"].get<std::string>()] = x["bytes"].get<std::size_t>();
  }
  EXPECT_EQ(total, plan["device_bytes_allocated"].get<std::size_t>());
  EXPECT_EQ(byName["output positions"], bufferBytes(positions));
  EXPECT_EQ(byName["output normals"], bufferBytes(normals));
  EXPECT_EQ(byName.count("node positions"), 0u) << plan.dump(1);
  const nlohmann::json planOne = nlohmann::json::parse(interleaved->planReport())["bodies"][0]["surface"];
  EXPECT_EQ(planOne["layout"], "interleaved");
  bool found = false;
  for (const auto& x : planOne["device_buffers_allocated"])
    if (x["name"] == "output vertex") found = x["bytes"].get<std::size_t>() == bufferBytes(both);
  EXPECT_TRUE(found) << planOne.dump(1);
}

/// Bodies with render surfaces share a batch (one set of launches) and each surface is updated on
/// the device from the body's own nodes in the batch's shared position buffer: the same bits as the
/// same bodies run unbatched, one backend each. Three bodies of different stiffness (so they deform
/// differently: reading another body's nodes, a wrong first node, changes a surface; the positions
/// are relative to each body's centroid, so the offset alone would not show it); one with separate
/// streams.
/// surfaceScene's body three times (body0..body2), 2 m apart; `varied`: stiffer each time, and
/// body2's surface in separate streams.
Scene threeSurfaceBodies(bool varied) {
  Scene scene = surfaceScene(BackendKind::OpenCL, Precision::Float);
  const BodyDesc first = scene.bodies[0];
  scene.bodies.clear();
  for (int i = 0; i < 3; ++i) {
    BodyDesc b = first;
    b.name = "body" + std::to_string(i);
    b.mesh.translate[1] += 2.0 * i;
    if (varied) {
      b.material.youngsModulus *= 1.0 + 0.5 * i;
      b.surfaceLayout = i == 2 ? SurfaceLayout::Separate : SurfaceLayout::Interleaved;
    }
    scene.bodies.push_back(b);
  }
  return scene;
}

/// Steps the batched `sim` and its unbatched `ref` (threeSurfaceBodies(true)) 4 times, then for each
/// body: its surface equals ref's bit for bit, positions and normals, and the device buffer a
/// renderer draws (3 floats per vertex for body2's separate streams, else 6) holds those positions.
/// Returns each body's positions; `buffers` gets each body's drawn buffer.
std::vector<std::vector<double>> expectTheUnbatchedSurfaces(Simulation& sim, Simulation& ref,
                                                            std::vector<cl_mem>& buffers) {
  for (int k = 1; k <= 4; ++k) {
    EXPECT_TRUE(sim.step()) << "step " << k;
    EXPECT_TRUE(ref.step()) << "step " << k;
  }
  const std::size_t n = sim.restSurface(0)->vertexCount();
  std::vector<std::vector<double>> all(3);
  for (int i = 0; i < 3; ++i) {
    SCOPED_TRACE("body " + std::to_string(i));
    std::vector<double>& positions = all[static_cast<std::size_t>(i)];
    std::vector<double> refPositions;
    std::vector<float> normals, refNormals;
    EXPECT_TRUE(sim.readSurface(i, positions, &normals));
    EXPECT_TRUE(ref.readSurface(i, refPositions, &refNormals));
    EXPECT_EQ(positions.size(), 3 * n);
    EXPECT_EQ(positions, refPositions);
    EXPECT_EQ(normals, refNormals);
    EXPECT_TRUE(sim.updateSurface(i));
    cl_mem buffer = test::clMem(sim.surfaceBuffer(i));
    buffers.push_back(buffer);
    if (!buffer || positions.size() != 3 * n) {
      ADD_FAILURE() << "no device buffer, or a surface of the wrong size";
      continue;
    }
    const std::size_t stride = i == 2 ? 3 : 6;
    const std::vector<float> drawn = drawnFloats(buffer, stride * n);
    for (std::size_t v = 0; v < n; ++v)
      for (std::size_t a = 0; a < 3; ++a)
        if (static_cast<double>(drawn[stride * v + a]) != positions[3 * v + a]) {
          ADD_FAILURE() << "vertex " << v << ": drawn " << drawn[stride * v + a] << ", read " << positions[3 * v + a];
          v = n;
          break;
        }
  }
  return all;
}

TEST(EmbedSimulation, BatchedBodiesUpdateTheirSurfacesOnTheDevice) {
  const Scene batched = threeSurfaceBodies(true);
  Scene alone = batched;
  alone.backend.batch = false;
  auto sim = Simulation::create(batched);
  if (!sim && sim.status().code() == ErrorCode::DeviceError) GTEST_SKIP() << "no OpenCL device: " << sim.message();
  ASSERT_TRUE(sim) << sim.message();
  auto ref = Simulation::create(alone);
  ASSERT_TRUE(ref) << ref.message();
  const nlohmann::json sched = nlohmann::json::parse(sim->schedulerReport());
  ASSERT_EQ(sched["batches"].size(), 1u) << sched.dump(1);
  EXPECT_EQ(sched["batches"][0]["bodies"].size(), 3u);
  EXPECT_TRUE(nlohmann::json::parse(ref->schedulerReport())["batches"].empty());
  std::vector<cl_mem> buffers;
  const std::vector<std::vector<double>> surfaces = expectTheUnbatchedSurfaces(sim.value(), ref.value(), buffers);
  ASSERT_FALSE(::testing::Test::HasFailure());
  const std::size_t n = sim->restSurface(0)->vertexCount();
  for (int i = 0; i < 3; ++i) {
    SCOPED_TRACE("body " + std::to_string(i));
    const std::vector<double>& positions = surfaces[static_cast<std::size_t>(i)];
    // Against the host's deformSurface of the body's own nodes: within the float output rounding.
    std::vector<double> nodes, own(3 * n);
    ASSERT_TRUE(sim->readPositions(i, nodes));
    SurfaceOutput out;
    out.positionsDouble = own.data();
    const SurfaceBinding binding = *bindSurface(sim->restMesh(i), *sim->restSurface(i));
    ASSERT_TRUE(deformSurface(binding, nodes.data(), sim->restMesh(i).nodeCount(), out));
    EXPECT_LE(worstDifference(positions, own), 2.5e-6);
    EXPECT_EQ(static_cast<bool>(sim->surfaceNormalBuffer(i)), i == 2);
    const nlohmann::json plan = nlohmann::json::parse(sim->planReport())["bodies"][i]["surface"];
    EXPECT_EQ(plan["where"], "device");
    // One set of launches per layout for the batch's surfaces.
    EXPECT_EQ(plan["shared_by"], i == 2 ? nlohmann::json({"body2"}) : nlohmann::json({"body0", "body1"}))
        << plan.dump(1);
  }
  EXPECT_NE(buffers[0], buffers[1]);
  EXPECT_NE(buffers[1], buffers[2]);
}

/// A batch whose merged surfaces the device cannot allocate (injected: the allocation fails as on a
/// device whose largest buffer is too small) still runs batched, and each body gets a surface of its
/// own that reads its nodes from the batch's shared position buffer (DeviceSurface from a first
/// node): the same bits as the bodies run unbatched, drawn from buffers of their own, and the plan
/// says why the surfaces are not shared.
TEST(EmbedSimulation, SurfacesTheDeviceCannotGroupAreEachBodysOwn) {
  const Scene batched = threeSurfaceBodies(true);
  Scene alone = batched;
  alone.backend.batch = false;
  auto ref = Simulation::create(alone);  // first: whether there is a device at all
  if (!ref && ref.status().code() == ErrorCode::DeviceError) GTEST_SKIP() << "no OpenCL device: " << ref.message();
  ASSERT_TRUE(ref) << ref.message();
  // The OpenCL devices of this test cannot hold the surfaces of several bodies together.
  ScopedBackend limited(test::wrapBackend("opencl", [](std::unique_ptr<detail::Device> d, const auto&) {
    class NoSurfaceGroups final : public ForwardingDevice {
     public:
      using ForwardingDevice::ForwardingDevice;
      std::unique_ptr<detail::DeviceSurfaces> createSurfaces(const std::vector<detail::SurfaceMember>& members,
                                                             bool separateStreams) override {
        if (members.size() > 1)
          detail::fail(ErrorCode::DeviceError,
                       "clCreateBuffer failed with CL_MEM_OBJECT_ALLOCATION_FAILURE (injected by the test)");
        return ForwardingDevice::createSurfaces(members, separateStreams);
      }
    };
    return std::unique_ptr<detail::Device>(std::make_unique<NoSurfaceGroups>(std::move(d)));
  }));
  auto sim = Simulation::create(batched);
  ASSERT_TRUE(sim) << "the batch must fall back to a surface per body: " << sim.message();
  const nlohmann::json sched = nlohmann::json::parse(sim->schedulerReport());
  ASSERT_EQ(sched["batches"].size(), 1u) << sched.dump(1);
  EXPECT_EQ(sched["batches"][0]["bodies"].size(), 3u) << "the bodies stay batched";
  std::vector<cl_mem> buffers;
  expectTheUnbatchedSurfaces(sim.value(), ref.value(), buffers);
  ASSERT_FALSE(::testing::Test::HasFailure());
  for (int i = 0; i < 3; ++i) {
    SCOPED_TRACE("body " + std::to_string(i));
    const nlohmann::json plan = nlohmann::json::parse(sim->planReport())["bodies"][i]["surface"];
    EXPECT_EQ(plan["where"], "device");
    if (i == 2) {  // the only body of its layout: its set of one was made
      EXPECT_EQ(plan["shared_by"], nlohmann::json({"body2"})) << plan.dump(1);
      continue;
    }
    EXPECT_FALSE(plan.contains("shared_by")) << plan.dump(1);
    ASSERT_TRUE(plan.contains("not_shared")) << plan.dump(1);
    EXPECT_NE(plan["not_shared"].get<std::string>().find("CL_MEM_OBJECT_ALLOCATION_FAILURE"), std::string::npos)
        << plan.dump(1);
  }
  EXPECT_NE(buffers[0], buffers[1]);
  EXPECT_NE(buffers[1], buffers[2]);
}

/// Surfaces the device cannot make at all (injected: every allocation of them fails) cost them their
/// device buffers, never the Simulation: it is created, steps on the device, and computes the
/// surfaces on the host, which the plan says with the reason.
TEST(EmbedSimulation, SurfacesTheDeviceCannotMakeAreComputedOnTheHost) {
  const Scene scene = threeSurfaceBodies(true);
  ScopedBackend limited(test::wrapBackend("opencl", [](std::unique_ptr<detail::Device> d, const auto&) {
    class NoSurfaces final : public ForwardingDevice {
     public:
      using ForwardingDevice::ForwardingDevice;
      std::unique_ptr<detail::DeviceSurfaces> createSurfaces(const std::vector<detail::SurfaceMember>&, bool) override {
        detail::fail(ErrorCode::DeviceError,
                     "clCreateBuffer failed with CL_MEM_OBJECT_ALLOCATION_FAILURE (injected by the test)");
      }
    };
    return std::unique_ptr<detail::Device>(std::make_unique<NoSurfaces>(std::move(d)));
  }));
  auto sim = Simulation::create(scene);
  if (!sim && sim.status().code() == ErrorCode::DeviceError) GTEST_SKIP() << "no OpenCL device: " << sim.message();
  ASSERT_TRUE(sim) << "surfaces must fall back to the host: " << sim.message();
  EXPECT_EQ(sim->backendName(), "opencl");
  ASSERT_TRUE(sim->step());
  const nlohmann::json plan = nlohmann::json::parse(sim->planReport());
  for (int i = 0; i < 3; ++i) {
    SCOPED_TRACE("body " + std::to_string(i));
    EXPECT_FALSE(sim->surfaceBuffer(i));
    const nlohmann::json& surface = plan["bodies"][i]["surface"];
    EXPECT_EQ(surface["where"], "host") << surface.dump(1);
    EXPECT_NE(surface.value("not_on_device", std::string()).find("injected"), std::string::npos) << surface.dump(1);
    std::vector<double> positions, nodes, own;
    ASSERT_TRUE(sim->readSurface(i, positions));
    ASSERT_TRUE(sim->readPositions(i, nodes));
    own.resize(positions.size());
    SurfaceOutput out;
    out.positionsDouble = own.data();
    const SurfaceBinding binding = *bindSurface(sim->restMesh(i), *sim->restSurface(i));
    ASSERT_TRUE(deformSurface(binding, nodes.data(), sim->restMesh(i).nodeCount(), out));
    EXPECT_EQ(positions, own);
  }
}

/// A batch whose device fails moves, every body of it, to the reference backend: the surfaces are
/// then computed on the host from each body's own nodes (the device buffers are gone) and keep
/// matching them.
TEST(EmbedSimulation, ABatchThatFailsOverComputesItsSurfacesOnTheHost) {
  const Scene scene = threeSurfaceBodies(false);
  ScopedBackend faulty(test::wrapBackend("opencl", [](std::unique_ptr<detail::Device> d, const auto&) {
    return injectFaults(std::move(d), {FaultKind::Launch, 3});
  }));
  auto sim = Simulation::create(scene);
  if (!sim && sim.status().code() == ErrorCode::DeviceError) GTEST_SKIP() << "no OpenCL device: " << sim.message();
  ASSERT_TRUE(sim) << sim.message();
  ASSERT_TRUE(sim->surfaceBuffer(1));  // on the batch's device before the failure
  for (int k = 1; k <= 6; ++k) ASSERT_TRUE(sim->step()) << "step " << k;
  const nlohmann::json sched = nlohmann::json::parse(sim->schedulerReport());
  ASSERT_EQ(sched["fallbacks"].size(), 3u) << sched.dump(1);
  const nlohmann::json plan = nlohmann::json::parse(sim->planReport());
  for (int i = 0; i < 3; ++i) {
    SCOPED_TRACE("body " + std::to_string(i));
    EXPECT_EQ(sched["bodies"][i]["current"], "reference");
    EXPECT_EQ(plan["bodies"][i]["surface"]["where"], "host") << plan.dump(1);
    EXPECT_FALSE(sim->surfaceBuffer(i));
    std::vector<double> positions, nodes, own;
    ASSERT_TRUE(sim->readSurface(i, positions));
    ASSERT_TRUE(sim->readPositions(i, nodes));
    own.resize(positions.size());
    SurfaceOutput out;
    out.positionsDouble = own.data();
    const SurfaceBinding binding = *bindSurface(sim->restMesh(i), *sim->restSurface(i));
    ASSERT_TRUE(deformSurface(binding, nodes.data(), sim->restMesh(i).nodeCount(), out));
    EXPECT_EQ(positions, own);  // the host path, exactly
  }
}

/// An application's own OpenCL context and queue (SimulationOptions::device): every body runs
/// there, with the answer of corofem's own context on that device bit for bit (the same kernels on
/// the same device), the surface's buffer lives in the application's context, and the update the
/// buffer's handout enqueues comes before the application's own work on its in-order queue. The
/// application's objects stay valid after the Simulation is gone.
TEST(EmbedSimulation, TheApplicationsContextHoldsTheBodiesAndTheSurfaceBuffers) {
  const std::vector<detail::cl::DeviceInfo> devices = detail::cl::listDevices();
  if (devices.empty()) GTEST_SKIP() << "no OpenCL device";
  const detail::cl::DeviceInfo info = detail::cl::selectDevice("");
  std::size_t index = 0;
  while (devices[index].device != info.device) ++index;
  cl_int status = CL_SUCCESS;
  cl_context context = clCreateContext(nullptr, 1, &info.device, nullptr, nullptr, &status);
  ASSERT_EQ(status, CL_SUCCESS);
  cl_command_queue queue = clCreateCommandQueue(context, info.device, 0, &status);
  ASSERT_EQ(status, CL_SUCCESS);
  {
    const Scene scene = surfaceScene(BackendKind::OpenCL, Precision::Float);
    SimulationOptions lent, own;
    lent.device = {GpuApi::OpenCL, context, queue, info.device};
    own.devices = {"opencl:" + std::to_string(index)};
    auto sim = Simulation::create(scene, lent);
    ASSERT_TRUE(sim) << sim.message();
    auto ref = Simulation::create(scene, own);
    ASSERT_TRUE(ref) << ref.message();
    const nlohmann::json sched = nlohmann::json::parse(sim->schedulerReport());
    EXPECT_EQ(sched["choice"], "opencl:external (the application's OpenCL device)") << sched.dump(1);
    EXPECT_EQ(sim->deviceName(), ref->deviceName());
    EXPECT_NE(sim->deviceName().find(info.name), std::string::npos) << sim->deviceName();
    for (int k = 1; k <= 3; ++k) {
      ASSERT_TRUE(sim->step()) << "step " << k;
      ASSERT_TRUE(ref->step()) << "step " << k;
    }
    const SurfaceState a = readState(sim.value()), b = readState(ref.value());
    EXPECT_EQ(a.nodes, b.nodes);
    EXPECT_EQ(a.positions, b.positions);
    ASSERT_TRUE(sim->step());
    // The buffer is the application's context's; reading it on the application's queue right after
    // the handout (no updateSurface) sees this step's surface.
    cl_mem buffer = test::clMem(sim->surfaceBuffer(0));
    ASSERT_NE(buffer, nullptr);
    cl_context owner = nullptr;
    ASSERT_EQ(clGetMemObjectInfo(buffer, CL_MEM_CONTEXT, sizeof(owner), &owner, nullptr), CL_SUCCESS);
    EXPECT_EQ(owner, context);
    const std::size_t n = sim->restSurface(0)->vertexCount();
    std::vector<float> drawn(6 * n, NAN);
    ASSERT_EQ(clEnqueueReadBuffer(queue, buffer, CL_TRUE, 0, drawn.size() * sizeof(float), drawn.data(), 0, nullptr,
                                  nullptr),
              CL_SUCCESS);
    const SurfaceState now = readState(sim.value());
    for (std::size_t v = 0; v < n; ++v)
      for (std::size_t c = 0; c < 3; ++c)
        ASSERT_EQ(static_cast<double>(drawn[6 * v + c]), now.positions[3 * v + c]) << "vertex " << v;

    // A body the lent device cannot run (a hyperelastic formulation) runs on the reference backend,
    // and the report says why.
    Scene soft = scene;
    soft.bodies[0].formulation = Formulation::NeoHookean;
    soft.solver.precision = Precision::Double;
    auto onHost = Simulation::create(soft, lent);
    ASSERT_TRUE(onHost) << onHost.message();
    EXPECT_EQ(onHost->backendName(), "reference");
    const nlohmann::json hostReport = nlohmann::json::parse(onHost->schedulerReport());
    EXPECT_NE(hostReport["candidates"][0]["error"].get<std::string>().find("neo"), std::string::npos)
        << hostReport.dump(1);

    // What cannot work is said at create().
    SimulationOptions noQueue = lent;
    noQueue.device.queue = nullptr;
    auto bad = Simulation::create(scene, noQueue);
    ASSERT_FALSE(bad);
    EXPECT_EQ(bad.status().code(), ErrorCode::BadInput);
    EXPECT_NE(bad.message().find("SimulationOptions::device"), std::string::npos) << bad.message();
    SimulationOptions both = lent;
    both.devices = {"reference"};
    auto twice = Simulation::create(scene, both);
    ASSERT_FALSE(twice);
    EXPECT_NE(twice.message().find("not both"), std::string::npos) << twice.message();
    SimulationOptions vulkan = lent;
    vulkan.device.api = GpuApi::Vulkan;
    auto none = Simulation::create(scene, vulkan);  // OpenCL handles named Vulkan: no VkInstance
    ASSERT_FALSE(none);
#ifdef COROFEM_WITH_VULKAN
    EXPECT_EQ(none.status().code(), ErrorCode::BadInput) << none.message();
    EXPECT_NE(none.message().find("instance is null"), std::string::npos) << none.message();
#else
    EXPECT_EQ(none.status().code(), ErrorCode::NotCompiledIn) << none.message();
#endif
  }
  EXPECT_EQ(clFinish(queue), CL_SUCCESS);
  EXPECT_EQ(clReleaseCommandQueue(queue), CL_SUCCESS);
  EXPECT_EQ(clReleaseContext(context), CL_SUCCESS);
}

// Mixed keeps float positions on the device (the float tolerances apply).
INSTANTIATE_TEST_SUITE_P(Precisions, EmbedSimulationOpenCL,
                         ::testing::Values(Precision::Float, Precision::Double, Precision::Mixed),
                         [](const ::testing::TestParamInfo<Precision>& info) {
                           return std::string(info.param == Precision::Double  ? "Double"
                                              : info.param == Precision::Mixed ? "Mixed"
                                                                               : "Float");
                         });

#endif

}  // namespace
}  // namespace corofem
