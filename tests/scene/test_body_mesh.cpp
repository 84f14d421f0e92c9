// loadBodyMesh (file or generated box, then scale and translate) and node sets on real meshes.
#include "common/test_data.hpp"

#include <corofem/scene.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>
#include <filesystem>

namespace corofem {
namespace {

std::array<double, 6> bounds(const TetMesh& mesh) {
  std::array<double, 6> b{1e300, 1e300, 1e300, -1e300, -1e300, -1e300};
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n)
    for (int a = 0; a < 3; ++a) {
      b[a] = std::min(b[a], mesh.nodes[3 * n + a]);
      b[3 + a] = std::max(b[3 + a], mesh.nodes[3 * n + a]);
    }
  return b;
}

TEST(BodyMesh, GeneratedBoxIsScaledThenTranslated) {
  BodyDesc body;
  BoxSpec box;
  box.min = {0, 0, 0};
  box.max = {0.8, 0.1, 0.1};
  box.cells = {8, 1, 1};
  body.mesh.box = box;
  body.mesh.scale = 2.0;
  body.mesh.translate = {1, -1, 0.5};
  MeshReadReport report;
  report.reorientedElements = 99;  // must be reset
  Result<TetMesh> mesh = loadBodyMesh(body, "", &report);
  ASSERT_TRUE(mesh.isOk()) << mesh.message();
  EXPECT_EQ(mesh->nodeCount(), 9u * 2 * 2);
  EXPECT_EQ(mesh->tetCount(), 8u * 5);
  EXPECT_EQ(report.reorientedElements, 0u);
  // x' = 2 x + t; tolerance: a few ulps of rounding in the generator's coordinates.
  const auto b = bounds(*mesh);
  const std::array<double, 6> expected{1, -1, 0.5, 2.6, -0.8, 0.7};
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(b[i], expected[i], 1e-12) << i;
}

TEST(BodyMesh, FileIsResolvedAgainstTheBaseDir) {
  COROFEM_REQUIRE_DATA("meshes/vega/beam3/beam3_tet.veg");
  BodyDesc body;
  body.name = "beam";
  body.mesh.file = "beam3/beam3_tet.veg";
  body.mesh.scale = 10;
  body.mesh.translate = {0, 0, 1};
  MeshReadReport report;
  Result<TetMesh> mesh = loadBodyMesh(body, test::dataPath("meshes/vega"), &report);
  ASSERT_TRUE(mesh.isOk()) << mesh.message();
  EXPECT_EQ(mesh->nodeCount(), 208u);  // SOURCES.md: N = 208, T = 450
  EXPECT_EQ(mesh->tetCount(), 450u);
  EXPECT_FALSE(report.format.empty());
  // bbox x[-0.06, 0.06] y[0, 1] z[-0.02, 0.02], times 10, plus (0, 0, 1); tolerance: the file's
  // printed digits (0.160000000000001-style rounding) times the scale.
  const auto b = bounds(*mesh);
  const std::array<double, 6> expected{-0.6, 0, 0.8, 0.6, 10, 1.2};
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(b[i], expected[i], 1e-12) << i;
}

TEST(BodyMesh, MissingFileNamesTheBodyAndTheResolvedPath) {
  BodyDesc body;
  body.name = "beam";
  body.mesh.file = "missing.msh";
  Result<TetMesh> mesh = loadBodyMesh(body, "/nonexistent/scenes");
  ASSERT_FALSE(mesh.isOk());
  EXPECT_EQ(mesh.message().rfind("body \"beam\": ", 0), 0u) << mesh.message();
  EXPECT_NE(mesh.message().find("/nonexistent/scenes/missing.msh"), std::string::npos) << mesh.message();
}

TEST(BodyMesh, InvalidDescriptionsAreBadInput) {
  BodyDesc neither;
  EXPECT_EQ(loadBodyMesh(neither, "").status().code(), ErrorCode::BadInput);
  BodyDesc both;
  both.mesh.file = "a.msh";
  both.mesh.box = BoxSpec{};
  EXPECT_EQ(loadBodyMesh(both, "").message(), "body \"body\": the mesh has both a file and a box; give exactly one");
  BodyDesc flat;
  flat.mesh.box = BoxSpec{};
  flat.mesh.scale = 0;
  EXPECT_EQ(loadBodyMesh(flat, "").message(), "body \"body\": mesh scale 0 must be a finite number > 0");
}

TEST(BodyMesh, VegaBouSelectsTheEndFaceOfBeam3) {
  COROFEM_REQUIRE_DATA("meshes/vega/beam3/beam3_tet.veg");
  COROFEM_REQUIRE_DATA("meshes/vega/beam3/beam3.bou");
  BodyDesc body;
  body.mesh.file = test::dataPath("meshes/vega/beam3/beam3_tet.veg");
  Result<TetMesh> mesh = loadBodyMesh(body, "");
  ASSERT_TRUE(mesh.isOk()) << mesh.message();

  NodeSetDesc bou;
  bou.kind = NodeSetDesc::Kind::BouFile;
  bou.bouFile = "beam3.bou";
  auto fixed = resolveNodeSet(bou, *mesh, test::dataPath("meshes/vega/beam3"));
  ASSERT_TRUE(fixed.isOk()) << fixed.message();
  // Ids 51, 52, 103, 104, 155, 156, 207, 208 (1-based) are the 8 nodes of the y = 1 end face.
  EXPECT_EQ(*fixed, (std::vector<std::uint32_t>{50, 51, 102, 103, 154, 155, 206, 207}));
  for (std::uint32_t n : *fixed) EXPECT_EQ(mesh->nodes[3 * n + 1], 1.0) << "node " << n;

  // The same face as a plane and as a box: the three kinds agree.
  NodeSetDesc plane;
  plane.kind = NodeSetDesc::Kind::Plane;
  plane.planePoint = {0, 1, 0};
  plane.planeNormal = {0, 1, 0};
  auto onPlane = resolveNodeSet(plane, *mesh);
  ASSERT_TRUE(onPlane.isOk()) << onPlane.message();
  EXPECT_EQ(*onPlane, *fixed);
  NodeSetDesc box;
  box.kind = NodeSetDesc::Kind::Box;
  box.boxMin = {-1, 1, -1};
  box.boxMax = {1, 1, 1};
  auto inBox = resolveNodeSet(box, *mesh);
  ASSERT_TRUE(inBox.isOk()) << inBox.message();
  EXPECT_EQ(*inBox, *fixed);
}

// A mesh the application holds in memory (MeshSourceDesc::mesh): the box's answer when it is the
// box's mesh, scaled and translated the same way; checked like a file's, inverted elements turned.
TEST(BodyMesh, InMemoryMeshIsTheBoxsAndIsChecked) {
  BoxSpec box;
  box.max = {0.8, 0.1, 0.1};
  box.cells = {8, 1, 1};
  BodyDesc fromBox;
  fromBox.mesh.box = box;
  fromBox.mesh.scale = 2.0;
  fromBox.mesh.translate = {1, -1, 0.5};
  Result<TetMesh> generated = generateBox(box);
  ASSERT_TRUE(generated) << generated.message();
  BodyDesc fromMemory = fromBox;
  fromMemory.name = "held";
  fromMemory.mesh.box.reset();
  fromMemory.mesh.mesh = std::make_shared<const TetMesh>(generated.value());
  MeshReadReport report;
  Result<TetMesh> a = loadBodyMesh(fromBox, ""), b = loadBodyMesh(fromMemory, "", &report);
  ASSERT_TRUE(a) << a.message();
  ASSERT_TRUE(b) << b.message();
  EXPECT_EQ(a->nodes, b->nodes);
  EXPECT_EQ(a->tets, b->tets);
  EXPECT_EQ(report.format, "in memory");
  EXPECT_EQ(report.reorientedElements, 0u);

  // An inverted element is turned and counted, as a reader does; the application's mesh is untouched.
  TetMesh inverted = generated.value();
  std::swap(inverted.tets[2], inverted.tets[3]);
  fromMemory.mesh.mesh = std::make_shared<const TetMesh>(inverted);
  Result<TetMesh> turned = loadBodyMesh(fromMemory, "", &report);
  ASSERT_TRUE(turned) << turned.message();
  EXPECT_EQ(report.reorientedElements, 1u);
  EXPECT_EQ(turned->tets, a->tets);
  EXPECT_NE(fromMemory.mesh.mesh->tets, a->tets);

  // Bad meshes: a clear BadInput naming the body, the mesh and the fix.
  struct Bad {
    const char* what;
    std::function<void(TetMesh&)> spoil;
    const char* says;
  };
  const std::vector<Bad> bad = {
      {"index out of range", [](TetMesh& m) { m.tets[5] = static_cast<std::uint32_t>(m.nodeCount()); }, "names node"},
      {"a node twice", [](TetMesh& m) { m.tets[1] = m.tets[0]; }, "twice"},
      {"not finite", [](TetMesh& m) { m.nodes[4] = std::nan(""); }, "not finite"},
      {"flat element",
       [](TetMesh& m) {  // element 0's fourth node moved into the plane of its other three
         const std::uint32_t* t = &m.tets[0];
         for (int a = 0; a < 3; ++a)
           m.nodes[3 * t[3] + a] = m.nodes[3 * t[1] + a] + m.nodes[3 * t[2] + a] - m.nodes[3 * t[0] + a];
       },
       "volume"},
      {"sizes", [](TetMesh& m) { m.tets.pop_back(); }, "4 per element"},
      {"regions", [](TetMesh& m) { m.regions = {1, 2}; }, "region ids"},
      {"empty", [](TetMesh& m) { m.tets.clear(); }, "no tetrahedra"},
  };
  for (const Bad& c : bad) {
    SCOPED_TRACE(c.what);
    TetMesh spoilt = generated.value();
    c.spoil(spoilt);
    fromMemory.mesh.mesh = std::make_shared<const TetMesh>(spoilt);
    Result<TetMesh> r = loadBodyMesh(fromMemory, "");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.status().code(), ErrorCode::BadInput);
    EXPECT_NE(r.message().find("body \"held\""), std::string::npos) << r.message();
    EXPECT_NE(r.message().find("MeshSourceDesc::mesh"), std::string::npos) << r.message();
    EXPECT_NE(r.message().find(c.says), std::string::npos) << r.message();
  }
  // Exactly one source.
  fromMemory.mesh.mesh = std::make_shared<const TetMesh>(generated.value());
  fromMemory.mesh.box = box;
  Result<TetMesh> two = loadBodyMesh(fromMemory, "");
  ASSERT_FALSE(two);
  EXPECT_NE(two.message().find("exactly one"), std::string::npos) << two.message();
}

}  // namespace
}  // namespace corofem
