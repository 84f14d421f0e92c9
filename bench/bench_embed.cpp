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
#include "mesh/locality_order.hpp"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <random>
#include <vector>

#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/program_cache.hpp"
#include "bench_bandwidth.hpp"
#include "backends/opencl/device_surface.hpp"
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
/// Numbered row by row (test::uvSphere): north pole 0, then 999 rings of 1000 vertices, south pole
/// last; a vertex's one-ring is v +- 1 and two neighbours in each adjacent ring (v +- 1000, v +- 999 or
/// 1001), so the rings of consecutive vertices are consecutive vertices (except across the seam and
/// at the poles, each pole has 1000 triangles).
const SurfaceMesh& sphere1M() {
  static const SurfaceMesh surface = test::uvSphere({0.5, 0.5, 1.25}, 0.45, 1000, 1000);
  return surface;
}

/// The same sphere renumbered along a Morton (Z-order) curve of the rest positions, as a mesh
/// generator or a locality-preserving reordering leaves an unstructured mesh: neighbours stay close
/// in memory, but consecutive vertices' one-rings are no longer consecutive vertices.
const SurfaceMesh& sphere1MMorton() {
  static const SurfaceMesh surface = [] {
    const SurfaceMesh& s = sphere1M();
    const std::size_t n = s.vertexCount();
    std::vector<std::pair<std::uint64_t, std::uint32_t>> keys(n);
    for (std::size_t v = 0; v < n; ++v) {
      std::uint64_t key = 0;
      for (int a = 0; a < 3; ++a) {  // the sphere lies in [0.05, 0.95] x [0.05, 0.95] x [0.8, 1.7]
        const double lo = a < 2 ? 0.05 : 0.8, t = (s.vertices[3 * v + a] - lo) / 0.9;
        key |= detail::mortonSpreadBits(static_cast<std::uint64_t>(std::clamp(t, 0.0, 1.0) * 2097151.0)) << a;
      }
      keys[v] = {key, static_cast<std::uint32_t>(v)};
    }
    std::sort(keys.begin(), keys.end());
    std::vector<std::uint32_t> newIndex(n);
    SurfaceMesh m;
    m.vertices.resize(3 * n);
    for (std::size_t i = 0; i < n; ++i) {
      newIndex[keys[i].second] = static_cast<std::uint32_t>(i);
      for (int a = 0; a < 3; ++a) m.vertices[3 * i + a] = s.vertices[3 * keys[i].second + a];
    }
    m.triangles.resize(s.triangles.size());
    for (std::size_t i = 0; i < s.triangles.size(); ++i) m.triangles[i] = newIndex[s.triangles[i]];
    return m;
  }();
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
/// positions (converted to the device precision), the kernels, finish(); no read-back.
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

/// updateFromDevice alone: the node positions are already on the device (as the OpenCL backend keeps
/// them, relative to the centroid, which the kernel adds back), so a frame is the kernels and
/// finish(), no upload, no read-back. range(0): 1 = double, 0 = float; range(1): 0 = the sphere's
/// own row-by-row numbering (sphere1M), 1 = renumbered along a Morton curve (sphere1MMorton: the
/// normal pass gathers its neighbours lane by lane instead of loading them as vectors); range(2): 1 =
/// the output as two separate streams (DeviceSurfaceOptions::separateStreams; the same bytes).
///
/// bytes_per_vertex: the least traffic one frame of this layout moves, per surface vertex (r = 4 or 8
/// bytes per real, n = vertices, N = 22491 tet nodes, K = ring slots per vertex; each array counted
/// once, caches assumed to hold the reuse, e.g. a neighbour's position read again by the next
/// vertex, or the 1 MB of node positions):
///   pass 1 (positions)  node indices 16 + weights 4r read, the 3r position scratch written, node
///                       positions 3r N / n read;
///   pass 2 (normals)    the ring entries read (4 bytes each: K per vertex, but none for a slot
///                       that holds consecutive vertices across its block of vector lanes) and the
///                       blocks' K + 1 run words, the 3r scratch read, the 24-byte output vertex
///                       written;
///   pass 3 (long rings) per such vertex 8 bytes of index + 4 per ring entry read, 12 written.
/// (UV sphere: K = 6, 2 poles of 1000 entries: 104.3 B in float, 144.5 B in double, when every
/// slot's entries are read; with the runs, fewer: ring_bytes_per_vertex says how many.) Not counted, as
/// this design no longer moves them: triangles, face vectors, the triangle CSR. The 12 / 24 MB
/// scratch may stay in the 32 MB L3 between the passes; it is counted as moved anyway (written and
/// read). bandwidth_fraction = (bytes / time) / the copy kernel's bandwidth on the same device, in
/// the same run (measuredBandwidth).
void BM_DeviceSurfaceFromDevice1M(benchmark::State& state) {
  const bool dbl = state.range(0) != 0, morton = state.range(1) != 0, separate = state.range(2) != 0;
  static std::unique_ptr<SurfaceBinding> bindings[2];
  std::unique_ptr<SurfaceBinding>& binding = bindings[morton ? 1 : 0];
  if (!binding) {
    auto b = bindSurface(box100k(), morton ? sphere1MMorton() : sphere1M());
    if (!b) {
      state.SkipWithError(b.message().c_str());
      return;
    }
    binding = std::make_unique<SurfaceBinding>(std::move(b).value());
  }
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
  options.separateStreams = separate;
  options.external = {GpuApi::OpenCL, ctx->context(), ctx->queue(), ctx->device()};
  auto device = DeviceSurface::create(*binding, options);
  if (!device) {
    state.SkipWithError(device.message().c_str());
    return;
  }
  // Node positions relative to their centroid, in the device precision, uploaded once.
  std::mt19937 rng(2);
  const std::vector<double> x = test::SmoothDeformation::random(rng, 2.5, true).apply(box100k().nodes);
  const std::size_t nodes = box100k().nodeCount(), n = binding->vertexCount();
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
    if (!device->updateFromDevice(detail::cl::bufferOf(positions), c) || !device->finish()) {
      clReleaseMemObject(positions);
      state.SkipWithError("warm-up update failed");
      return;
    }
  for (auto _ : state) {
    const Status s = device->updateFromDevice(detail::cl::bufferOf(positions), c);
    const Status f = device->finish();
    if (!s || !f) {
      state.SkipWithError((s ? f : s).message().c_str());
      break;
    }
  }
  clReleaseMemObject(positions);
  const detail::DeviceSurfaceLayout layout =
      detail::deviceSurfaceLayout(*binding, detail::surfaceLanes(ctx->info().gpu, dbl));  // create() took it
  const double r = dbl ? 8.0 : 4.0, nv = static_cast<double>(n);
  const double bytes = nv * (16 + 4 * r + 3 * r) + 3 * r * static_cast<double>(nodes) +        // pass 1
                       4.0 * static_cast<double>(layout.ringEntriesRead + layout.runWords) +  // pass 2
                       nv * (3 * r + 24) +
                       static_cast<double>(layout.overflowVertices) * (8 + 12) +                // pass 3
                       4.0 * static_cast<double>(layout.overflowEntries);
  const double bandwidth = bench::measuredBandwidth(*ctx, "bench_embed");
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * n));
  state.SetBytesProcessed(static_cast<std::int64_t>(static_cast<double>(state.iterations()) * bytes));
  state.counters["bytes_per_vertex"] = bytes / nv;
  state.counters["ring_slots"] = static_cast<double>(layout.slots);
  state.counters["ring_bytes_per_vertex"] = 4.0 * static_cast<double>(layout.ringEntriesRead + layout.runWords) / nv;
  state.counters["copy_GBps"] = bandwidth / 1e9;
  state.counters["bandwidth_fraction"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * bytes / bandwidth, benchmark::Counter::kIsRate);
  state.SetLabel(device->deviceName());
}
BENCHMARK(BM_DeviceSurfaceFromDevice1M)
    ->Args({0, 0, 0})
    ->Args({1, 0, 0})
    ->Args({0, 1, 0})
    ->Args({1, 1, 0})
    ->Args({0, 0, 1})
    ->ArgNames({"double", "morton", "separate"})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()  // CPU: all threads of the process (PoCL's workers)
    ->UseRealTime();
#endif

}  // namespace

BENCHMARK_MAIN();
