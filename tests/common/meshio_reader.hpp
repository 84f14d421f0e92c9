// meshio (Debian's python3-meshio, through /usr/bin/python3) as an independent reader of the files
// corofem writes: tests/common/read_with_meshio.py turns what it reads into JSON.
#pragma once

#include "common/test_data.hpp"

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

namespace corofem::test {

/// True when /usr/bin/python3 can import meshio (checked once per process).
inline bool meshioAvailable() {
  static const bool available = std::system("/usr/bin/python3 -c 'import meshio' >/dev/null 2>&1") == 0;
  return available;
}

/// Reads `path` with meshio. On failure returns null and puts the reader's output in `error`.
inline nlohmann::json readWithMeshio(const std::string& path, std::string& error) {
  const std::string json = path + ".meshio.json", log = path + ".meshio.log";
  const std::string cmd = std::string("/usr/bin/python3 '") + COROFEM_SOURCE_DIR +
                          "/tests/common/read_with_meshio.py' '" + path + "' '" + json + "' >'" + log + "' 2>&1";
  const int rc = std::system(cmd.c_str());
  std::ifstream in(rc == 0 ? json : log);
  std::stringstream text;
  text << in.rdbuf();
  if (rc != 0) {
    error = "meshio could not read " + path + " (exit status " + std::to_string(rc) + "): " + text.str().substr(0, 2000);
    return nullptr;
  }
  return nlohmann::json::parse(text.str());
}

}  // namespace corofem::test

/// Skips the current test with the reason when meshio cannot be imported.
#define COROFEM_REQUIRE_MESHIO()                                                                      \
  do {                                                                                                \
    if (!::corofem::test::meshioAvailable())                                                          \
      GTEST_SKIP() << "meshio is not importable by /usr/bin/python3 (install Debian's python3-meshio, " \
                      "as cmake/debian-deps.sh does); the independent read-back is skipped";          \
  } while (0)
