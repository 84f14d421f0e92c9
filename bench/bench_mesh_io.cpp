// Mesh reader throughput: readTetMesh on the two largest shared Gmsh 4.1 meshes (the whole path a
// user sees: file read, parse, validation), reported as bytes/s of ASCII. Target: >= 50 MB/s.
// Also the OBJ reader on the largest shared surface, and the .vtu writer. Rates use wall-clock time
// (UseRealTime): a reader waits on the file as a user does.
#include <corofem/mesh.hpp>

#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>
#include <string>

namespace {

std::string meshPath(const char* relative) {
  return std::string(COROFEM_SOURCE_DIR) + "/../shared/data/meshes/" + relative;
}

void readTet(benchmark::State& state, const char* relative) {
  const std::string path = meshPath(relative);
  if (!std::filesystem::exists(path)) {
    state.SkipWithError(("mesh file absent: " + path).c_str());
    return;
  }
  const auto bytes = static_cast<std::int64_t>(std::filesystem::file_size(path));
  std::size_t tets = 0;
  for (auto _ : state) {
    auto r = corofem::readTetMesh(path);
    if (!r.isOk()) {
      state.SkipWithError(r.message().c_str());
      return;
    }
    tets = r.value().tetCount();
    benchmark::DoNotOptimize(r.value().nodes.data());
  }
  state.SetBytesProcessed(bytes * state.iterations());
  state.counters["tets"] = double(tets);
  state.counters["tets/s"] = benchmark::Counter(double(tets), benchmark::Counter::kIsIterationInvariantRate);
}

void readObj(benchmark::State& state, const char* relative) {
  const std::string path = meshPath(relative);
  if (!std::filesystem::exists(path)) {
    state.SkipWithError(("mesh file absent: " + path).c_str());
    return;
  }
  const auto bytes = static_cast<std::int64_t>(std::filesystem::file_size(path));
  for (auto _ : state) {
    auto r = corofem::readSurfaceMesh(path);
    if (!r.isOk()) {
      state.SkipWithError(r.message().c_str());
      return;
    }
    benchmark::DoNotOptimize(r.value().vertices.data());
  }
  state.SetBytesProcessed(bytes * state.iterations());
}

void writeVtu(benchmark::State& state) {
  const std::string path = meshPath("ipc/Armadillo13K.msh");
  if (!std::filesystem::exists(path)) {
    state.SkipWithError(("mesh file absent: " + path).c_str());
    return;
  }
  const auto mesh = corofem::readTetMesh(path);
  const std::string out = (std::filesystem::temp_directory_path() / "corofem_bench_mesh_io.vtu").string();
  for (auto _ : state) {
    const corofem::Status st = corofem::writeTetMesh(out, mesh.value());
    if (!st.isOk()) {
      state.SkipWithError(st.message().c_str());
      return;
    }
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(std::filesystem::file_size(out)) * state.iterations());
  std::remove(out.c_str());
}

}  // namespace

BENCHMARK_CAPTURE(readTet, Armadillo13K_gmsh41, "ipc/Armadillo13K.msh")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(readTet, rod300x33_gmsh41, "ipc/rod300x33.msh")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(readTet, dolphin5K_gmsh22, "ipc/dolphin5K.msh")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(readTet, wheelset_vtk51, "sfepy/wheelset.vtk")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(readObj, simpleBridge_obj, "vega/simpleBridge/simpleBridge.obj")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(writeVtu)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
