// Program cache (memory per context, disk binaries), build-failure reporting, and the backend's
// error messages (unsupported formulation, bad device selector, missing double precision).
#include "backends/opencl/opencl_backend.hpp"
#include "backends/opencl/program_cache.hpp"
#include "opencl/opencl_test_support.hpp"
#include "common/test_data.hpp"
#include "util/error.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace corofem {
namespace {

namespace fs = std::filesystem;
using test::DeviceCase;

const char* kTinySource = R"(
__kernel void scale(__global float* v, const float s) { v[get_global_id(0)] *= s; }
)";

/// Points $COROFEM_CACHE_DIR at a fresh folder for the test (the kernel cache is its kernels/
/// folder, `dir`), restoring it afterwards.
class ScopedCacheDir {
 public:
  explicit ScopedCacheDir(const fs::path& dir) : dir_(dir) {
    if (const char* old = std::getenv("COROFEM_CACHE_DIR")) old_ = old, hadOld_ = true;
    setenv("COROFEM_CACHE_DIR", dir.parent_path().string().c_str(), 1);
  }
  ~ScopedCacheDir() {
    if (hadOld_) setenv("COROFEM_CACHE_DIR", old_.c_str(), 1);
    else unsetenv("COROFEM_CACHE_DIR");
  }
  const fs::path& dir() const { return dir_; }

 private:
  fs::path dir_;
  std::string old_;
  bool hadOld_ = false;
};

class OpenCLProgramCache : public ::testing::TestWithParam<DeviceCase> {
 protected:
  std::string selector() const { return std::to_string(GetParam().device); }
};

// The disk cache's tests ask for it on every device (BinaryCache::Always): PoCL's devices, the only
// ones in CI, do not use it by default (cachesBinaries; the tests after these).
constexpr auto kAlways = detail::cl::BinaryCache::Always;

TEST_P(OpenCLProgramCache, SecondBuildOnANewContextComesFromDisk) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  ScopedCacheDir cache(test::tempDir() / "kernels");
  auto ctx1 = detail::cl::Context::create(selector());
  const auto first = detail::cl::buildProgram(*ctx1, "tiny", kTinySource, "-DTINY=1", kAlways);
  EXPECT_EQ(first.origin, detail::cl::ProgramOrigin::Compiled);
  ASSERT_FALSE(first.cacheFile.empty());
  EXPECT_TRUE(fs::exists(first.cacheFile)) << first.cacheFile;
  EXPECT_EQ(fs::path(first.cacheFile).parent_path(), cache.dir());
  // Same context: memory.
  EXPECT_EQ(detail::cl::buildProgram(*ctx1, "tiny", kTinySource, "-DTINY=1", kAlways).origin,
            detail::cl::ProgramOrigin::Memory);
  // New context: the binary on disk.
  auto ctx2 = detail::cl::Context::create(selector());
  const auto second = detail::cl::buildProgram(*ctx2, "tiny", kTinySource, "-DTINY=1", kAlways);
  EXPECT_EQ(second.origin, detail::cl::ProgramOrigin::Disk);
  EXPECT_EQ(second.cacheFile, first.cacheFile);
  // Other options or source: another file.
  const auto other = detail::cl::buildProgram(*ctx2, "tiny", kTinySource, "-DTINY=2", kAlways);
  EXPECT_EQ(other.origin, detail::cl::ProgramOrigin::Compiled);
  EXPECT_NE(other.cacheFile, first.cacheFile);
}

TEST_P(OpenCLProgramCache, CorruptedCacheFileIsRebuiltNotFatal) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  ScopedCacheDir cache(test::tempDir() / "kernels");
  auto ctx1 = detail::cl::Context::create(selector());
  const auto first = detail::cl::buildProgram(*ctx1, "tiny", kTinySource, "", kAlways);
  ASSERT_TRUE(fs::exists(first.cacheFile));
  const auto goodSize = fs::file_size(first.cacheFile);
  for (const std::string garbage : {std::string("not a binary at all"), std::string()}) {
    {
      std::ofstream out(first.cacheFile, std::ios::binary | std::ios::trunc);
      out << garbage;
    }
    auto ctx = detail::cl::Context::create(selector());
    const auto again = detail::cl::buildProgram(*ctx, "tiny", kTinySource, "", kAlways);
    EXPECT_EQ(again.origin, detail::cl::ProgramOrigin::Compiled);
    ASSERT_NE(again.program, nullptr);
    // Rewritten with a real binary (the size may differ by a few bytes between compilations),
    // which the next context loads.
    EXPECT_GT(fs::file_size(first.cacheFile), goodSize / 2) << "the cache file was rewritten";
    auto next = detail::cl::Context::create(selector());
    EXPECT_EQ(detail::cl::buildProgram(*next, "tiny", kTinySource, "", kAlways).origin,
              detail::cl::ProgramOrigin::Disk);
  }
}

TEST_P(OpenCLProgramCache, BackendCreationUsesTheDiskCacheWhereTheDeviceCachesBinaries) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  ScopedCacheDir cache(test::tempDir() / "kernels");
  const detail::Problem p = test::makeProblem(test::cellBox(2, 1, 1));
  SolverDesc s;
  s.precision = GetParam().precision;
  auto b1 = test::openclOn(p, s, detail::cl::Context::create(selector()));
  auto b2 = test::openclOn(p, s, detail::cl::Context::create(selector()));
  EXPECT_EQ(b1->programOrigin(), detail::cl::ProgramOrigin::Compiled);
  const auto info = detail::cl::listDevices().at(static_cast<std::size_t>(GetParam().device));
  if (detail::cl::cachesBinaries(info)) {
    EXPECT_TRUE(fs::exists(b1->programBuild().cacheFile));
    EXPECT_EQ(b2->programOrigin(), detail::cl::ProgramOrigin::Disk);
  } else {
    // PoCL: no binary asked for (it would compile every kernel of the program) and none written;
    // the second context's build is PoCL's, from its own cache.
    EXPECT_EQ(b1->programBuild().cacheFile, "");
    EXPECT_EQ(b2->programOrigin(), detail::cl::ProgramOrigin::Compiled);
    EXPECT_TRUE(!fs::exists(cache.dir()) || fs::is_empty(cache.dir())) << cache.dir();
  }
  // Either way both compute the same forces.
  Eigen::VectorXd x = p.restPositions * 1.01, f1, f2;
  b1->setPositions(x);
  b2->setPositions(x);
  b1->internalForces(f1);
  b2->internalForces(f2);
  EXPECT_EQ(f1, f2);
}

TEST_P(OpenCLProgramCache, PoclKeepsItsOwnCacheAndOthersOurs) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  detail::cl::DeviceInfo device = detail::cl::listDevices().at(static_cast<std::size_t>(GetParam().device));
  device.platformName = "NVIDIA CUDA";
  EXPECT_TRUE(detail::cl::cachesBinaries(device));
  device.platformName = "Portable Computing Language";
  EXPECT_FALSE(detail::cl::cachesBinaries(device));
}

TEST_P(OpenCLProgramCache, BuildFailureReportsTheCompilerLog) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  ScopedCacheDir cache(test::tempDir() / "kernels");
  auto ctx = detail::cl::Context::create(selector());
  const std::string broken = "__kernel void broken(__global float* v) { v[0] = undeclared_name; }\n";
  try {
    detail::cl::buildProgram(*ctx, "deliberately-broken", broken, "-DX=1");
    FAIL() << "expected a build failure";
  } catch (const detail::Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(e.code(), ErrorCode::DeviceError);
    EXPECT_NE(msg.find("deliberately-broken"), std::string::npos) << msg;
    EXPECT_NE(msg.find("undeclared_name"), std::string::npos) << "the log names the culprit: " << msg;
    EXPECT_NE(msg.find(ctx->deviceName()), std::string::npos) << msg;
    EXPECT_NE(msg.find("-DX=1"), std::string::npos) << msg;
  }
  EXPECT_TRUE(!fs::exists(cache.dir()) || fs::is_empty(cache.dir())) << "nothing cached for a failed build";
}

TEST_P(OpenCLProgramCache, EmbeddedSourcesFormOneProgram) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const std::string src = detail::cl::corofemProgramSource();
  // Layout header first, then the kernels in dependency order.
  const auto layout = src.find("#line 1 \"corofem_layout.h\"");
  const auto mat3 = src.find("#line 1 \"mat3.cl\"");
  const auto rotation = src.find("#line 1 \"rotation.cl\"");
  const auto pcg = src.find("#line 1 \"pcg.cl\"");
  ASSERT_NE(layout, std::string::npos);
  ASSERT_NE(pcg, std::string::npos);
  EXPECT_LT(layout, mat3);
  EXPECT_LT(mat3, rotation);
  EXPECT_LT(rotation, pcg);
}

TEST_P(OpenCLProgramCache, UnsupportedFormulationNamesItAndTheReferenceBackend) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  detail::Problem p = test::makeProblem(test::cellBox(1, 1, 1));
  p.name = "jelly";
  for (Formulation f : {Formulation::StVenantKirchhoff, Formulation::NeoHookean}) {
    p.formulation = f;
    try {
      test::openclOn(p, SolverDesc{}, detail::cl::Context::shared(selector()));
      FAIL() << "expected BadInput for " << toString(f);
    } catch (const detail::Error& e) {
      const std::string msg = e.what();
      EXPECT_EQ(e.code(), ErrorCode::BadInput);
      EXPECT_NE(msg.find(toString(f)), std::string::npos) << msg;
      EXPECT_NE(msg.find("reference"), std::string::npos) << msg;
      EXPECT_NE(msg.find("jelly"), std::string::npos) << msg;
    }
  }
  p.formulation = Formulation::Corotational;
  SolverDesc cholesky;
  cholesky.linearSolver = LinearSolverKind::Cholesky;
  EXPECT_THROW(test::openclOn(p, cholesky, detail::cl::Context::shared(selector())), detail::Error);
}

TEST_P(OpenCLProgramCache, BadDeviceSelectorListsTheDevices) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = test::makeProblem(test::cellBox(1, 1, 1));
  const auto devices = detail::cl::listDevices();
  for (const std::string sel : {std::string("no-such-device-xyz"), std::to_string(devices.size() + 5)}) {
    try {
      test::openclOn(p, SolverDesc{}, detail::cl::Context::shared(sel));
      FAIL() << "expected DeviceError for selector " << sel;
    } catch (const detail::Error& e) {
      const std::string msg = e.what();
      EXPECT_EQ(e.code(), ErrorCode::DeviceError);
      EXPECT_NE(msg.find(sel), std::string::npos) << msg;
      for (const auto& d : devices) EXPECT_NE(msg.find(d.name), std::string::npos) << msg;
    }
  }
  // A name substring, any case, selects the device.
  std::string part = devices.at(static_cast<std::size_t>(GetParam().device)).name.substr(0, 6);
  for (char& c : part) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  EXPECT_NO_THROW(detail::cl::selectDevice(part));
}

TEST_P(OpenCLProgramCache, DoubleOnADeviceWithoutFp64IsAClearError) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const auto info = detail::cl::listDevices().at(static_cast<std::size_t>(GetParam().device));
  if (info.fp64) GTEST_SKIP() << info.name << " has cl_khr_fp64; the error path cannot be reached here";
  const detail::Problem p = test::makeProblem(test::cellBox(1, 1, 1));
  SolverDesc s;
  s.precision = Precision::Double;
  try {
    test::openclOn(p, s, detail::cl::Context::shared(std::to_string(GetParam().device)));
    FAIL();
  } catch (const detail::Error& e) {
    EXPECT_NE(std::string(e.what()).find("float"), std::string::npos) << e.what();
  }
}

// One case per device (precision is irrelevant here except for BackendCreationHitsTheDiskCache).
std::vector<DeviceCase> oncePerDevice() {
  std::vector<DeviceCase> out;
  for (const auto& c : test::deviceCases(false))
    if (out.empty() || out.back().device != c.device) out.push_back(c);
  return out;
}

INSTANTIATE_TEST_SUITE_P(Devices, OpenCLProgramCache, ::testing::ValuesIn(oncePerDevice()), test::caseName);

}  // namespace
}  // namespace corofem
