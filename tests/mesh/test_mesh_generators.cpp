// generateBox (5- and 6-tet splits): counts, exact volume, positive orientation, conformity (every
// interior face shared by exactly two tets, boundary faces = 2 per boundary cell face), the paper's
// Fig. 8 beam; bad specs. computeMeshInfo and signedVolume on hand-made tets.
#include "mesh/mesh_test_util.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

namespace {

using corofem::test::contains;

struct FaceCount {
  std::size_t interiorShared2 = 0, boundary = 0, other = 0;
};

/// Counts how many tets share each face (sorted node triple).
FaceCount countFaces(const corofem::TetMesh& mesh) {
  std::map<std::array<std::uint32_t, 3>, int> faces;
  static const int kFaces[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  for (std::size_t e = 0; e < mesh.tetCount(); ++e)
    for (const auto& f : kFaces) {
      std::array<std::uint32_t, 3> key = {mesh.tets[4 * e + f[0]], mesh.tets[4 * e + f[1]], mesh.tets[4 * e + f[2]]};
      std::sort(key.begin(), key.end());
      ++faces[key];
    }
  FaceCount c;
  for (const auto& [key, n] : faces) (n == 1 ? c.boundary : n == 2 ? c.interiorShared2 : c.other)++;
  return c;
}

class Box : public ::testing::TestWithParam<std::tuple<int, std::array<int, 3>>> {};

TEST_P(Box, CountsVolumeOrientationAndConformity) {
  const auto [tetsPerCell, cells] = GetParam();
  corofem::BoxSpec spec;
  spec.min = {-1.0, 0.5, 2.0};
  spec.max = {2.0, 1.25, 2.3};
  spec.cells = cells;
  spec.tetsPerCell = tetsPerCell;
  auto r = corofem::generateBox(spec);
  ASSERT_TRUE(r.isOk()) << r.message();
  const corofem::TetMesh& mesh = r.value();
  const std::size_t nx = cells[0], ny = cells[1], nz = cells[2];
  EXPECT_EQ(mesh.nodeCount(), (nx + 1) * (ny + 1) * (nz + 1));
  EXPECT_EQ(mesh.tetCount(), std::size_t(tetsPerCell) * nx * ny * nz);
  EXPECT_TRUE(mesh.regions.empty());

  double volume = 0;
  for (std::size_t e = 0; e < mesh.tetCount(); ++e) {
    const double v = corofem::signedVolume(mesh, e);
    ASSERT_GT(v, 0.0) << "element " << e;
    volume += v;
  }
  const double boxVolume = 3.0 * 0.75 * 0.3;
  EXPECT_NEAR(volume, boxVolume, 1e-12 * boxVolume);  // a sum of ~100 rounded products

  // Conforming: every face is either interior (exactly 2 tets) or on the box surface, and the
  // surface has 2 triangles per boundary cell face.
  const FaceCount faces = countFaces(mesh);
  EXPECT_EQ(faces.other, 0u);
  const std::size_t boundaryCellFaces = 2 * (nx * ny + ny * nz + nx * nz);
  EXPECT_EQ(faces.boundary, 2 * boundaryCellFaces);
  // Every face counted once per tet: 4 T = boundary + 2 interior.
  EXPECT_EQ(4 * mesh.tetCount(), faces.boundary + 2 * faces.interiorShared2);
  const corofem::MeshInfo info = corofem::computeMeshInfo(mesh);
  EXPECT_EQ(info.boundaryFaces, faces.boundary);
  EXPECT_EQ(info.unusedNodes, 0u);
  EXPECT_NEAR(info.volume, boxVolume, 1e-12 * boxVolume);
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(info.bboxMin[a], spec.min[a]);
    EXPECT_EQ(info.bboxMax[a], spec.max[a]);
  }
}

INSTANTIATE_TEST_SUITE_P(Splits, Box,
                         ::testing::Combine(::testing::Values(5, 6),
                                            ::testing::Values(std::array<int, 3>{1, 1, 1}, std::array<int, 3>{2, 3, 4},
                                                              std::array<int, 3>{5, 1, 2}, std::array<int, 3>{4, 4, 4})));

TEST(BoxGenerator, Figure8BeamHas40TetsAnd36Nodes) {
  corofem::BoxSpec spec;
  spec.max = {8.0, 1.0, 1.0};
  spec.cells = {8, 1, 1};
  spec.tetsPerCell = 5;
  auto r = corofem::generateBox(spec);
  ASSERT_TRUE(r.isOk()) << r.message();
  EXPECT_EQ(r.value().tetCount(), 40u);
  EXPECT_EQ(r.value().nodeCount(), 36u);
}

TEST(BoxGenerator, BadSpecsAreBadInput) {
  auto expectBad = [](const corofem::BoxSpec& spec, const std::string& needle) {
    auto r = corofem::generateBox(spec);
    ASSERT_FALSE(r.isOk());
    EXPECT_EQ(r.status().code(), corofem::ErrorCode::BadInput);
    EXPECT_TRUE(contains(r.message(), needle));
  };
  corofem::BoxSpec s;
  s.max[1] = s.min[1];
  expectBad(s, "max.y");
  s = {};
  s.max[0] = -1;
  expectBad(s, "max.x");
  s = {};
  s.cells[2] = 0;
  expectBad(s, "cells.z is 0");
  s = {};
  s.tetsPerCell = 4;
  expectBad(s, "tetsPerCell is 4");
  s = {};
  s.min[0] = std::nan("");
  expectBad(s, "finite");
}

TEST(MeshInfo, RegularTetHasAspectOneAndKnownVolume) {
  // Regular tet: alternate corners of a cube of side 1 (edge sqrt 2, volume 1/3).
  corofem::TetMesh mesh;
  mesh.nodes = {0, 0, 0, 1, 1, 0, 1, 0, 1, 0, 1, 1};
  mesh.tets = {0, 1, 2, 3};
  double v = corofem::signedVolume(mesh, 0);
  if (v < 0) std::swap(mesh.tets[2], mesh.tets[3]);
  EXPECT_NEAR(std::abs(v), 1.0 / 3.0, 1e-15);
  const corofem::MeshInfo info = corofem::computeMeshInfo(mesh);
  EXPECT_NEAR(info.minAspect, 1.0, 1e-12);
  EXPECT_NEAR(info.maxAspect, 1.0, 1e-12);
  EXPECT_EQ(info.boundaryFaces, 4u);
  EXPECT_EQ(info.negativeElements, 0u);
  EXPECT_NEAR(info.volume, 1.0 / 3.0, 1e-15);
}

TEST(MeshInfo, NegativeElementsUnusedNodesAndSlivers) {
  corofem::TetMesh mesh;
  // Unit right tet (positive), the same tet with two nodes swapped (negative), and an unused node.
  mesh.nodes = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1, 5, 5, 5};
  mesh.tets = {0, 1, 2, 3, 0, 2, 1, 4};
  EXPECT_NEAR(corofem::signedVolume(mesh, 0), 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(corofem::signedVolume(mesh, 1), 1.0 / 6.0, 1e-15);  // below the plane, nodes swapped: positive
  mesh.tets = {0, 1, 2, 3, 0, 1, 2, 4};
  EXPECT_NEAR(corofem::signedVolume(mesh, 1), -1.0 / 6.0, 1e-15);
  const corofem::MeshInfo info = corofem::computeMeshInfo(mesh);
  EXPECT_EQ(info.nodes, 6u);
  EXPECT_EQ(info.tets, 2u);
  EXPECT_EQ(info.negativeElements, 1u);
  EXPECT_EQ(info.unusedNodes, 1u);
  EXPECT_EQ(info.boundaryFaces, 6u);  // the shared face (0, 1, 2) is interior
  EXPECT_NEAR(info.minVolume, -1.0 / 6.0, 1e-15);
  EXPECT_NEAR(info.maxVolume, 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(info.volume, 2.0 / 6.0, 1e-15);
  // The right tet: longest edge sqrt 2, inradius 1 / (3 + sqrt 3).
  const double aspect = std::sqrt(2.0) * (3.0 + std::sqrt(3.0)) / (2.0 * std::sqrt(6.0));
  EXPECT_NEAR(info.maxAspect, aspect, 1e-12);
  EXPECT_EQ(info.bboxMax[0], 5.0);
  EXPECT_EQ(info.bboxMin[2], -1.0);
}

}  // namespace
