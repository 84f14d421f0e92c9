// Coupled mesh (paper Section 5) on the host: binding time (Vega bridge; 1M vertices in a 100k-element
// box) and the per-frame surface update (positions + normals) for 1M vertices.
//
//   build-*/bench/bench_embed --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
//
// Counters: items_per_second = surface vertices per second; bytes_per_second (per-frame update) =
// the compulsory memory traffic of one frame (every binding array read once, the double scratch
// positions written and read once, the output written once, the tet node positions read once) per
// second, to compare with the machine's bandwidth (DESIGN.md: ~33 GB/s single-thread triad).
#include <corofem/embed.hpp>
#include <corofem/mesh.hpp>

#include "embed/embed_test_util.hpp"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <random>
#include <vector>

#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/program_cache.hpp"
#endif

namespace {

using namespace corofem;

/// 20 x 20 x 50 cells of 0.05 m, 5 tets each: 100000 elements, 22491 nodes.
const TetMesh& box100k() {
  static const TetMesh mesh = [] {
    BoxSpec spec;
    spec.min = {0.0, 0.0, 0.0};
    spec.max = {1.0, 1.0, 2.5};
    spec.cells = {20, 20, 50};
    auto r = generateBox(spec);
    if (!r) {
      std::fprintf(stderr, "generateBox: %s\n", r.message().c_str());
      std::abort();
    }
    return std::move(r).value();
  }();
  return mesh;
}

/// UV sphere of radius 0.45 m inside the box: 999 x 1000 + 2 = 999002 vertices, 1998000 triangles.
const SurfaceMesh& sphere1M() {
  static const SurfaceMesh surface = test::uvSphere({0.5, 0.5, 1.25}, 0.45, 1000, 1000);
  return surface;
}

/// 1M uniformly random points in a box 2% larger than the tet mesh (about 6% of them outside).
const SurfaceMesh& cloud1M() {
  static const SurfaceMesh surface = [] {
    std::mt19937 rng(1);
    std::uniform_real_distribution<double> u(-0.01, 1.01), w(-0.025, 2.525);
    SurfaceMesh s;
    s.vertices.reserve(3000000);
    for (int i = 0; i < 1000000; ++i) s.vertices.insert(s.vertices.end(), {u(rng), u(rng), w(rng)});
    return s;
  }();
  return surface;
}

std::string dataFile(const char* relative) {
  const char* env = std::getenv("COROFEM_DATA_DIR");
  const std::filesystem::path root =
      env ? std::filesystem::path(env) : std::filesystem::path(COROFEM_SOURCE_DIR) / ".." / "shared" / "data";
  return (root / relative).string();
}

void bindAndCount(benchmark::State& state, const TetMesh& tets, const SurfaceMesh& surface) {
  BindingOptions options;
  options.threads = static_cast<int>(state.range(0));
  std::size_t outside = 0;
  for (auto _ : state) {
    auto b = bindSurface(tets, surface, options);
    if (!b) {
      state.SkipWithError(b.message().c_str());
      return;
    }
    outside = b->statistics.outsideCount;
    benchmark::DoNotOptimize(b->weights.data());
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * surface.vertexCount()));
  state.counters["vertices"] = static_cast<double>(surface.vertexCount());
  state.counters["elements"] = static_cast<double>(tets.tetCount());
  state.counters["outside"] = static_cast<double>(outside);
}

void BM_BindBridge(benchmark::State& state) {
  static std::unique_ptr<std::pair<TetMesh, SurfaceMesh>> bridge;
  if (!bridge) {
    auto t = readTetMesh(dataFile("meshes/vega/simpleBridge/simpleBridge-ic_128_0.15_.1.veg"));
    auto s = readSurfaceMesh(dataFile("meshes/vega/simpleBridge/simpleBridge.obj"));
    if (!t || !s) {
      state.SkipWithError("shared data (../shared/data/meshes/vega/simpleBridge) is absent");
      return;
    }
    bridge = std::make_unique<std::pair<TetMesh, SurfaceMesh>>(std::move(t).value(), std::move(s).value());
  }
  bindAndCount(state, bridge->first, bridge->second);
}
BENCHMARK(BM_BindBridge)->Arg(1)->Arg(2)->ArgName("threads")->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_BindSphere1M_Box100k(benchmark::State& state) { bindAndCount(state, box100k(), sphere1M()); }
BENCHMARK(BM_BindSphere1M_Box100k)->Arg(1)->Arg(2)->ArgName("threads")->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

void BM_BindCloud1M_Box100k(benchmark::State& state) { bindAndCount(state, box100k(), cloud1M()); }
BENCHMARK(BM_BindCloud1M_Box100k)->Arg(1)->Arg(2)->ArgName("threads")->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

/// The per-frame update of the 1M-vertex sphere. range(0): threads; range(1): 1 = interleaved
/// position+normal float buffer, 0 = float positions only (no normals).
void BM_DeformSphere1M(benchmark::State& state) {
  static std::unique_ptr<SurfaceBinding> binding;
  if (!binding) {
    auto b = bindSurface(box100k(), sphere1M());
    if (!b) {
      state.SkipWithError(b.message().c_str());
      return;
    }
    binding = std::make_unique<SurfaceBinding>(std::move(b).value());
  }
  std::mt19937 rng(2);
  const std::vector<double> x = test::SmoothDeformation::random(rng, 2.5, true).apply(box100k().nodes);
  const bool normals = state.range(1) != 0;
  const std::size_t n = binding->vertexCount();
  std::vector<float> out((normals ? 6 : 3) * n);
  SurfaceOutput o;
  (normals ? o.interleaved : o.positions) = out.data();
  o.threads = static_cast<int>(state.range(0));
  for (auto _ : state) {
    const Status s = deformSurface(*binding, x.data(), box100k().nodeCount(), o);
    if (!s) {
      state.SkipWithError(s.message().c_str());
      return;
    }
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  // Compulsory traffic of one frame (bytes): nodes + weights (16 + 32 per vertex), tet node positions,
  // the output; with normals also the double position scratch (written, read), the triangle list, the
  // double face vectors (written, read) and the CSR adjacency. Positions only: the weighted sum goes
  // straight to the float output.
  double bytes = 48.0 * n + 24.0 * box100k().nodeCount() + 4.0 * out.size();
  if (normals)
    bytes += 48.0 * n + 20.0 * binding->triangles.size() +  // per index: 4 B + 16 B of face vector
             4.0 * (binding->vertexTriangleOffsets.size() + binding->vertexTriangles.size());
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * n));
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * bytes));
  state.counters["bytes_per_vertex"] = bytes / static_cast<double>(n);
}
BENCHMARK(BM_DeformSphere1M)
    ->Args({1, 1})
    ->Args({2, 1})
    ->Args({1, 0})
    ->Args({2, 0})
    ->ArgNames({"threads", "normals"})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

#ifdef COROFEM_WITH_OPENCL
/// The same update on the OpenCL device ("" = first GPU, else first device; $COROFEM_DEVICE
/// overrides). range(0): 1 = double on the device, 0 = float. Each frame: upload the 22491 node
/// positions (converted to the device precision), the three kernels, finish(); no read-back.
void BM_DeviceSurface1M(benchmark::State& state) {
  static std::unique_ptr<SurfaceBinding> binding;
  if (!binding) {
    auto b = bindSurface(box100k(), sphere1M());
    if (!b) {
      state.SkipWithError(b.message().c_str());
      return;
    }
    binding = std::make_unique<SurfaceBinding>(std::move(b).value());
  }
  DeviceSurfaceOptions options;
  if (const char* env = std::getenv("COROFEM_DEVICE")) options.device = env;
  options.doublePrecision = state.range(0) != 0;
  auto device = DeviceSurface::create(*binding, options);
  if (!device) {
    state.SkipWithError(device.message().c_str());
    return;
  }
  std::mt19937 rng(2);
  const std::vector<double> x = test::SmoothDeformation::random(rng, 2.5, true).apply(box100k().nodes);
  for (int warm = 0; warm < 2; ++warm)  // PoCL specialises kernels on their first launches
    if (!device->update(x.data(), box100k().nodeCount()) || !device->finish()) {
      state.SkipWithError("warm-up update failed");
      return;
    }
  for (auto _ : state) {
    const Status s = device->update(x.data(), box100k().nodeCount());
    const Status f = device->finish();
    if (!s || !f) {
      state.SkipWithError((s ? f : s).message().c_str());
      return;
    }
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * binding->vertexCount()));
  state.SetLabel(device->deviceName());
}
BENCHMARK(BM_DeviceSurface1M)->Arg(0)->Arg(1)->ArgName("double")->Unit(benchmark::kMillisecond)->UseRealTime();

/// Device bandwidth (bytes/s) measured with the copy kernel of bandwidth.cl on 64 MiB buffers (read +
/// write counted), median of 9 runs after a warm-up; the approach of bench_opencl.cpp.
double measuredBandwidth(detail::cl::Context& ctx) {
  static double cached = 0;
  if (cached > 0) return cached;
  const auto build = detail::cl::buildProgram(ctx, "corofem", detail::cl::corofemProgramSource(),
                                              "-cl-std=CL1.2 -DCOROFEM_WG=64");
  cl_int status = CL_SUCCESS;
  cl_kernel k = clCreateKernel(build.program, "bandwidth_copy", &status);
  const std::size_t bytes = 64u << 20, count = bytes / 16;
  cl_mem a = clCreateBuffer(ctx.context(), CL_MEM_READ_WRITE, bytes, nullptr, &status);
  cl_mem b = clCreateBuffer(ctx.context(), CL_MEM_READ_WRITE, bytes, nullptr, &status);
  const float one = 1.0f;
  clEnqueueFillBuffer(ctx.queue(), a, &one, sizeof(one), 0, bytes, 0, nullptr, nullptr);
  cl_uint n = static_cast<cl_uint>(count);
  clSetKernelArg(k, 0, sizeof(n), &n);
  clSetKernelArg(k, 1, sizeof(cl_mem), &a);
  clSetKernelArg(k, 2, sizeof(cl_mem), &b);
  std::vector<double> times;
  for (int rep = 0; rep < 10; ++rep) {
    const std::size_t global = count, local = 256;
    const auto t0 = std::chrono::steady_clock::now();
    clEnqueueNDRangeKernel(ctx.queue(), k, 1, nullptr, &global, &local, 0, nullptr, nullptr);
    clFinish(ctx.queue());
    const auto t1 = std::chrono::steady_clock::now();
    if (rep > 0) times.push_back(std::chrono::duration<double>(t1 - t0).count());  // first: warm-up
  }
  std::sort(times.begin(), times.end());
  clReleaseMemObject(a);
  clReleaseMemObject(b);
  clReleaseKernel(k);
  cached = 2.0 * bytes / times[times.size() / 2];
  std::fprintf(stderr, "[bench_embed] %s: copy bandwidth %.1f GB/s\n", ctx.deviceName().c_str(), cached / 1e9);
  return cached;
}

/// updateFromDevice alone: the node positions are already on the device (as the OpenCL backend keeps
/// them, relative to the centroid, which the kernel adds back), so a frame is the three kernels and
/// finish(), no upload, no read-back. range(0): 1 = double, 0 = float.
///
/// bytes_per_vertex, the compulsory traffic of one frame per surface vertex (r = 4 or 8 bytes per
/// real, T = triangles, N = tet nodes, n = vertices; every array touched once, caches assumed to hold
/// the reuse):
///   pass 1  node indices 16 + weights 4r read, positions 3r written; node positions 3r N / n gathered
///   pass 2  triangle indices 12 T / n and positions 3r read, face vectors 3r T / n written
///   pass 3  CSR offsets 4 + incidence 12 T / n, face vectors 3r T / n and positions 3r read, output 24 written
/// (UV sphere: T / n ~ 2, N / n ~ 0.02: 192 B in float, 293 B in double). bandwidth_fraction = that
/// traffic per second over the copy kernel's bandwidth on the same device.
void BM_DeviceSurfaceFromDevice1M(benchmark::State& state) {
  static std::unique_ptr<SurfaceBinding> binding;
  if (!binding) {
    auto b = bindSurface(box100k(), sphere1M());
    if (!b) {
      state.SkipWithError(b.message().c_str());
      return;
    }
    binding = std::make_unique<SurfaceBinding>(std::move(b).value());
  }
  const bool dbl = state.range(0) != 0;
  std::shared_ptr<detail::cl::Context> ctx;
  try {
    const char* env = std::getenv("COROFEM_DEVICE");
    ctx = detail::cl::Context::shared(env ? env : "");
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
    return;
  }
  DeviceSurfaceOptions options;
  options.doublePrecision = dbl;
  options.context = ctx->context();
  options.queue = ctx->queue();
  options.deviceId = ctx->device();
  auto device = DeviceSurface::create(*binding, options);
  if (!device) {
    state.SkipWithError(device.message().c_str());
    return;
  }
  // Node positions relative to their centroid, in the device precision, uploaded once.
  std::mt19937 rng(2);
  const std::vector<double> x = test::SmoothDeformation::random(rng, 2.5, true).apply(box100k().nodes);
  const std::size_t nodes = box100k().nodeCount(), n = binding->vertexCount(), t = binding->triangles.size() / 3;
  double c[3] = {0, 0, 0};
  for (std::size_t i = 0; i < 3 * nodes; ++i) c[i % 3] += x[i] / static_cast<double>(nodes);
  std::vector<double> rel(3 * nodes);
  std::vector<float> relF(3 * nodes);
  for (std::size_t i = 0; i < 3 * nodes; ++i) relF[i] = static_cast<float>(rel[i] = x[i] - c[i % 3]);
  cl_int status = CL_SUCCESS;
  cl_mem positions = clCreateBuffer(ctx->context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR,
                                    3 * nodes * (dbl ? 8 : 4), dbl ? static_cast<void*>(rel.data()) : relF.data(),
                                    &status);
  if (status != CL_SUCCESS) {
    state.SkipWithError("clCreateBuffer (node positions) failed");
    return;
  }
  for (int warm = 0; warm < 2; ++warm)  // PoCL specialises kernels on their first launches
    if (!device->updateFromDevice(positions, c) || !device->finish()) {
      clReleaseMemObject(positions);
      state.SkipWithError("warm-up update failed");
      return;
    }
  for (auto _ : state) {
    const Status s = device->updateFromDevice(positions, c);
    const Status f = device->finish();
    if (!s || !f) {
      state.SkipWithError((s ? f : s).message().c_str());
      break;
    }
  }
  clReleaseMemObject(positions);
  const double r = dbl ? 8.0 : 4.0, tn = static_cast<double>(t) / static_cast<double>(n);
  const double bytesPerVertex = (16 + 4 * r + 3 * r + 3 * r * static_cast<double>(nodes) / static_cast<double>(n)) +
                                (12 * tn + 3 * r + 3 * r * tn) + (4 + 12 * tn + 3 * r * tn + 3 * r + 24);
  const double bandwidth = measuredBandwidth(*ctx);
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * n));
  state.SetBytesProcessed(static_cast<std::int64_t>(static_cast<double>(state.iterations()) * bytesPerVertex *
                                                    static_cast<double>(n)));
  state.counters["bytes_per_vertex"] = bytesPerVertex;
  state.counters["copy_GBps"] = bandwidth / 1e9;
  state.counters["bandwidth_fraction"] = benchmark::Counter(
      static_cast<double>(state.iterations()) * bytesPerVertex * static_cast<double>(n) / bandwidth,
      benchmark::Counter::kIsRate);
  state.SetLabel(device->deviceName());
}
BENCHMARK(BM_DeviceSurfaceFromDevice1M)->Arg(0)->Arg(1)->ArgName("double")->Unit(benchmark::kMillisecond)->UseRealTime();
#endif

}  // namespace

BENCHMARK_MAIN();
