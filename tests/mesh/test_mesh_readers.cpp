// Every reader on the real files in ../shared/data/meshes: node, element and triangle counts,
// bounding boxes and boundary faces exactly as SOURCES.md lists them.
#include "mesh/mesh_test_util.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <set>

namespace {

using corofem::test::dataPath;

/// A SOURCES.md value as printed, e.g. "-0.0199". The tolerance is half a unit in its last printed
/// digit (the table rounds); a value printed without a decimal point ("0", "10") is exact, up to
/// 1e-9 for values like -2.7e-19 that print as 0.
struct Printed {
  const char* text;
  double value() const { return std::atof(text); }
  double tolerance() const {
    const char* dot = std::strchr(text, '.');
    if (!dot) return 1e-9;
    const int decimals = int(std::strlen(dot + 1));
    return 0.5 * std::pow(10.0, -decimals) * (1 + 1e-9);
  }
};

struct TetCase {
  const char* file;
  const char* format;
  std::size_t nodes, tets;
  long boundary;  // -1 where SOURCES.md gives none
  Printed bbox[6];  // xmin xmax ymin ymax zmin zmax
  double volume;  // 0 where SOURCES.md gives none
  double volumeTolerance;
  std::size_t reoriented;
};

std::ostream& operator<<(std::ostream& os, const TetCase& c) { return os << c.file; }

// From ../shared/data/meshes/SOURCES.md (N, T, bnd, bbox, volume, neg). The pbd/octahedron rows are
// read through either TetGen file; cylinder.vtk has the bbox of cylinder.mesh ("as above").
const TetCase kTetCases[] = {
    {"sofa/liver.msh", "gmsh 1", 181, 596, 276, {{"-4.679"}, {"1.803"}, {"0.2179"}, {"5.157"}, {"-1.693"}, {"2.729"}}, 36.56, 0.005, 0},
    {"ipc/dolphin5K.msh", "gmsh 2.2", 8111, 36304, 10000, {{"-26.56"}, {"75.87"}, {"-11.53"}, {"79.36"}, {"2.724"}, {"76.00"}}, 0, 0, 0},
    {"ipc/bar-186.msh", "gmsh 4.1", 86, 186, 168, {{"0"}, {"10"}, {"0"}, {"0.5"}, {"0"}, {"1"}}, 5, 1e-12, 0},
    {"ipc/bar-651.msh", "gmsh 4.1", 292, 651, 580, {{"0"}, {"10"}, {"0"}, {"0.5"}, {"0"}, {"1"}}, 5, 1e-12, 0},
    {"ipc/bar-2523.msh", "gmsh 4.1", 886, 2523, 1618, {{"0"}, {"10"}, {"0"}, {"0.5"}, {"0"}, {"1"}}, 5, 1e-12, 0},
    {"ipc/bar-14114.msh", "gmsh 4.1", 3842, 14114, 5788, {{"0"}, {"10"}, {"0"}, {"0.5"}, {"0"}, {"1"}}, 5, 1e-12, 0},
    {"ipc/rod300x33.msh", "gmsh 4.1", 13333, 50511, 19966, {{"-0.5"}, {"0.5"}, {"-0.0199"}, {"0.02"}, {"-0.01998"}, {"0.01998"}}, 1.2491e-3, 0.00005e-3, 0},
    {"ipc/Armadillo13K.msh", "gmsh 4.1", 13230, 54985, 17296, {{"-63.53"}, {"63.54"}, {"-54.19"}, {"97.17"}, {"-57.69"}, {"57.70"}}, 0, 0, 0},
    {"pbd/armadillo_4k.node", "tetgen", 1180, 3717, 2102, {{"-1.264"}, {"1.274"}, {"-1.081"}, {"1.949"}, {"-1.171"}, {"1.145"}}, 0, 0, 0},
    {"pbd/armadillo_4k.ele", "tetgen", 1180, 3717, 2102, {{"-1.264"}, {"1.274"}, {"-1.081"}, {"1.949"}, {"-1.171"}, {"1.145"}}, 0, 0, 0},
    {"sfepy/cylinder.mesh", "medit", 354, 1348, 440, {{"0"}, {"0.1"}, {"-0.02"}, {"0.02"}, {"-0.02"}, {"0.02"}}, 0, 0, 0},
    {"sfepy/cylinder.vtk", "vtk legacy 2.0", 354, 1348, 440, {{"0"}, {"0.1"}, {"-0.02"}, {"0.02"}, {"-0.02"}, {"0.02"}}, 0, 0, 0},
    {"sfepy/elbow2.mesh", "medit", 1823, 8161, 1678, {{"-0.03"}, {"0.23"}, {"0"}, {"0.1299"}, {"-0.03"}, {"0.03"}}, 0, 0, 8161},
    {"sfepy/wheelset.vtk", "vtk legacy 5.1", 5457, 21934, 6636, {{"-1.09"}, {"1.09"}, {"-0.46"}, {"0.46"}, {"-0.46"}, {"0.46"}}, 0, 0, 0},
    {"sfepy/octahedron.node", "tetgen", 330, 1224, 464, {{"-4"}, {"4"}, {"-4"}, {"4"}, {"-4"}, {"4"}}, 256.0 / 3.0, 1e-9, 0},
    {"sfepy/octahedron.ele", "tetgen", 330, 1224, 464, {{"-4"}, {"4"}, {"-4"}, {"4"}, {"-4"}, {"4"}}, 256.0 / 3.0, 1e-9, 0},
    {"sfepy/msh_tetra.msh", "gmsh 2.2", 66, 127, -1, {{"0"}, {"0.5"}, {"0"}, {"0.5"}, {"0"}, {"0.5"}}, 0, 0, 0},
    {"vega/beam3/beam3_tet.veg", "vega", 208, 450, -1, {{"-0.06"}, {"0.06"}, {"0"}, {"1"}, {"-0.02"}, {"0.02"}}, 0.0048, 1e-12, 0},
    {"vega/turtle/turtle-volumetric-homogeneous.veg", "vega", 347, 1185, 530, {{"-3.592"}, {"3.600"}, {"-0.2992"}, {"7.171"}, {"-1.559"}, {"2.175"}}, 45.19, 0.005, 0},
    {"vega/simpleBridge/simpleBridge-ic_128_0.15_.1.veg", "vega", 4000, 12827, 7058, {{"-10.17"}, {"10.13"}, {"-0.149"}, {"3.139"}, {"-1.428"}, {"1.354"}}, 30.71, 0.005, 0},
};

class TetFile : public ::testing::TestWithParam<TetCase> {};

TEST_P(TetFile, CountsBoundingBoxBoundaryAndVolumeMatchSources) {
  const TetCase& c = GetParam();
  COROFEM_REQUIRE_DATA(std::string("meshes/") + c.file);
  corofem::MeshReadReport report;
  const corofem::TetMesh mesh = corofem::test::loadTet(dataPath(std::string("meshes/") + c.file), &report);
  EXPECT_EQ(report.format, c.format);
  ASSERT_EQ(mesh.nodeCount(), c.nodes);
  ASSERT_EQ(mesh.tetCount(), c.tets);
  EXPECT_EQ(report.reorientedElements, c.reoriented);
  EXPECT_EQ(report.skippedElements, 0u);  // F = 0 and only tets in every listed tet file

  const corofem::MeshInfo info = corofem::computeMeshInfo(mesh);
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(info.bboxMin[a], c.bbox[2 * a].value(), c.bbox[2 * a].tolerance()) << "axis " << a;
    EXPECT_NEAR(info.bboxMax[a], c.bbox[2 * a + 1].value(), c.bbox[2 * a + 1].tolerance()) << "axis " << a;
  }
  if (c.boundary >= 0) EXPECT_EQ(info.boundaryFaces, std::size_t(c.boundary));
  if (c.volume > 0) EXPECT_NEAR(info.volume, c.volume, c.volumeTolerance);
  // "None of the tet meshes has degenerate tets ... or unused nodes"; all positive after loading.
  EXPECT_EQ(info.unusedNodes, 0u);
  EXPECT_EQ(info.negativeElements, 0u);
  EXPECT_GT(info.minVolume, 0.0);
  EXPECT_GE(info.minAspect, 1.0 - 1e-12);  // 1 is the regular tet, the best possible
}

INSTANTIATE_TEST_SUITE_P(SharedMeshes, TetFile, ::testing::ValuesIn(kTetCases),
                         [](const ::testing::TestParamInfo<TetCase>& info) {
                           std::string name = info.param.file;
                           for (char& ch : name)
                             if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                           return name;
                         });

struct ObjCase {
  const char* file;
  std::size_t vertices, triangles, quads;
  Printed bbox[6];
  bool texcoords;
};

std::ostream& operator<<(std::ostream& os, const ObjCase& c) { return os << c.file; }

// From SOURCES.md (N, F, notes on quads, bbox; "same as"/"as the .veg" rows use that file's bbox).
const ObjCase kObjCases[] = {
    {"sofa/liver-smooth.obj", 2194, 4384, 0, {{"-4.658"}, {"1.728"}, {"0.2644"}, {"5.172"}, {"-1.674"}, {"2.738"}}, false},
    {"sofa/liver.obj", 181, 274, 0, {{"-4.679"}, {"1.803"}, {"0.2179"}, {"5.157"}, {"-1.693"}, {"2.729"}}, false},
    {"ipc/dolphin5K.obj", 5002, 10000, 0, {{"-26.56"}, {"75.87"}, {"-11.53"}, {"79.36"}, {"2.724"}, {"76.00"}}, false},
    {"vega/beam3/beam3_tet.obj", 208, 412, 0, {{"-0.06"}, {"0.06"}, {"0"}, {"1"}, {"-0.02"}, {"0.02"}}, false},
    {"vega/beam3/beam3.obj", 208, 412, 206, {{"-0.06"}, {"0.06"}, {"0"}, {"1"}, {"-0.02"}, {"0.02"}}, false},
    {"vega/turtle/turtle.obj", 1961, 3654, 1770, {{"-3.368"}, {"3.368"}, {"0.0027"}, {"6.928"}, {"-1.291"}, {"1.912"}}, false},
    {"vega/turtle/turtle-volumetric.obj", 347, 530, 0, {{"-3.592"}, {"3.600"}, {"-0.2992"}, {"7.171"}, {"-1.559"}, {"2.175"}}, false},
    {"vega/simpleBridge/simpleBridge.obj", 16085, 32014, 15396, {{"-10.02"}, {"9.976"}, {"-0.0063"}, {"3.005"}, {"-1.290"}, {"1.210"}}, false},
    {"vega/simpleBridge/simpleBridge-ic_128_0.15_.1.obj", 4000, 7058, 0, {{"-10.17"}, {"10.13"}, {"-0.149"}, {"3.139"}, {"-1.428"}, {"1.354"}}, false},
};

class ObjFile : public ::testing::TestWithParam<ObjCase> {};

TEST_P(ObjFile, CountsAndBoundingBoxMatchSources) {
  const ObjCase& c = GetParam();
  COROFEM_REQUIRE_DATA(std::string("meshes/") + c.file);
  corofem::MeshReadReport report;
  auto r = corofem::readSurfaceMesh(dataPath(std::string("meshes/") + c.file), &report);
  ASSERT_TRUE(r.isOk()) << r.message();
  const corofem::SurfaceMesh& s = r.value();
  EXPECT_EQ(report.format, "obj");
  EXPECT_EQ(s.vertexCount(), c.vertices);
  EXPECT_EQ(s.triangleCount(), c.triangles);
  // Every quad splits into 2 triangles; SOURCES.md counts quads, we count split polygons (all quads here).
  EXPECT_EQ(report.splitPolygons, c.quads);
  EXPECT_EQ(!s.texcoords.empty(), c.texcoords);
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (std::size_t i = 0; i < s.vertexCount(); ++i)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], s.vertices[3 * i + a]);
      hi[a] = std::max(hi[a], s.vertices[3 * i + a]);
    }
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(lo[a], c.bbox[2 * a].value(), c.bbox[2 * a].tolerance()) << "axis " << a;
    EXPECT_NEAR(hi[a], c.bbox[2 * a + 1].value(), c.bbox[2 * a + 1].tolerance()) << "axis " << a;
  }
  for (std::uint32_t v : s.triangles) ASSERT_LT(v, s.vertexCount());
}

INSTANTIATE_TEST_SUITE_P(SharedMeshes, ObjFile, ::testing::ValuesIn(kObjCases),
                         [](const ::testing::TestParamInfo<ObjCase>& info) {
                           std::string name = info.param.file;
                           for (char& ch : name)
                             if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                           return name;
                         });

// sfepy ships the same cylinder as Medit and as VTK 2.0: both readers must agree exactly.
TEST(CrossFormat, CylinderMeshAndVtkAreTheSameMesh) {
  COROFEM_REQUIRE_DATA("meshes/sfepy/cylinder.mesh");
  COROFEM_REQUIRE_DATA("meshes/sfepy/cylinder.vtk");
  const auto medit = corofem::test::loadTet(dataPath("meshes/sfepy/cylinder.mesh"));
  const auto vtk = corofem::test::loadTet(dataPath("meshes/sfepy/cylinder.vtk"));
  ASSERT_EQ(medit.nodeCount(), vtk.nodeCount());
  ASSERT_EQ(medit.tetCount(), vtk.tetCount());
  for (std::size_t i = 0; i < medit.nodes.size(); ++i)
    ASSERT_NEAR(medit.nodes[i], vtk.nodes[i], 1e-12) << "value " << i;  // same decimal text in both files
  for (std::size_t e = 0; e < medit.tetCount(); ++e) {
    std::multiset<std::uint32_t> a(medit.tets.begin() + 4 * e, medit.tets.begin() + 4 * e + 4);
    std::multiset<std::uint32_t> b(vtk.tets.begin() + 4 * e, vtk.tets.begin() + 4 * e + 4);
    ASSERT_EQ(a, b) << "element " << e;
  }
  // Medit references and the VTK mat_id cell data are the same material ids.
  EXPECT_EQ(medit.regions, vtk.regions);
  EXPECT_EQ(medit.regions.size(), medit.tetCount());
}

TEST(Orientation, Elbow2IsAllNegativeAndEveryElementIsReoriented) {
  COROFEM_REQUIRE_DATA("meshes/sfepy/elbow2.mesh");
  corofem::MeshReadReport report;
  const auto mesh = corofem::test::loadTet(dataPath("meshes/sfepy/elbow2.mesh"), &report);
  EXPECT_EQ(report.reorientedElements, 8161u);
  for (std::size_t e = 0; e < mesh.tetCount(); ++e) ASSERT_GT(corofem::signedVolume(mesh, e), 0.0) << e;

  // With reorientation off, the file's convention shows: every element negative.
  corofem::MeshValidation keep;
  keep.reorient = false;
  auto raw = corofem::readTetMesh(dataPath("meshes/sfepy/elbow2.mesh"), nullptr, keep);
  ASSERT_TRUE(raw.isOk()) << raw.message();
  EXPECT_EQ(corofem::computeMeshInfo(raw.value()).negativeElements, 8161u);
}

TEST(Regions, OctahedronRegionAttributeAndWheelsetMatId) {
  COROFEM_REQUIRE_DATA("meshes/sfepy/octahedron.ele");
  const auto oct = corofem::test::loadTet(dataPath("meshes/sfepy/octahedron.ele"));
  ASSERT_EQ(oct.regions.size(), 1224u);
  EXPECT_EQ(oct.regions.front(), 100);  // the first .ele row ends in attribute 100
  EXPECT_EQ(oct.regions.back(), 100);
  COROFEM_REQUIRE_DATA("meshes/sfepy/wheelset.vtk");
  const auto wheel = corofem::test::loadTet(dataPath("meshes/sfepy/wheelset.vtk"));
  EXPECT_EQ(wheel.regions.size(), wheel.tetCount());  // from the CELL_DATA FIELD array mat_id
  COROFEM_REQUIRE_DATA("meshes/pbd/armadillo_4k.ele");
  EXPECT_TRUE(corofem::test::loadTet(dataPath("meshes/pbd/armadillo_4k.ele")).regions.empty());  // no attributes
}

TEST(ZeroBased, ArmadilloNodeIdsStartAtZeroOctahedronAtOne) {
  COROFEM_REQUIRE_DATA("meshes/pbd/armadillo_4k.node");
  COROFEM_REQUIRE_DATA("meshes/sfepy/octahedron.node");
  // First .node rows: "0  -1.03293 1.35422 -1.17087" and "1  0 0 0".
  const auto arm = corofem::test::loadTet(dataPath("meshes/pbd/armadillo_4k.node"));
  EXPECT_DOUBLE_EQ(arm.nodes[0], -1.0329299999999999);
  const auto oct = corofem::test::loadTet(dataPath("meshes/sfepy/octahedron.node"));
  EXPECT_DOUBLE_EQ(oct.nodes[0], 0.0);
  EXPECT_DOUBLE_EQ(oct.nodes[3], 4.0);  // node 2 is (4, 0, 0)
  // First element "0  480 116 560 1054" (0-based), possibly with two nodes swapped for orientation.
  std::multiset<std::uint32_t> first(arm.tets.begin(), arm.tets.begin() + 4);
  EXPECT_EQ(first, (std::multiset<std::uint32_t>{480, 116, 560, 1054}));
}

TEST(Gmsh, Liver1FirstElementAndNodes) {
  COROFEM_REQUIRE_DATA("meshes/sofa/liver.msh");
  const auto liver = corofem::test::loadTet(dataPath("meshes/sofa/liver.msh"));
  // "$NOD ... 1 -0.979259 2.23512 2.61245"; "$ELM ... 1 4 1 1 4 128 141 138 142" (1-based).
  EXPECT_DOUBLE_EQ(liver.nodes[0], -0.979259);
  EXPECT_DOUBLE_EQ(liver.nodes[2], 2.61245);
  std::multiset<std::uint32_t> first(liver.tets.begin(), liver.tets.begin() + 4);
  EXPECT_EQ(first, (std::multiset<std::uint32_t>{127, 140, 137, 141}));
  EXPECT_EQ(liver.regions.size(), liver.tetCount());  // physical region 1 for every element
}

}  // namespace
