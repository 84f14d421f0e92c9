// deformSurface: positions under known maps, normals, output layouts, determinism.
#include <corofem/embed.hpp>
#include <corofem/mesh.hpp>

#include "embed/embed_test_util.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

namespace corofem {
namespace {

using test::point;

/// A sphere of radius 0.4 inside the unit box, bound to a 5x5x5-cell box mesh (625 tets).
struct SphereInBox {
  TetMesh tets;
  SurfaceMesh surface;
  SurfaceBinding binding;
};

SphereInBox makeSphereInBox(int stacks = 24, int slices = 48) {
  SphereInBox s;
  BoxSpec spec;
  spec.cells = {5, 5, 5};
  s.tets = *generateBox(spec);
  s.surface = test::uvSphere({0.5, 0.5, 0.5}, 0.4, stacks, slices);
  auto b = bindSurface(s.tets, s.surface);
  EXPECT_TRUE(b.isOk()) << b.message();
  if (b) s.binding = std::move(b).value();
  return s;
}

TEST(EmbedDeform, AffineMapIsReproducedExactly) {
  SphereInBox s = makeSphereInBox();
  // Add vertices outside the box: extrapolation is exact for affine maps too.
  s.surface.vertices.insert(s.surface.vertices.end(), {1.03, 0.5, 0.5, -0.02, -0.02, 1.01});
  auto b = bindSurface(s.tets, s.surface);
  ASSERT_TRUE(b.isOk()) << b.message();
  ASSERT_EQ(b->statistics.outsideCount, 2u);
  std::mt19937 rng(3);
  for (int trial = 0; trial < 3; ++trial) {
    const test::SmoothDeformation phi = test::SmoothDeformation::random(rng, 1.0, false);
    const std::vector<double> x = phi.apply(s.tets.nodes);
    std::vector<double> out(3 * b->vertexCount());
    SurfaceOutput o;
    o.positionsDouble = out.data();
    ASSERT_TRUE(deformSurface(*b, x.data(), s.tets.nodeCount(), o).isOk());
    for (std::size_t v = 0; v < b->vertexCount(); ++v)
      // Rounding only: coordinates O(1), about 30 flops.
      ASSERT_LT((point(out, v) - phi(point(s.surface.vertices, v))).norm(), 1e-13) << "vertex " << v;
  }
}

TEST(EmbedDeform, NonlinearMapIsInterpolatedPerElement) {
  SphereInBox s = makeSphereInBox();
  std::mt19937 rng(5);
  const test::SmoothDeformation phi = test::SmoothDeformation::random(rng, 1.0, true);
  const std::vector<double> x = phi.apply(s.tets.nodes);
  std::vector<double> out(3 * s.binding.vertexCount());
  SurfaceOutput o;
  o.positionsDouble = out.data();
  ASSERT_TRUE(deformSurface(s.binding, x.data(), s.tets.nodeCount(), o).isOk());
  double worst = 0;
  for (std::size_t v = 0; v < s.binding.vertexCount(); ++v) {
    // Independent evaluation: the exact barycentric coordinates in the bound element.
    std::array<std::uint32_t, 4> nodes;
    std::copy_n(&s.binding.nodes[4 * v], 4, nodes.begin());
    const auto w = test::exactBarycentric(s.tets.nodes, nodes, point(s.surface.vertices, v));
    ASSERT_LT((point(out, v) - test::interpolate(x, nodes, w)).norm(), 1e-13);
    worst = std::max(worst, (point(out, v) - phi(point(s.surface.vertices, v))).norm());
  }
  // Linear interpolation of a smooth map on elements of size 0.2: an O(h^2 |phi''|) error, not zero.
  EXPECT_GT(worst, 1e-4);
  EXPECT_LT(worst, 0.1);
}

TEST(EmbedDeform, SphereNormalsPointOutwardAndRotateWithTheMesh) {
  SphereInBox s = makeSphereInBox();
  const std::size_t n = s.binding.vertexCount();
  std::vector<float> normals(3 * n), positions(3 * n);
  SurfaceOutput o;
  o.normals = normals.data();
  o.positions = positions.data();
  ASSERT_TRUE(deformSurface(s.binding, s.tets.nodes.data(), s.tets.nodeCount(), o).isOk());
  for (std::size_t v = 0; v < n; ++v) {
    const Eigen::Vector3d radial = (point(s.surface.vertices, v) - Eigen::Vector3d(0.5, 0.5, 0.5)).normalized();
    const Eigen::Vector3d nv(normals[3 * v], normals[3 * v + 1], normals[3 * v + 2]);
    EXPECT_NEAR(nv.norm(), 1.0, 1e-6);  // float rounding
    // A 24 x 48 UV sphere: the area-weighted normal is within a few degrees of the radial direction.
    EXPECT_GT(nv.dot(radial), 0.995) << "vertex " << v;
  }
  // Rigid motion of the tet mesh: positions and normals move with it (float output: 1e-6).
  std::mt19937 rng(9);
  test::SmoothDeformation rigid = test::SmoothDeformation::random(rng, 1.0, false);
  rigid.A.setIdentity();
  const std::vector<double> x = rigid.apply(s.tets.nodes);
  std::vector<float> normals2(3 * n), positions2(3 * n);
  o.normals = normals2.data();
  o.positions = positions2.data();
  ASSERT_TRUE(deformSurface(s.binding, x.data(), s.tets.nodeCount(), o).isOk());
  for (std::size_t v = 0; v < n; ++v) {
    const Eigen::Vector3d n0(normals[3 * v], normals[3 * v + 1], normals[3 * v + 2]);
    const Eigen::Vector3d n1(normals2[3 * v], normals2[3 * v + 1], normals2[3 * v + 2]);
    EXPECT_LT((n1 - rigid.Q * n0).norm(), 2e-6) << "vertex " << v;
    const Eigen::Vector3d p1(positions2[3 * v], positions2[3 * v + 1], positions2[3 * v + 2]);
    EXPECT_LT((p1 - rigid(point(s.surface.vertices, v))).norm(), 4e-6) << "vertex " << v;
  }
}

TEST(EmbedDeform, FlatSquareNormalIsUpAndIsolatedVertexGetsZero) {
  TetMesh box = *generateBox(BoxSpec{});
  SurfaceMesh sq = test::pointCloud({0.2, 0.2, 0.5, 0.8, 0.2, 0.5, 0.8, 0.8, 0.5, 0.2, 0.8, 0.5, 0.5, 0.5, 0.5});
  sq.triangles = {0, 1, 2, 0, 2, 3};  // vertex 4 belongs to no triangle
  auto b = bindSurface(box, sq);
  ASSERT_TRUE(b.isOk()) << b.message();
  std::vector<float> vbo(6 * 5, -7.0f);
  SurfaceOutput o;
  o.interleaved = vbo.data();
  ASSERT_TRUE(deformSurface(*b, box.nodes.data(), box.nodeCount(), o).isOk());
  for (int v = 0; v < 4; ++v) {
    // Interpolated z = 0.5 carries rounding of 1e-16, which tilts the normal by as much.
    EXPECT_NEAR(vbo[6 * v + 3], 0.0f, 1e-12f);
    EXPECT_NEAR(vbo[6 * v + 4], 0.0f, 1e-12f);
    EXPECT_EQ(vbo[6 * v + 5], 1.0f);
    EXPECT_NEAR(vbo[6 * v + 2], 0.5f, 1e-7f);
  }
  EXPECT_EQ(vbo[6 * 4 + 3], 0.0f);
  EXPECT_EQ(vbo[6 * 4 + 4], 0.0f);
  EXPECT_EQ(vbo[6 * 4 + 5], 0.0f);
  EXPECT_NEAR(vbo[6 * 4 + 0], 0.5f, 1e-7f);
}

TEST(EmbedDeform, InterleavedAndSeparateStreamsAgreeBitwiseForAnyThreadCount) {
  SphereInBox s = makeSphereInBox(60, 120);  // 7082 vertices
  std::mt19937 rng(13);
  const std::vector<double> x = test::SmoothDeformation::random(rng, 1.0, true).apply(s.tets.nodes);
  const std::size_t n = s.binding.vertexCount();
  std::vector<float> vbo1(6 * n), vbo2(6 * n), pos(3 * n), nor(3 * n);
  std::vector<double> pd(3 * n);
  SurfaceOutput a;
  a.interleaved = vbo1.data();
  a.threads = 1;
  ASSERT_TRUE(deformSurface(s.binding, x.data(), s.tets.nodeCount(), a).isOk());
  SurfaceOutput b;
  b.interleaved = vbo2.data();
  b.positions = pos.data();
  b.normals = nor.data();
  b.positionsDouble = pd.data();
  b.threads = 3;
  ASSERT_TRUE(deformSurface(s.binding, x.data(), s.tets.nodeCount(), b).isOk());
  EXPECT_EQ(0, std::memcmp(vbo1.data(), vbo2.data(), vbo1.size() * sizeof(float)));
  for (std::size_t v = 0; v < n; ++v)
    for (int c = 0; c < 3; ++c) {
      ASSERT_EQ(vbo1[6 * v + c], pos[3 * v + c]);
      ASSERT_EQ(vbo1[6 * v + 3 + c], nor[3 * v + c]);
      ASSERT_EQ(pos[3 * v + c], static_cast<float>(pd[3 * v + c]));
    }
}

TEST(EmbedDeform, RejectsWrongNodeCountAndMissingOutputs) {
  SphereInBox s = makeSphereInBox(6, 8);
  std::vector<float> vbo(6 * s.binding.vertexCount());
  SurfaceOutput o;
  o.interleaved = vbo.data();
  Status wrong = deformSurface(s.binding, s.tets.nodes.data(), s.tets.nodeCount() - 1, o);
  EXPECT_EQ(wrong.code(), ErrorCode::BadInput);
  EXPECT_NE(wrong.message().find("215 node positions given"), std::string::npos) << wrong.message();
  EXPECT_NE(wrong.message().find("216 nodes"), std::string::npos) << wrong.message();
  Status none = deformSurface(s.binding, s.tets.nodes.data(), s.tets.nodeCount(), SurfaceOutput{});
  EXPECT_EQ(none.code(), ErrorCode::BadInput);
  EXPECT_NE(none.message().find("no buffer"), std::string::npos) << none.message();
  Status null = deformSurface(s.binding, nullptr, s.tets.nodeCount(), o);
  EXPECT_EQ(null.code(), ErrorCode::BadInput);
  EXPECT_NE(null.message().find("tetNodePositions is null"), std::string::npos) << null.message();
  // Nothing was written by the failed calls.
  for (float f : vbo) ASSERT_EQ(f, 0.0f);
}

}  // namespace
}  // namespace corofem
