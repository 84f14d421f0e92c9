// bindSurface on small meshes with known answers, and its grid search against brute force.
#include <corofem/embed.hpp>
#include <corofem/mesh.hpp>

#include "embed/element_locator.hpp"
#include "embed/embed_test_util.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace corofem {
namespace {

using test::point;

constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(EmbedBinding, CentroidOfOneTetHasEqualWeights) {
  const TetMesh tet = test::unitTet();
  auto b = bindSurface(tet, test::pointCloud({0.25, 0.25, 0.25}));
  ASSERT_TRUE(b.isOk()) << b.message();
  EXPECT_EQ(b->element[0], 0u);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(b->nodes[k], static_cast<std::uint32_t>(k));
    EXPECT_NEAR(b->weights[k], 0.25, 1e-15);  // exact up to one rounding
  }
  EXPECT_EQ(b->statistics.insideCount, 1u);
  EXPECT_EQ(b->statistics.outsideCount, 0u);
  EXPECT_EQ(b->statistics.largestDistance, 0.0);
  EXPECT_NEAR(b->statistics.boundingBoxDiagonal, std::sqrt(3.0), 1e-15);
  EXPECT_NEAR(b->statistics.maxDistanceUsed, 0.05 * std::sqrt(3.0), 1e-15);
}

// Two tets sharing the face (1, 2, 3); vertices on that face (and on its nodes) lie in both. The
// lowest element index wins, whatever the order of the elements in the mesh.
TEST(EmbedBinding, VertexOnSharedFacePicksLowestElementIndex) {
  TetMesh m;
  m.nodes = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1};
  const std::vector<std::uint32_t> a = {0, 1, 2, 3}, b = {4, 1, 3, 2};
  const std::vector<double> onFace = {1.0 / 3, 1.0 / 3, 1.0 / 3, /* node 1 */ 1, 0, 0,
                                      /* edge 1-2 midpoint */ 0.5, 0.5, 0};
  for (int order = 0; order < 2; ++order) {
    m.tets = order == 0 ? a : b;
    m.tets.insert(m.tets.end(), (order == 0 ? b : a).begin(), (order == 0 ? b : a).end());
    auto r = bindSurface(m, test::pointCloud(onFace));
    ASSERT_TRUE(r.isOk()) << r.message();
    for (std::size_t v = 0; v < 3; ++v) {
      EXPECT_EQ(r->element[v], 0u) << "order " << order << " vertex " << v;
      EXPECT_LT((test::interpolate(m.nodes, &r->nodes[4 * v], &r->weights[4 * v]) - point(onFace, v)).norm(), 1e-15);
    }
    EXPECT_EQ(r->statistics.insideCount, 3u);
  }
}

TEST(EmbedBinding, OutsideVertexGetsTrueDistanceAndExtrapolatedWeights) {
  const TetMesh tet = test::unitTet();
  // Below the face z = 0 (foot point inside the face): distance 0.1. Beyond node 0: sqrt(3) * 0.1.
  // Beyond the face x + y + z = 1: distance (1.2 - 1) / sqrt(3).
  const std::vector<double> xyz = {0.5, 0.2, -0.1, -0.1, -0.1, -0.1, 0.4, 0.4, 0.4};
  BindingOptions options;
  options.maxDistance = 0.2;  // the default, 5% of the diagonal, is 0.087
  auto b = bindSurface(tet, test::pointCloud(xyz), options);
  ASSERT_TRUE(b.isOk()) << b.message();
  const BindingStatistics& s = b->statistics;
  ASSERT_EQ(s.outsideCount, 3u);
  EXPECT_EQ(s.insideCount, 0u);
  ASSERT_EQ(s.outsideVertices, (std::vector<std::uint32_t>{0, 1, 2}));
  EXPECT_NEAR(s.outsideDistances[0], 0.1, 1e-15);
  EXPECT_NEAR(s.outsideDistances[1], std::sqrt(0.03), 1e-15);
  EXPECT_NEAR(s.outsideDistances[2], 0.2 / std::sqrt(3.0), 1e-15);
  EXPECT_NEAR(s.largestDistance, std::sqrt(0.03), 1e-15);
  // Barycentric coordinates of (x, y, z) in the unit tet are (1 - x - y - z, x, y, z).
  const double expected[4] = {0.4, 0.5, 0.2, -0.1};
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(b->weights[k], expected[k], 1e-15);
  for (std::size_t v = 0; v < 3; ++v)
    EXPECT_LT((test::interpolate(tet.nodes, &b->nodes[4 * v], &b->weights[4 * v]) - point(xyz, v)).norm(), 1e-15);
}

TEST(EmbedBinding, InsideToleranceDecidesBoundaryVertices) {
  const TetMesh tet = test::unitTet();
  const std::vector<double> xyz = {0.3, 0.3, -1e-12};  // 1e-12 below the face z = 0
  BindingOptions options;
  auto loose = bindSurface(tet, test::pointCloud(xyz), options);  // default tolerance 1e-10
  ASSERT_TRUE(loose.isOk()) << loose.message();
  EXPECT_EQ(loose->statistics.insideCount, 1u);
  options.insideTolerance = 0.0;
  auto strict = bindSurface(tet, test::pointCloud(xyz), options);
  ASSERT_TRUE(strict.isOk()) << strict.message();
  ASSERT_EQ(strict->statistics.outsideCount, 1u);
  EXPECT_NEAR(strict->statistics.outsideDistances[0], 1e-12, 1e-20);
}

TEST(EmbedBinding, MaxDistanceZeroRequiresEveryVertexInsideAndInfinityAcceptsAny) {
  const TetMesh tet = test::unitTet();
  const std::vector<double> xyz = {0.1, 0.1, 0.1, 50.0, 0.0, 0.0};
  BindingOptions options;
  options.maxDistance = 0.0;
  auto none = bindSurface(tet, test::pointCloud(xyz), options);
  ASSERT_FALSE(none.isOk());
  EXPECT_EQ(none.status().code(), ErrorCode::BadInput);
  options.maxDistance = kInf;
  auto any = bindSurface(tet, test::pointCloud(xyz), options);
  ASSERT_TRUE(any.isOk()) << any.message();
  EXPECT_NEAR(any->statistics.largestDistance, 49.0, 1e-12);  // to node 1 = (1, 0, 0)
  EXPECT_TRUE(std::isinf(any->statistics.maxDistanceUsed));
}

// The grid search must give exactly what a loop over all elements gives: for inside points the
// lowest-index element that contains them, for outside points the smallest distance (the element may
// differ only on ties). Points: random ones in and around the mesh, and the lattice points of the box
// cells (each shared by up to 20 elements: the tie rule under stress).
TEST(EmbedBinding, GridSearchEqualsBruteForce) {
  BoxSpec spec;
  spec.min = {-1.0, 0.0, 2.0};
  spec.max = {3.0, 1.5, 4.5};
  spec.cells = {7, 3, 5};
  for (int tetsPerCell : {5, 6}) {
    spec.tetsPerCell = tetsPerCell;
    auto box = generateBox(spec);
    ASSERT_TRUE(box.isOk()) << box.message();
    // Perturb the interior nodes so that elements are irregular (boundary stays a box).
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-0.3, 0.3);
    TetMesh m = *box;
    for (std::size_t n = 0; n < m.nodeCount(); ++n)
      for (int a = 0; a < 3; ++a) {
        const double h = (spec.max[a] - spec.min[a]) / spec.cells[a];
        const double x = m.nodes[3 * n + a];
        if (x > spec.min[a] + 1e-9 && x < spec.max[a] - 1e-9) m.nodes[3 * n + a] = x + u(rng) * h;
      }
    std::vector<double> xyz;
    std::uniform_real_distribution<double> ux(-2.0, 4.0), uy(-1.0, 2.5), uz(1.0, 5.5);
    for (int i = 0; i < 3000; ++i) xyz.insert(xyz.end(), {ux(rng), uy(rng), uz(rng)});
    for (int i = 0; i <= spec.cells[0]; ++i)
      for (int j = 0; j <= spec.cells[1]; ++j)
        for (int k = 0; k <= spec.cells[2]; ++k)
          xyz.insert(xyz.end(), {spec.min[0] + i * (spec.max[0] - spec.min[0]) / spec.cells[0],
                                 spec.min[1] + j * (spec.max[1] - spec.min[1]) / spec.cells[1],
                                 spec.min[2] + k * (spec.max[2] - spec.min[2]) / spec.cells[2]});
    BindingOptions options;
    options.maxDistance = kInf;
    auto b = bindSurface(m, test::pointCloud(xyz), options);
    ASSERT_TRUE(b.isOk()) << b.message();
    const BindingStatistics& s = b->statistics;
    detail::ElementLocator locator(m, 0.0);
    const double tieTolerance = 1e-12 * s.boundingBoxDiagonal;  // the search's own tie tolerance
    std::size_t inside = 0, outsideSeen = 0;
    for (std::size_t v = 0; v < xyz.size() / 3; ++v) {
      const detail::Point3 p{xyz[3 * v], xyz[3 * v + 1], xyz[3 * v + 2]};
      std::uint32_t containing = detail::ElementLocator::kNone;
      double nearest = kInf;
      for (std::size_t e = 0; e < m.tetCount(); ++e) {
        double w[4];
        locator.barycentric(e, p, w);
        if (containing == detail::ElementLocator::kNone && *std::min_element(w, w + 4) >= -options.insideTolerance)
          containing = static_cast<std::uint32_t>(e);
        nearest = std::min(nearest, locator.pointTetDistance(e, p));
      }
      if (containing != detail::ElementLocator::kNone) {
        ++inside;
        ASSERT_EQ(b->element[v], containing) << "tets/cell " << tetsPerCell << " point " << v;
      } else {
        ASSERT_LT(outsideSeen, s.outsideVertices.size());
        ASSERT_EQ(s.outsideVertices[outsideSeen], v);
        EXPECT_NEAR(s.outsideDistances[outsideSeen], nearest, tieTolerance) << "point " << v;
        ++outsideSeen;
      }
    }
    EXPECT_EQ(inside, s.insideCount);
    EXPECT_EQ(outsideSeen, s.outsideCount);
    EXPECT_GT(inside, 500u);      // the sample really covers both cases
    EXPECT_GT(outsideSeen, 500u);
  }
}

TEST(EmbedBinding, ResultDoesNotDependOnThreadCount) {
  BoxSpec spec;
  spec.cells = {6, 6, 6};
  auto box = generateBox(spec);
  ASSERT_TRUE(box.isOk()) << box.message();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.02, 1.02);
  std::vector<double> xyz;
  for (int i = 0; i < 50000; ++i) xyz.insert(xyz.end(), {u(rng), u(rng), u(rng)});
  BindingOptions options;
  options.threads = 1;
  auto one = bindSurface(*box, test::pointCloud(xyz), options);
  options.threads = 2;
  auto two = bindSurface(*box, test::pointCloud(xyz), options);
  options.threads = 3;  // more threads than cores: still identical
  auto three = bindSurface(*box, test::pointCloud(xyz), options);
  ASSERT_TRUE(one.isOk() && two.isOk() && three.isOk());
  EXPECT_EQ(one->element, two->element);
  EXPECT_EQ(one->weights, two->weights);  // bitwise
  EXPECT_EQ(one->element, three->element);
  EXPECT_EQ(one->weights, three->weights);
  EXPECT_EQ(one->statistics.outsideVertices, two->statistics.outsideVertices);
  EXPECT_EQ(one->statistics.outsideDistances, three->statistics.outsideDistances);
  EXPECT_GT(one->statistics.outsideCount, 0u);
}

TEST(EmbedBinding, VertexTriangleAdjacencyListsEachCornerInOrder) {
  const TetMesh tet = test::unitTet();
  SurfaceMesh s = test::pointCloud({0.1, 0.1, 0.1, 0.2, 0.1, 0.1, 0.1, 0.2, 0.1, 0.1, 0.1, 0.2});
  s.triangles = {0, 1, 2, 0, 2, 3, 1, 3, 2};
  auto b = bindSurface(tet, s);
  ASSERT_TRUE(b.isOk()) << b.message();
  EXPECT_EQ(b->vertexTriangleOffsets, (std::vector<std::uint32_t>{0, 2, 4, 7, 9}));
  EXPECT_EQ(b->vertexTriangles, (std::vector<std::uint32_t>{0, 1, 0, 2, 0, 1, 2, 1, 2}));
  EXPECT_EQ(b->triangles, s.triangles);
}

}  // namespace
}  // namespace corofem
