// `corofem info` reports, for every mesh in ../shared/data/meshes, the counts that SOURCES.md
// gives (nodes, tets or triangles, boundary faces where listed).
#include "cli/cli_runner.hpp"
#include "common/test_data.hpp"

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

namespace {

struct MeshCounts {
  const char* file;
  std::size_t nodes;     // N (or vertices for OBJ)
  std::size_t elements;  // T (or triangles after fan-splitting for OBJ)
  long boundary;         // bnd from SOURCES.md, -1 where not listed
};

std::ostream& operator<<(std::ostream& os, const MeshCounts& m) { return os << m.file; }

// From ../shared/data/meshes/SOURCES.md.
const MeshCounts kMeshes[] = {
    {"sofa/liver.msh", 181, 596, 276},
    {"ipc/dolphin5K.msh", 8111, 36304, 10000},
    {"ipc/bar-186.msh", 86, 186, 168},
    {"ipc/bar-651.msh", 292, 651, 580},
    {"ipc/bar-2523.msh", 886, 2523, 1618},
    {"ipc/bar-14114.msh", 3842, 14114, 5788},
    {"ipc/rod300x33.msh", 13333, 50511, 19966},
    {"ipc/Armadillo13K.msh", 13230, 54985, 17296},
    {"pbd/armadillo_4k.ele", 1180, 3717, 2102},
    {"sfepy/cylinder.mesh", 354, 1348, 440},
    {"sfepy/cylinder.vtk", 354, 1348, 440},
    {"sfepy/elbow2.mesh", 1823, 8161, 1678},
    {"sfepy/wheelset.vtk", 5457, 21934, 6636},
    {"sfepy/octahedron.node", 330, 1224, 464},
    {"sfepy/msh_tetra.msh", 66, 127, -1},
    {"vega/beam3/beam3_tet.veg", 208, 450, -1},
    {"vega/turtle/turtle-volumetric-homogeneous.veg", 347, 1185, 530},
    {"vega/simpleBridge/simpleBridge-ic_128_0.15_.1.veg", 4000, 12827, 7058},
    {"sofa/liver-smooth.obj", 2194, 4384, -1},
    {"sofa/liver.obj", 181, 274, -1},
    {"ipc/dolphin5K.obj", 5002, 10000, -1},
    {"vega/beam3/beam3_tet.obj", 208, 412, -1},
    {"vega/beam3/beam3.obj", 208, 412, -1},
    {"vega/turtle/turtle.obj", 1961, 3654, -1},
    {"vega/turtle/turtle-volumetric.obj", 347, 530, -1},
    {"vega/simpleBridge/simpleBridge.obj", 16085, 32014, -1},
    {"vega/simpleBridge/simpleBridge-ic_128_0.15_.1.obj", 4000, 7058, -1},
};

class CliInfo : public ::testing::TestWithParam<MeshCounts> {};

TEST_P(CliInfo, CountsMatchSources) {
  const MeshCounts& m = GetParam();
  const std::string rel = std::string("meshes/") + m.file;
  COROFEM_REQUIRE_DATA(rel);
  const auto r = corofem::test::runCli("info --json '" + corofem::test::dataPath(rel) + "'");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  const bool surface = j.contains("vertices");
  EXPECT_EQ(j.at(surface ? "vertices" : "nodes").get<std::size_t>(), m.nodes);
  EXPECT_EQ(j.at(surface ? "triangles" : "tets").get<std::size_t>(), m.elements);
  if (m.boundary >= 0) EXPECT_EQ(j.at("boundary_faces").get<long>(), m.boundary);
  if (!surface) {
    EXPECT_GT(j.at("volume").get<double>(), 0.0);
    EXPECT_EQ(j.at("unused_nodes").get<std::size_t>(), 0u);  // SOURCES.md: no mesh has unused nodes
    // The OpenCL device's numbering follows the two jumps (at most half: Morton).
    const double own = j.at("node_jump").get<double>(), morton = j.at("node_jump_morton").get<double>();
    EXPECT_EQ(j.at("device_numbering"), morton <= 0.5 * own ? "morton" : "mesh");
  }
}

INSTANTIATE_TEST_SUITE_P(SharedMeshes, CliInfo, ::testing::ValuesIn(kMeshes),
                         [](const auto& info) {
                           std::string n = info.param.file;
                           for (char& c : n)
                             if (!isalnum(static_cast<unsigned char>(c))) c = '_';
                           return n;
                         });

TEST(CliInfo, TheLargeGmshMeshesGetTheDevicesMortonNumbering) {
  // Measured (bench_mesh_order): their steps 1.45-1.55x faster in it on PoCL.
  for (const char* file : {"meshes/ipc/Armadillo13K.msh", "meshes/ipc/dolphin5K.msh", "meshes/ipc/rod300x33.msh"}) {
    COROFEM_REQUIRE_DATA(file);
    const auto r = corofem::test::runCli("info --json '" + corofem::test::dataPath(file) + "'");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const auto j = nlohmann::json::parse(r.output);
    EXPECT_EQ(j.at("device_numbering"), "morton") << file;
    EXPECT_LT(j.at("node_jump_morton").get<double>(), 0.2 * j.at("node_jump").get<double>()) << file;
  }
}

TEST(CliInfo, ElbowReportsItsOrientation) {
  COROFEM_REQUIRE_DATA("meshes/sfepy/elbow2.mesh");
  const auto r = corofem::test::runCli("info --json '" + corofem::test::dataPath("meshes/sfepy/elbow2.mesh") + "'");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  // SOURCES.md: all 8161 tets of elbow2 are negatively oriented in the file.
  EXPECT_EQ(nlohmann::json::parse(r.output).at("negatively_oriented_in_file").get<std::size_t>(), 8161u);
}

TEST(CliInfo, MissingFileIsAnErrorNamingThePath) {
  const auto r = corofem::test::runCli("info /nonexistent/mesh.msh");
  EXPECT_NE(r.exitCode, 0);
  EXPECT_NE(r.output.find("/nonexistent/mesh.msh"), std::string::npos) << r.output;
}

TEST(CliInfo, UnknownExtensionNamesTheSupportedOnes) {
  const auto r = corofem::test::runCli("info README.md");
  EXPECT_EQ(r.exitCode, 2) << r.output;
  EXPECT_NE(r.output.find(".msh"), std::string::npos) << r.output;
}

}  // namespace
