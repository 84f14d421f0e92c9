// Regression tests of issue 27 (what fuzzing and fault injection found) for `corofem run` and
// `corofem info`, end to end: a crash on malformed JSON, names that would write outside the output
// folder, a full disk reported as success, files that are not regular files, unbounded messages,
// probe names that broke probes.csv, NaN and infinity in probes.csv, uncapped substeps, a static
// answer with inverted elements and unconverged runs reported as "ok". Each test names the item of
// the issue it covers.
#include "cli/cli_runner.hpp"
#include "common/test_data.hpp"

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include <sys/stat.h>
#include <unistd.h>

namespace {

using corofem::test::readFile;
using corofem::test::runCli;
namespace fs = std::filesystem;

bool has(const std::string& haystack, const std::string& needle) { return haystack.find(needle) != std::string::npos; }

/// A two-step run of a small box on the reference backend, with a probe named `probe`.
std::string tinyScene(const std::string& name = "tiny", const std::string& body = "beam",
                      const std::string& probe = "tip") {
  return R"({"name": ")" + name + R"(", "bodies": [{"name": ")" + body +
         R"(", "mesh": {"box": {"max": [1, 0.2, 0.2], "cells": [2, 1, 1]}},
    "fixed": [{"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}}],
    "loads": [{"type": "gravity", "vector": [0, -9.81, 0]}]}],
  "analysis": {"time_step": 0.01, "steps": 2}, "backend": "reference",
  "output": {"probes": [{"name": ")" + probe + R"(", "nodes": {"plane": {"point": [1, 0, 0], "normal": [1, 0, 0]}}}],
             "vtk": true}})";
}

fs::path writeScene(const fs::path& dir, const std::string& text, const char* file = "scene.json") {
  std::ofstream(dir / file) << text;
  return dir / file;
}

std::string quoted(const fs::path& p) { return "'" + p.string() + "'"; }

/// Fields of one CSV line, with RFC 4180 quotes.
std::vector<std::string> csvFields(const std::string& line) {
  std::vector<std::string> fields(1);
  bool inQuotes = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (inQuotes && c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
      fields.back() += '"';
      ++i;
    } else if (c == '"') {
      inQuotes = !inQuotes;
    } else if (c == ',' && !inQuotes) {
      fields.emplace_back();
    } else {
      fields.back() += c;
    }
  }
  return fields;
}

std::vector<std::string> lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

TEST(Issue27, TheTinySceneRuns) {  // the base the cases below break
  const fs::path dir = corofem::test::tempDir();
  const auto r = runCli("run " + quoted(writeScene(dir, tinyScene())) + " -q --out " + quoted(dir / "out"));
  ASSERT_EQ(r.exitCode, 0) << r.output;
  EXPECT_EQ(lines(readFile(dir / "out" / "probes.csv")).size(), 4u);  // header, steps 0, 1, 2
}

// ------------------------------------------------------------------ item 1
TEST(Issue27Item1, ALongTokenInTheSceneIsExit2NotSigsegv) {
  const fs::path dir = corofem::test::tempDir();
  const std::string text = R"({"bodies": [{"mesh": {"box": {}}}], "name": ")" + std::string(40000, 'a');
  const auto r = runCli("run " + quoted(writeScene(dir, text)) + " -q --out " + quoted(dir / "out"));
  EXPECT_EQ(r.exitCode, 2) << r.output.substr(0, 500);
  EXPECT_TRUE(has(r.output, "invalid JSON")) << r.output.substr(0, 500);
  EXPECT_LT(r.output.size(), 1000u);
}

// ------------------------------------------------------------------ item 2
TEST(Issue27Item2, ABodyNamedLikeAPathWritesNothingOutsideTheOutputFolder) {
  const fs::path dir = corofem::test::tempDir();
  fs::create_directories(dir / "a" / "b");
  const auto r = runCli("run " + quoted(writeScene(dir, tinyScene("tiny", "../../escaped"))) + " -q --out " +
                        quoted(dir / "a" / "b" / "out"));
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_TRUE(has(r.output, "bodies[0].name: the name \"../../escaped\" contains '/'")) << r.output;
  EXPECT_FALSE(fs::exists(dir / "a" / "escaped.pvd"));
  EXPECT_FALSE(fs::exists(dir / "a" / "b" / "out")) << "a refused scene creates no output folder";
}

TEST(Issue27Item2, ASceneNamedLikeAPathIsRefusedAsTheDefaultOutputFolder) {
  // Without --out the folder is out/<scene name>, relative to the working directory (the project
  // root here): "../out-issue27-escape" would be a folder beside out/.
  const fs::path dir = corofem::test::tempDir();
  const fs::path escaped = fs::path(COROFEM_SOURCE_DIR) / "out-issue27-escape";
  fs::remove_all(escaped);
  const auto r = runCli("run " + quoted(writeScene(dir, tinyScene("../out-issue27-escape"))) + " -q");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_TRUE(has(r.output, "name: the name \"../out-issue27-escape\" contains '/'")) << r.output;
  EXPECT_FALSE(fs::exists(escaped));
  fs::remove_all(escaped);
}

// ------------------------------------------------------------------ item 3
TEST(Issue27Item3, AFullDiskUnderProbesCsvIsAnError) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  const fs::path dir = corofem::test::tempDir();
  fs::create_directories(dir / "out");
  fs::create_symlink("/dev/full", dir / "out" / "probes.csv");  // every write: ENOSPC
  const auto r = runCli("run " + quoted(writeScene(dir, tinyScene())) + " -q --out " + quoted(dir / "out"));
  EXPECT_EQ(r.exitCode, 1) << r.output;
  EXPECT_TRUE(has(r.output, "probes.csv: " + std::string(std::strerror(ENOSPC)))) << r.output;
}

TEST(Issue27Item3, AWriteThatFailsMidRunIsAnErrorAndTheSummarySaysSo) {
  // A file size limit of 4 KiB (SIGXFSZ ignored, so a write beyond it fails with EFBIG): probes.csv
  // reaches it after about 40 rows, the rows before stay whole, and the summary (about 2.2 KiB)
  // records the failure. `ulimit -f` counts 512-byte blocks in popen's /bin/sh (POSIX, dash) and
  // 1 KiB blocks in bash: 8 is 4 or 8 KiB, either way far below the 200 rows' 20 KiB.
  const fs::path dir = corofem::test::tempDir();
  const auto r = runCli("run " + quoted(writeScene(dir, tinyScene())) + " -q --out " + quoted(dir / "out") +
                            " --set analysis.steps=200 --set output.vtk=false",
                        "trap '' XFSZ; ulimit -f 8;");
  EXPECT_EQ(r.exitCode, 1) << r.output;
  EXPECT_TRUE(has(r.output, "probes.csv: " + std::string(std::strerror(EFBIG)))) << r.output;
  const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
  EXPECT_EQ(summary.at("status"), "failed");
  EXPECT_EQ(summary.at("error_kind"), "i/o error");
  EXPECT_LT(summary.at("steps_taken").get<int>(), 200);
}

TEST(Issue27Item3, AFullDiskUnderSummaryJsonIsAnError) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  const fs::path dir = corofem::test::tempDir();
  fs::create_directories(dir / "out");
  fs::create_symlink("/dev/full", dir / "out" / "summary.json");
  fs::create_symlink("/dev/full", dir / "out" / "summary.json.tmp");
  const auto r = runCli("run " + quoted(writeScene(dir, tinyScene())) + " -q --out " + quoted(dir / "out"));
  EXPECT_EQ(r.exitCode, 1) << r.output;
  EXPECT_TRUE(has(r.output, "summary.json: " + std::string(std::strerror(ENOSPC)))) << r.output;
}

// ------------------------------------------------------------------ item 4
TEST(Issue27Item4, InfoOnADirectoryOrAFifoIsBadInput) {
  const fs::path dir = corofem::test::tempDir();
  fs::create_directories(dir / "folder.msh");
  auto r = runCli("info " + quoted(dir / "folder.msh"));
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_TRUE(has(r.output, "is a directory, not a regular file")) << r.output;
  EXPECT_FALSE(has(r.output, "internal error")) << r.output;
  ASSERT_EQ(::mkfifo((dir / "pipe.vtk").string().c_str(), 0600), 0) << std::strerror(errno);
  r = runCli("info " + quoted(dir / "pipe.vtk"));  // blocked forever before
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_TRUE(has(r.output, "is a FIFO")) << r.output;
}

/// The input limits (corofem::InputLimits) are the flags --max-input-bytes, --max-scene-bytes and
/// --max-box-tets of every command: an input over one is exit 2 naming the limit and the flag, and
/// the flag raises it.
TEST(Issue27Item4, TheLimitFlagsSetTheInputLimits) {
  const fs::path dir = corofem::test::tempDir();
  std::ofstream(dir / "small.msh") << "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n"
                                      "3 0 1 0\n4 0 0 1\n$EndNodes\n$Elements\n1\n1 4 2 0 1 1 2 3 4\n$EndElements\n";
  const std::string mesh = quoted(dir / "small.msh");  // 129 bytes
  for (const std::string& command : {"info " + mesh, "convert " + mesh + " " + quoted(dir / "small.vtu")}) {
    auto r = runCli(command + " --max-input-bytes 100");
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_TRUE(has(r.output, "small.msh: it has 129 bytes, more than the limit of 100 bytes "
                              "(InputLimits::maxInputBytes)"))
        << r.output;
    EXPECT_TRUE(has(r.output, "--max-input-bytes, e.g. --max-input-bytes 4G")) << r.output;
    r = runCli(command + " --max-input-bytes=1K");
    EXPECT_EQ(r.exitCode, 0) << r.output;
  }
  auto r = runCli("info " + mesh + " --max-input-bytes lots");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_TRUE(has(r.output, "--max-input-bytes \"lots\" is not a limit")) << r.output;
  r = runCli("info " + mesh + " --max-box-tets");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_TRUE(has(r.output, "--max-box-tets needs a value")) << r.output;

  // run and warmup: the scene file, its box (2 x 1 x 1 cells: 10 tetrahedra) and its .bou file.
  const std::string scene = quoted(writeScene(dir, tinyScene()));
  const std::string out = " -q --out " + quoted(dir / "out");
  for (const std::string& command : {"run " + scene + out, "warmup " + scene}) {
    r = runCli(command + " --max-box-tets 9");
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_TRUE(has(r.output, "give 10 tetrahedra, more than the limit of 9 (InputLimits::maxBoxTets)")) << r.output;
    EXPECT_TRUE(has(r.output, "--max-box-tets")) << r.output;
  }
  r = runCli("run " + scene + out + " --max-scene-bytes 100");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_TRUE(has(r.output, "bytes, more than the limit of 100 bytes (InputLimits::maxSceneBytes)")) << r.output;
  EXPECT_TRUE(has(r.output, "--max-scene-bytes")) << r.output;
  r = runCli("run " + scene + out + " --max-box-tets 10 --max-scene-bytes 1K --max-input-bytes 100");
  EXPECT_EQ(r.exitCode, 0) << r.output;
  // A .bou file is read by the simulation, under the flag too.
  std::ofstream(dir / "fix.bou") << "1\n# " << std::string(200, 'x') << "\n";
  std::string withBou = tinyScene();
  const std::string plane = R"({"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}})";
  withBou.replace(withBou.find(plane), plane.size(), R"({"bou": "fix.bou"})");
  const std::string bouScene = quoted(writeScene(dir, withBou, "bou.json"));
  r = runCli("run " + bouScene + out + " --max-input-bytes 100");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_TRUE(has(r.output, "fix.bou")) << r.output;
  EXPECT_TRUE(has(r.output, "more than the limit of 100 bytes (InputLimits::maxInputBytes)")) << r.output;
  r = runCli("run " + bouScene + out + " --max-input-bytes 1K");
  EXPECT_EQ(r.exitCode, 0) << r.output;
  // --help documents the flags.
  r = runCli("--help");
  EXPECT_EQ(r.exitCode, 0);
  for (const char* flag : {"--max-input-bytes SIZE", "--max-scene-bytes SIZE", "--max-box-tets COUNT"})
    EXPECT_TRUE(has(r.output, flag)) << r.output;
}

// ------------------------------------------------------------------ item 5
TEST(Issue27Item5, AHugeOverrideIsNotEchoedWhole) {
  const fs::path dir = corofem::test::tempDir();
  const std::string big(100000, 'z');  // (one argument may have at most 128 KiB)
  const auto r = runCli("run " + quoted(writeScene(dir, tinyScene())) + " -q --out " + quoted(dir / "out") +
                        " --set 'analysis..x" + big + "=1'");
  EXPECT_EQ(r.exitCode, 2);
  EXPECT_LT(r.output.size(), 1000u) << r.output.substr(0, 500);
}

// ------------------------------------------------------------------ item 7
TEST(Issue27Item7, AProbeNameWithACommaKeepsTheCsvHeaderAligned) {
  const fs::path dir = corofem::test::tempDir();
  const auto r = runCli("run " + quoted(writeScene(dir, tinyScene("tiny", "beam", "tip, \\\"left\\\""))) +
                        " -q --out " + quoted(dir / "out"));
  ASSERT_EQ(r.exitCode, 0) << r.output;
  const auto rows = lines(readFile(dir / "out" / "probes.csv"));
  ASSERT_EQ(rows.size(), 4u);
  const auto header = csvFields(rows[0]);
  EXPECT_EQ(header.size(), csvFields(rows[1]).size()) << rows[0];
  EXPECT_EQ(header.back(), "tip, \"left\"_uz");
}

// ------------------------------------------------------------------ item 8
TEST(Issue27Item8, NoNanOrInfInProbesCsvAndNoRowForAFailedStep) {
  for (const char* set : {"bodies.0.material.youngs_modulus=1e308", "bodies.0.initial_velocity=[1e200,0,0]"}) {
    const fs::path dir = corofem::test::tempDir();
    const auto r = runCli("run " + quoted(writeScene(dir, tinyScene())) + " -q --out " + quoted(dir / "out") +
                          " --set '" + set + "'");
    EXPECT_EQ(r.exitCode, 3) << set << "\n" << r.output;
    EXPECT_TRUE(has(r.output, "warning: ")) << r.output;
    EXPECT_TRUE(has(r.output, "not finite")) << r.output;
    const std::string csv = readFile(dir / "out" / "probes.csv");
    for (const char* bad : {"nan", "inf", "NaN", "Inf"}) EXPECT_FALSE(has(csv, bad)) << set << "\n" << csv;
    // The header and step 0; the failed step 1 adds no row (it added one numbered 0).
    EXPECT_EQ(lines(csv).size(), 2u) << set << "\n" << csv;
    const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
    EXPECT_GE(summary.at("non_finite_values").at("count").get<int>(), 1) << summary.dump(2);
  }
}

// ------------------------------------------------------------------ item 9
TEST(Issue27Item9, MaxSubstepsBeyondTheCapIsExit2) {
  const fs::path dir = corofem::test::tempDir();
  const auto r = runCli("run " + quoted(writeScene(dir, tinyScene())) + " -q --out " + quoted(dir / "out") +
                        " --set analysis.max_substeps=2147483647");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_TRUE(has(r.output, "max_substeps <= 1024")) << r.output;
}

// ------------------------------------------------------------------ item 10
TEST(Issue27Item10, AStaticAnswerWithInvertedElementsIsNotOk) {
  // A St. Venant-Kirchhoff block whose top face is pushed through its bottom to its mirror image
  // (tests/solve/test_solve_hardening.cpp): the increment "converged" inside out and the summary
  // said "ok"; now the run fails (exit 3) and says how many elements are inverted and how badly.
  const fs::path dir = corofem::test::tempDir();
  const std::string scene = R"({"name": "mirror", "bodies": [{"name": "block",
    "mesh": {"box": {"max": [0.2, 0.2, 0.1], "cells": [2, 2, 2]}}, "formulation": "stvk",
    "fixed": [{"plane": {"point": [0, 0, 0], "normal": [0, 0, 1]}}],
    "loads": [{"type": "displacement", "vector": [0, 0, -0.2],
               "nodes": {"plane": {"point": [0, 0, 0.1], "normal": [0, 0, 1]}}}]}],
  "analysis": {"type": "static"}, "solver": {"linear_solver": "cholesky"}, "backend": "reference",
  "output": {"vtk": false}})";
  const auto r = runCli("run " + quoted(writeScene(dir, scene)) + " -q --out " + quoted(dir / "out"));
  EXPECT_EQ(r.exitCode, 3) << r.output;
  const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
  EXPECT_EQ(summary.at("status"), "failed") << summary.dump(2);
  const std::string error = summary.value("error", "");
  EXPECT_TRUE(has(error, " of 40 elements inverted (det F <= 0; the lowest, -")) << error;
  EXPECT_EQ(summary.at("steps_taken"), 0);
}

// ------------------------------------------------------------------ item 12
/// The 1 x 0.1 x 0.1 m beam of issue 29 (coarser), backward Euler at 1/60 s, three steps, PCG capped
/// at `cap` iterations; failed steps retried in up to 8 substeps.
std::string cappedBeam(int cap) {
  return R"({"name": "capped", "bodies": [{"name": "beam",
    "mesh": {"box": {"max": [1, 0.1, 0.1], "cells": [12, 2, 2]}},
    "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3, "density": 1000},
    "fixed": [{"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}}],
    "loads": [{"type": "gravity", "vector": [0, -9.81, 0]}]}],
  "analysis": {"integrator": "backward_euler", "time_step": 0.016666666666666666, "steps": 3, "max_substeps": 8},
  "solver": {"max_iterations": )" + std::to_string(cap) + R"(, "tolerance": 1e-6}, "backend": "reference",
  "output": {"vtk": false}})";
}

TEST(Issue27Item12, ARunWhoseSolvesDidNotConvergeIsNotPlainOk) {
  const fs::path dir = corofem::test::tempDir();
  const auto r = runCli("run " + quoted(writeScene(dir, cappedBeam(5))) + " --out " + quoted(dir / "out"));
  ASSERT_EQ(r.exitCode, 0) << r.output;  // the run completed; exit 0 is documented for it
  const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
  EXPECT_EQ(summary.at("status"), "ok_unconverged") << summary.dump(2);
  const auto& c = summary.at("convergence");
  EXPECT_EQ(c.at("steps_unconverged"), 3) << c.dump();
  EXPECT_EQ(c.at("steps_recorded"), 3) << c.dump();
  EXPECT_EQ(c.at("first_unconverged_step"), 1) << c.dump();
  EXPECT_GT(c.at("worst_unconverged_linear_residual").get<double>(), 1e-2) << c.dump();  // far from 1e-6
  EXPECT_EQ(c.at("solver_max_iterations"), 5) << c.dump();
  // The command says so, with the count, the worst residual and the fix; every step's line too.
  EXPECT_TRUE(has(r.output, "warning: 3 of 3 steps finished with linear solves short of solver.tolerance = 1e-06"))
      << r.output;
  EXPECT_TRUE(has(r.output, "solver.max_iterations = 5): their answer is inexact")) << r.output;
  EXPECT_TRUE(has(r.output, "step 3/3")) << r.output;
  EXPECT_TRUE(has(r.output, "unconverged (linear residual ")) << r.output;
  // probes.csv's column agrees.
  const auto rows = lines(readFile(dir / "out" / "probes.csv"));
  ASSERT_EQ(rows.size(), 5u);
  const auto header = csvFields(rows[0]);
  const std::size_t col = std::find(header.begin(), header.end(), "converged") - header.begin();
  ASSERT_LT(col, header.size());
  for (std::size_t i = 2; i < rows.size(); ++i) EXPECT_EQ(csvFields(rows[i]).at(col), "0") << rows[i];
}

TEST(Issue27Item12, AConvergedRunIsOkAndCountsNoUnconvergedStep) {
  const fs::path dir = corofem::test::tempDir();
  const auto r = runCli("run " + quoted(writeScene(dir, cappedBeam(1000))) + " -q --out " + quoted(dir / "out"));
  ASSERT_EQ(r.exitCode, 0) << r.output;
  const auto summary = nlohmann::json::parse(readFile(dir / "out" / "summary.json"));
  EXPECT_EQ(summary.at("status"), "ok") << summary.dump(2);
  EXPECT_EQ(summary.at("convergence").at("steps_unconverged"), 0) << summary.dump(2);
  EXPECT_TRUE(summary.at("convergence").at("first_unconverged_step").is_null()) << summary.dump(2);
  EXPECT_LE(summary.at("convergence").at("worst_linear_residual").get<double>(), 1e-5) << summary.dump(2);
  EXPECT_FALSE(has(r.output, "unconverged")) << r.output;
}

}  // namespace
