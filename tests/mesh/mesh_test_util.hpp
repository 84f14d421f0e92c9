// Helpers for the mesh tests: writing small inline files, comparing meshes.
#pragma once

#include "common/test_data.hpp"

#include <corofem/mesh.hpp>

#include <gtest/gtest.h>

#include <fstream>
#include <string>

namespace corofem::test {

/// Writes text to tempDir()/name and returns the path.
inline std::string writeTemp(const std::filesystem::path& dir, const std::string& name, const std::string& text) {
  const auto path = dir / name;
  std::ofstream(path, std::ios::binary) << text;
  return path.string();
}

/// True when haystack contains needle (for message assertions with a readable failure).
inline ::testing::AssertionResult contains(const std::string& haystack, const std::string& needle) {
  if (haystack.find(needle) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "'" << haystack << "' does not contain '" << needle << "'";
}

/// Reads a tet mesh and fails the test (with the message) when it does not load.
inline TetMesh loadTet(const std::string& path, MeshReadReport* report = nullptr) {
  auto r = readTetMesh(path, report);
  EXPECT_TRUE(r.isOk()) << r.message();
  return r.isOk() ? std::move(r).value() : TetMesh{};
}

}  // namespace corofem::test
