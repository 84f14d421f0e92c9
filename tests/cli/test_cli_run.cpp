// `corofem run` and `corofem convert` end to end: outputs written, --set applied, exit codes.
#include "cli/cli_runner.hpp"
#include "common/test_data.hpp"

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

namespace {

using corofem::test::readFile;
using corofem::test::runCli;
namespace fs = std::filesystem;

std::size_t lineCount(const std::string& s) {
  std::size_t n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

TEST(CliRun, WritesProbesVtkAndSummary) {
  const fs::path out = corofem::test::tempDir();
  const auto r = runCli(std::string("run ") + corofem::test::kFig8Scene + " --quiet --out '" + out.string() +
                        "' --set analysis.steps=12 --set output.vtk_every=5");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  // probes.csv: a header, the initial state (step 0) and one row per step.
  const std::string csv = readFile(out / "probes.csv");
  EXPECT_EQ(lineCount(csv), 1u + 1u + 12u) << csv;
  EXPECT_NE(csv.find("tip_uy"), std::string::npos);
  const auto summary = nlohmann::json::parse(readFile(out / "summary.json"));
  EXPECT_EQ(summary.at("status"), "ok");
  EXPECT_EQ(summary.at("steps_taken").get<int>(), 12);
  EXPECT_EQ(summary.at("backend"), "reference");
  EXPECT_GT(summary.at("wall_time_per_step_s").at("median").get<double>(), 0.0);
  // The beam sags under gravity (-y): after 12 steps of 10 ms the tip has moved down.
  EXPECT_LT(summary.at("final_probe_displacement").at("tip").at(1).get<double>(), 0.0);
  // VTK: steps 0, 5, 10 and the last (12).
  EXPECT_TRUE(fs::exists(out / "beam.pvd"));
  for (int step : {0, 5, 10, 12}) {
    char name[64];
    std::snprintf(name, sizeof name, "beam_%06d.vtu", step);
    EXPECT_TRUE(fs::exists(out / "vtk" / name)) << name;
  }
}

TEST(CliRun, SetOverridesAValue) {
  const fs::path a = corofem::test::tempDir() / "stiff";
  const fs::path b = corofem::test::tempDir() / "soft";
  ASSERT_EQ(runCli(std::string("run ") + corofem::test::kFig8Scene + " -q --out '" + a.string() + "' --set analysis.steps=5 --set output.vtk=false").exitCode, 0);
  ASSERT_EQ(runCli(std::string("run ") + corofem::test::kFig8Scene + " -q --out '" + b.string() +
                   "' --set analysis.steps=5 --set output.vtk=false --set bodies.0.material.youngs_modulus=2e4").exitCode, 0);
  const double tipStiff = nlohmann::json::parse(readFile(a / "summary.json"))["final_probe_displacement"]["tip"][1];
  const double tipSoft = nlohmann::json::parse(readFile(b / "summary.json"))["final_probe_displacement"]["tip"][1];
  EXPECT_NE(tipStiff, tipSoft);  // the override reached the material
  EXPECT_FALSE(fs::exists(a / "vtk")) << "output.vtk=false must write no VTK series";
}

TEST(CliRun, MisspeltOverrideIsBadInputWithSuggestion) {
  const auto r = runCli(std::string("run ") + corofem::test::kFig8Scene + " --out '" + corofem::test::tempDir().string() +
                        "' --set bodies.0.material.youngs_modulus_=1e5");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_NE(r.output.find("youngs_modulus"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("did you mean"), std::string::npos) << r.output;
}

TEST(CliRun, OutOfRangeValueIsBadInput) {
  const auto r = runCli(std::string("run ") + corofem::test::kFig8Scene + " --out '" + corofem::test::tempDir().string() +
                        "' --set bodies.0.material.poisson_ratio=0.5");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_NE(r.output.find("poisson_ratio"), std::string::npos) << r.output;
}

TEST(CliRun, FailedSolveExitsThreeAndLeavesReadableOutputs) {
  const fs::path out = corofem::test::tempDir();
  // A static analysis allowed a single Newton iteration under a load that rotates the beam a lot:
  // the co-rotational Newton cannot converge in one iteration, so the first increment fails.
  const auto r = runCli(std::string("run ") + corofem::test::kFig8Scene + " --out '" + out.string() +
                        "' --set analysis='{\"type\":\"static\",\"increments\":2,\"max_newton_iterations\":1}'"
                        " --set bodies.0.material.youngs_modulus=2e4");
  EXPECT_EQ(r.exitCode, 3) << r.output;
  const auto summary = nlohmann::json::parse(readFile(out / "summary.json"));
  EXPECT_EQ(summary.at("status"), "failed");
  EXPECT_FALSE(summary.at("error").get<std::string>().empty());
  EXPECT_GE(lineCount(readFile(out / "probes.csv")), 2u);  // header + initial state at least
}

TEST(CliRun, MissingSceneNamesThePath) {
  const auto r = runCli("run /nonexistent/scene.json");
  EXPECT_NE(r.exitCode, 0);
  EXPECT_NE(r.output.find("/nonexistent/scene.json"), std::string::npos) << r.output;
}

TEST(CliRun, UnknownCommandAndOption) {
  EXPECT_EQ(runCli("frobnicate").exitCode, 2);
  EXPECT_EQ(runCli(std::string("run ") + corofem::test::kFig8Scene + " --bogus").exitCode, 2);
}

TEST(CliConvert, RoundTripKeepsCounts) {
  COROFEM_REQUIRE_DATA("meshes/ipc/bar-186.msh");
  const fs::path dir = corofem::test::tempDir();
  for (const char* ext : {".vtk", ".mesh", ".veg", ".msh"}) {
    const std::string out = (dir / (std::string("bar") + ext)).string();
    auto r = runCli("convert '" + corofem::test::dataPath("meshes/ipc/bar-186.msh") + "' '" + out + "'");
    ASSERT_EQ(r.exitCode, 0) << ext << ": " << r.output;
    r = runCli("info --json '" + out + "'");
    ASSERT_EQ(r.exitCode, 0) << ext << ": " << r.output;
    const auto j = nlohmann::json::parse(r.output);
    EXPECT_EQ(j.at("nodes").get<int>(), 86) << ext;
    EXPECT_EQ(j.at("tets").get<int>(), 186) << ext;
    EXPECT_NEAR(j.at("volume").get<double>(), 5.0, 1e-9) << ext;  // the bar is 10 x 0.5 x 1
  }
  EXPECT_EQ(runCli("convert '" + corofem::test::dataPath("meshes/ipc/bar-186.msh") + "' '" + (dir / "bar.vtu").string() + "'").exitCode, 0);
  EXPECT_TRUE(fs::exists(dir / "bar.vtu"));
}

}  // namespace

namespace {

TEST(CliRun, CoupledSurfaceIsWrittenAndReported) {
  COROFEM_REQUIRE_DATA("meshes/sofa/liver-smooth.obj");
  const fs::path out = corofem::test::tempDir();
  const auto r = runCli("run samples/coupled_liver/liver.json -q --out '" + out.string() +
                        "' --set analysis.steps=10 --set output.vtk_every=5");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  const auto summary = nlohmann::json::parse(readFile(out / "summary.json"));
  const auto& surface = summary.at("bodies").at(0).at("surface");
  EXPECT_EQ(surface.at("vertices").get<int>(), 2194);  // SOURCES.md: liver-smooth.obj
  EXPECT_EQ(surface.at("inside").get<int>() + surface.at("outside").get<int>(), 2194);
  EXPECT_GT(surface.at("largest_distance").get<double>(), 0.0);  // the smooth surface bulges out of the coarse mesh
  EXPECT_EQ(surface.at("layout"), "interleaved");
  EXPECT_TRUE(fs::exists(out / "liver_surface.pvd"));
  EXPECT_TRUE(fs::exists(out / "surface" / "liver_surface_000010.obj"));
  // The deformed OBJ differs from the rest one (the handle moved) but has the same size.
  const std::string rest = readFile(out / "surface" / "liver_surface_000000.obj");
  const std::string last = readFile(out / "surface" / "liver_surface_000010.obj");
  EXPECT_NE(rest, last);
  EXPECT_EQ(lineCount(rest), lineCount(last));
}

TEST(CliRun, SurfaceTooFarFromTheMeshIsBadInput) {
  COROFEM_REQUIRE_DATA("meshes/sofa/liver.msh");
  // A surface with one triangle 100 units away from the liver (whose diagonal is about 9.3).
  const fs::path dir = corofem::test::tempDir();
  std::ofstream(dir / "far.obj") << "v 100 0 0\nv 101 0 0\nv 100 1 0\nf 1 2 3\n";
  const auto r = runCli("run samples/coupled_liver/liver.json --out '" + (dir / "out").string() +
                        "' --set 'bodies.0.surface=\"" + (dir / "far.obj").string() + "\"'");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_NE(r.output.find("maxDistance"), std::string::npos) << r.output;  // names the option to raise
  EXPECT_NE(r.output.find("3 "), std::string::npos) << r.output;           // counts the vertices
}

}  // namespace
