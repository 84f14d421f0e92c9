// Runs the built `corofem` command and captures its exit status and output.
#pragma once

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <sys/wait.h>

namespace corofem::test {

/// The paper's Fig. 8 beam (0.8 x 0.1 x 0.1 m, clamped at x = 0), from the project root.
inline constexpr const char* kFig8Scene = "samples/fig8_beam/fig8_beam.json";

struct CommandResult {
  int exitCode = -1;
  std::string output;  ///< stdout and stderr together
};

/// Runs `corofem ARGS` (the shell parses ARGS) from the project root; `shellPrefix` runs before it
/// in the same shell (e.g. "ulimit -f 2;").
inline CommandResult runCli(const std::string& args, const std::string& shellPrefix = "") {
  const std::string cmd = shellPrefix + std::string(" cd '") + COROFEM_SOURCE_DIR + "' && '" + COROFEM_CLI_PATH +
                          "' " + args + " 2>&1";
  CommandResult r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf{};
  std::size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  const int status = pclose(pipe);
  r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

/// The whole text of a file ("" when it cannot be read).
inline std::string readFile(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace corofem::test
