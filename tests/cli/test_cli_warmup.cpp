// `corofem warmup`: compiles and caches the kernels a scene's plan uses, so that the next run on the
// machine finds them (COROFEM_CACHE_DIR's kernels folder gains the program binaries); an open-ended
// scene is refused by `corofem run` (it would never end) but warmed up like any other.
#include "cli/cli_runner.hpp"

#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/program_cache.hpp"
#endif

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace corofem::test {
namespace {

namespace fs = std::filesystem;

/// A small beam scene written to `dir`, on `backend`, open-ended when steps is 0.
fs::path writeScene(const fs::path& dir, const std::string& backend, int steps) {
  fs::create_directories(dir);
  const fs::path p = dir / "scene.json";
  std::ofstream(p) << R"({"name": "warm", "bodies": [{"name": "b", "mesh": {"box": {"min": [0, 0, 0], "max": [1, 0.1, 0.1],
    "cells": [10, 2, 2]}}, "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3, "density": 1000},
    "fixed": [{"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}}]}],
    "analysis": {"type": "dynamic", "steps": )" << steps << R"(}, "backend": ")" << backend << R"("})";
  return p;
}

/// Files under `dir` whose name ends with `ext` (".clbin": corofem's program binaries; ".so": the
/// kernels PoCL compiled, in its own cache).
std::size_t filesEndingWith(const fs::path& dir, const std::string& ext) {
  std::size_t n = 0;
  if (fs::is_directory(dir))
    for (const auto& e : fs::recursive_directory_iterator(dir)) n += e.path().extension() == ext;
  return n;
}

TEST(CliWarmup, CachesTheKernelsOfTheScenesPlan) {
  const fs::path dir = fs::temp_directory_path() / "corofem_cli_warmup";
  fs::remove_all(dir);
  const fs::path scene = writeScene(dir, "opencl", 0);
  const std::string env = "export COROFEM_CACHE_DIR='" + (dir / "cache").string() + "' POCL_CACHE_DIR='" +
                          (dir / "pocl").string() + "';";
  const CommandResult r = runCli("warmup '" + scene.string() + "'", env);
  // No backend (exit 2) or no device (DeviceError, exit 1): nothing to warm up here.
  if (r.exitCode != 0 && (r.output.find("not compiled") != std::string::npos ||
                          r.output.find("NotCompiledIn") != std::string::npos || r.output.find("no OpenCL") != std::string::npos))
    GTEST_SKIP() << "no OpenCL backend or device here: " << r.output;
  ASSERT_EQ(r.exitCode, 0) << r.output;
  EXPECT_NE(r.output.find("compiled and cached"), std::string::npos) << r.output;
  // corofem's program binaries, or on PoCL (program_cache.hpp, cachesBinaries) the kernels PoCL
  // compiled, in its own cache; the device is the one "opencl" picks (the first GPU, else the first).
#ifdef COROFEM_WITH_OPENCL
  if (detail::cl::cachesBinaries(detail::cl::selectDevice(""))) {
    EXPECT_GE(filesEndingWith(dir / "cache" / "kernels", ".clbin"), 1u) << "warmup left no program binary";
  } else {
    EXPECT_EQ(filesEndingWith(dir / "cache" / "kernels", ".clbin"), 0u) << "a binary asked of PoCL";
    EXPECT_GE(filesEndingWith(dir / "pocl", ".so"), 1u) << "warmup left no kernel in PoCL's cache";
  }
#endif
  // The open-ended scene cannot be run (it would never end); with a step count it runs.
  const CommandResult open = runCli("run '" + scene.string() + "' --quiet --out '" + (dir / "out").string() + "'", env);
  EXPECT_EQ(open.exitCode, 2) << open.output;
  EXPECT_NE(open.output.find("analysis.steps"), std::string::npos) << open.output;
  const CommandResult counted = runCli("run '" + scene.string() + "' --quiet --set analysis.steps=2 --out '" +
                                       (dir / "out").string() + "'", env);
  EXPECT_EQ(counted.exitCode, 0) << counted.output;
  fs::remove_all(dir);
}

TEST(CliWarmup, BadScenesAreBadInput) {
  const CommandResult missing = runCli("warmup /no/such/scene.json");
  EXPECT_NE(missing.exitCode, 0) << missing.output;
  EXPECT_NE(missing.output.find("/no/such/scene.json"), std::string::npos) << missing.output;
  const CommandResult option = runCli("warmup --frobnicate");
  EXPECT_EQ(option.exitCode, 2) << option.output;
  EXPECT_NE(option.output.find("--frobnicate"), std::string::npos) << option.output;
}

}  // namespace
}  // namespace corofem::test
