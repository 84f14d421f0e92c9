// bindSurface on bad input: every failure is ErrorCode::BadInput with a message that names the place
// and the fix.
#include <corofem/embed.hpp>
#include <corofem/mesh.hpp>

#include "embed/embed_test_util.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace corofem {
namespace {

::testing::AssertionResult mentions(const std::string& message, const std::string& part) {
  if (message.find(part) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "message \"" << message << "\" does not mention \"" << part << "\"";
}

TEST(EmbedErrors, FarVertexIsCountedAndLocated) {
  const TetMesh tet = test::unitTet();
  // Vertex 2 is 9 from the tet (nearest point: node 1 at (1, 0, 0)); the default limit is
  // 0.05 * sqrt(3) = 0.0866.
  auto r = bindSurface(tet, test::pointCloud({0.1, 0.1, 0.1, 0.2, 0.2, 0.2, 10, 0, 0}));
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::BadInput);
  const std::string& m = r.message();
  EXPECT_TRUE(mentions(m, "1 of 3 surface vertices"));
  EXPECT_TRUE(mentions(m, "vertex 2 at (10, 0, 0) is 9 away"));
  EXPECT_TRUE(mentions(m, "BindingOptions::maxDistance = 0.0866"));
  EXPECT_TRUE(mentions(m, "the default, 5% of the tet mesh's bounding-box diagonal"));
  EXPECT_TRUE(mentions(m, "raise BindingOptions::maxDistance (to at least 9"));
}

TEST(EmbedErrors, ManyFarVerticesShowTheFirstFiveAndCountTheRest) {
  const TetMesh tet = test::unitTet();
  std::vector<double> xyz = {0.1, 0.1, 0.1};
  for (int i = 0; i < 8; ++i) xyz.insert(xyz.end(), {0.0, 0.0, 2.0 + i});  // vertices 1..8
  BindingOptions options;
  options.maxDistance = 0.5;
  auto r = bindSurface(tet, test::pointCloud(xyz), options);
  ASSERT_FALSE(r.isOk());
  const std::string& m = r.message();
  EXPECT_TRUE(mentions(m, "8 of 9 surface vertices"));
  EXPECT_TRUE(mentions(m, "maxDistance = 0.5 (tet mesh bounding-box diagonal"));
  EXPECT_TRUE(mentions(m, "vertex 1 at (0, 0, 2) is 1 away"));
  EXPECT_TRUE(mentions(m, "vertex 5 at (0, 0, 6) is 5 away"));
  EXPECT_FALSE(mentions(m, "vertex 6 at"));
  EXPECT_TRUE(mentions(m, "and 3 more"));
}

TEST(EmbedErrors, EmptyMeshesAreRejected) {
  const TetMesh tet = test::unitTet();
  auto noTets = bindSurface(TetMesh{}, test::pointCloud({0, 0, 0}));
  ASSERT_FALSE(noTets.isOk());
  EXPECT_EQ(noTets.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(mentions(noTets.message(), "the tet mesh is empty (0 nodes, 0 elements)"));
  TetMesh nodesOnly = tet;
  nodesOnly.tets.clear();
  auto noElements = bindSurface(nodesOnly, test::pointCloud({0, 0, 0}));
  ASSERT_FALSE(noElements.isOk());
  EXPECT_TRUE(mentions(noElements.message(), "(4 nodes, 0 elements)"));
  auto noVertices = bindSurface(tet, SurfaceMesh{});
  ASSERT_FALSE(noVertices.isOk());
  EXPECT_EQ(noVertices.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(mentions(noVertices.message(), "the surface mesh has no vertices"));
}

TEST(EmbedErrors, NonFiniteVertexIsNamed) {
  const TetMesh tet = test::unitTet();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  auto r = bindSurface(tet, test::pointCloud({0.1, 0.1, 0.1, 0.2, nan, 0.2}));
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(mentions(r.message(), "surface vertex 1 has a non-finite coordinate (0.2, nan, 0.2)"));
  auto inf = bindSurface(tet, test::pointCloud({0.1, 0.1, std::numeric_limits<double>::infinity()}));
  ASSERT_FALSE(inf.isOk());
  EXPECT_TRUE(mentions(inf.message(), "surface vertex 0"));
  TetMesh badNode = tet;
  badNode.nodes[7] = nan;
  auto n = bindSurface(badNode, test::pointCloud({0.1, 0.1, 0.1}));
  ASSERT_FALSE(n.isOk());
  EXPECT_TRUE(mentions(n.message(), "tet mesh node 2 has a non-finite coordinate y"));
}

TEST(EmbedErrors, IndicesOutOfRangeAndFlatElementsAreNamed) {
  TetMesh tet = test::unitTet();
  SurfaceMesh s = test::pointCloud({0.1, 0.1, 0.1, 0.2, 0.1, 0.1, 0.1, 0.2, 0.1});
  s.triangles = {0, 1, 2, 0, 2, 3};
  auto tri = bindSurface(tet, s);
  ASSERT_FALSE(tri.isOk());
  EXPECT_TRUE(mentions(tri.message(), "surface triangle 1 refers to vertex 3 but the surface has only 3 vertices"));
  s.triangles.resize(3);
  TetMesh badIndex = tet;
  badIndex.tets[2] = 4;
  auto idx = bindSurface(badIndex, s);
  ASSERT_FALSE(idx.isOk());
  EXPECT_TRUE(mentions(idx.message(), "element 0 refers to node 4 but the tet mesh has only 4 nodes"));
  TetMesh flat = tet;
  flat.nodes[11] = 0.0;  // node 3 moved into the plane z = 0
  auto f = bindSurface(flat, s);
  ASSERT_FALSE(f.isOk());
  EXPECT_EQ(f.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(mentions(f.message(), "element 0 is flat (zero volume; nodes 0, 1, 2, 3)"));
}

TEST(EmbedErrors, BadOptionsAreRejected) {
  const TetMesh tet = test::unitTet();
  BindingOptions options;
  options.insideTolerance = -1e-3;
  auto t = bindSurface(tet, test::pointCloud({0.1, 0.1, 0.1}), options);
  ASSERT_FALSE(t.isOk());
  EXPECT_TRUE(mentions(t.message(), "BindingOptions::insideTolerance is -0.001"));
  options = {};
  options.maxDistance = std::numeric_limits<double>::quiet_NaN();
  auto d = bindSurface(tet, test::pointCloud({0.1, 0.1, 0.1}), options);
  ASSERT_FALSE(d.isOk());
  EXPECT_TRUE(mentions(d.message(), "BindingOptions::maxDistance is NaN"));
}

}  // namespace
}  // namespace corofem
