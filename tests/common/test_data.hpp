// Paths to the shared test data (../shared/data relative to the project root) and a skip helper.
#pragma once

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace corofem::test {

/// Root of the shared data folder: $COROFEM_DATA_DIR if set, else <project>/../shared/data.
inline std::filesystem::path dataRoot() {
  if (const char* env = std::getenv("COROFEM_DATA_DIR")) return env;
  return std::filesystem::path(COROFEM_SOURCE_DIR) / ".." / "shared" / "data";
}

/// Full path of a shared data file, e.g. dataPath("meshes/ipc/bar-186.msh").
inline std::string dataPath(const std::string& relative) { return (dataRoot() / relative).string(); }

/// Temporary directory unique to the running test and process (created, emptied first):
/// <build>/test-tmp/<pid>/<suite.test>. Per process because CTest runs some suites twice (the
/// Morton-forced ones, tests/CMakeLists.txt) and may run a test and its twin at once. The process's
/// folder is removed when it exits normally, unless COROFEM_KEEP_TEST_TMP is set (a process killed
/// by a timeout leaves its folder behind).
inline std::filesystem::path tempDir() {
  struct ProcessDir {
    long pid = static_cast<long>(::getpid());
    std::filesystem::path path = std::filesystem::path(COROFEM_BINARY_DIR) / "test-tmp" / std::to_string(pid);
    ~ProcessDir() {
      // Not in a forked child that exits normally (its parent's folder stays the parent's).
      std::error_code ignored;
      if (pid == static_cast<long>(::getpid()) && !std::getenv("COROFEM_KEEP_TEST_TMP"))
        std::filesystem::remove_all(path, ignored);
    }
  };
  static const ProcessDir process;
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = std::string(info->test_suite_name()) + "." + info->name();
  for (char& c : name)
    if (c == '/') c = '_';
  auto dir = process.path / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace corofem::test

/// Skips the current test with a clear reason when a shared data file is absent.
#define COROFEM_REQUIRE_DATA(relative)                                                         \
  do {                                                                                         \
    if (!std::filesystem::exists(::corofem::test::dataPath(relative)))                         \
      GTEST_SKIP() << "shared data file " << ::corofem::test::dataPath(relative)               \
                   << " is absent (the ../shared/data folder beside the project root holds "   \
                      "the test meshes); skipping";                                            \
  } while (0)
