// resolveNodeSet on a small in-memory lattice: one test per kind of node set, and the errors.
#include "common/test_data.hpp"

#include <corofem/scene.hpp>

#include <gtest/gtest.h>

#include <fstream>

namespace corofem {
namespace {

constexpr int kNx = 4, kNy = 3, kNz = 2;

/// Nodes at (0.1 i, 0.1 j, 0.1 k): 0.1 * 3 = 0.30000000000000004, so the x = 0.3 row sits just
/// off the round value, as coordinates read from files do. One tetrahedron keeps it a mesh.
TetMesh lattice() {
  TetMesh mesh;
  for (int k = 0; k < kNz; ++k)
    for (int j = 0; j < kNy; ++j)
      for (int i = 0; i < kNx; ++i) {
        mesh.nodes.push_back(0.1 * i);
        mesh.nodes.push_back(0.1 * j);
        mesh.nodes.push_back(0.1 * k);
      }
  mesh.tets = {0, 1, static_cast<std::uint32_t>(kNx), static_cast<std::uint32_t>(kNx * kNy)};
  return mesh;
}

std::uint32_t node(int i, int j, int k) { return static_cast<std::uint32_t>(i + kNx * (j + kNy * k)); }

NodeSetDesc box(Vec3 min, Vec3 max) {
  NodeSetDesc set;
  set.kind = NodeSetDesc::Kind::Box;
  set.boxMin = min;
  set.boxMax = max;
  return set;
}

NodeSetDesc plane(Vec3 point, Vec3 normal, double tolerance = 1e-9) {
  NodeSetDesc set;
  set.kind = NodeSetDesc::Kind::Plane;
  set.planePoint = point;
  set.planeNormal = normal;
  set.planeTolerance = tolerance;
  return set;
}

NodeSetDesc bou(const std::string& file) {
  NodeSetDesc set;
  set.kind = NodeSetDesc::Kind::BouFile;
  set.bouFile = file;
  return set;
}

std::vector<std::uint32_t> resolveOk(const NodeSetDesc& set, const std::string& baseDir = "") {
  auto r = resolveNodeSet(set, lattice(), baseDir);
  EXPECT_TRUE(r.isOk()) << r.message();
  return r.isOk() ? r.value() : std::vector<std::uint32_t>{};
}

std::string resolveError(const NodeSetDesc& set, ErrorCode code = ErrorCode::BadInput, const std::string& baseDir = "") {
  auto r = resolveNodeSet(set, lattice(), baseDir);
  EXPECT_FALSE(r.isOk()) << "expected an error";
  if (r.isOk()) return "";
  EXPECT_EQ(r.status().code(), code) << r.message();
  return r.message();
}

TEST(NodeSetBox, IsInclusiveDespiteRounding) {
  // The face x = 0.3 of the box lies on the last row, whose coordinate is 0.30000000000000004.
  const auto face = resolveOk(box({0.3, -1, -1}, {0.3, 1, 1}));
  std::vector<std::uint32_t> expected;
  for (int k = 0; k < kNz; ++k)
    for (int j = 0; j < kNy; ++j) expected.push_back(node(3, j, k));
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(face, expected);
}

TEST(NodeSetBox, SelectsExactlyTheNodesInside) {
  // x in [0, 0.1], y in [0.1, 0.2], z = 0: the slack (1e-9 of the diagonal) reaches no other row.
  const auto nodes = resolveOk(box({0, 0.1, 0}, {0.1, 0.2, 0}));
  EXPECT_EQ(nodes, (std::vector<std::uint32_t>{node(0, 1, 0), node(1, 1, 0), node(0, 2, 0), node(1, 2, 0)}));
}

TEST(NodeSetBox, EmptySelectionNamesTheSetAndTheBoundingBox) {
  EXPECT_EQ(resolveError(box({2, 2, 2}, {3, 3, 3})),
            "the box node set (min [2, 2, 2], max [3, 3, 3]) selects no nodes; the mesh's bounding box is "
            "[0, 0, 0] to [0.30000000000000004, 0.2, 0.1]. Fix the box's coordinates so that it contains some nodes");
}

TEST(NodeSetPlane, SelectsNodesOnAnObliquePlaneWithANonUnitNormal) {
  // x + y = 0.2: (0.2, 0), (0.1, 0.1), (0, 0.2) on both z layers. The normal (3, 3, 0) is not unit:
  // the distance divides by |n|.
  const auto nodes = resolveOk(plane({0.2, 0, 0}, {3, 3, 0}));
  std::vector<std::uint32_t> expected{node(2, 0, 0), node(1, 1, 0), node(0, 2, 0),
                                      node(2, 0, 1), node(1, 1, 1), node(0, 2, 1)};
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(nodes, expected);
}

TEST(NodeSetPlane, ToleranceIsADistance) {
  // The plane x = 0.05 lies 0.05 from the rows x = 0 and x = 0.1: a tolerance of 0.049 catches
  // neither, 0.051 both (and, being a distance along the unit normal, not x = 0.2).
  EXPECT_EQ(resolveOk(plane({0.05, 0, 0}, {-2, 0, 0}, 0.051)).size(), 2u * kNy * kNz);
  const std::string message = resolveError(plane({0.05, 0, 0}, {-2, 0, 0}, 0.049));
  EXPECT_NE(message.find("selects no nodes: the nearest node is 0.05"), std::string::npos) << message;
  EXPECT_NE(message.find("bounding box is [0, 0, 0] to [0.30000000000000004, 0.2, 0.1]"), std::string::npos) << message;
}

TEST(NodeSetPlane, ZeroNormalIsAnError) {
  EXPECT_EQ(resolveError(plane({0, 0, 0}, {0, 0, 0})),
            "the plane node set (point [0, 0, 0], normal [0, 0, 0], tolerance 1e-09): the normal must be a "
            "non-zero, finite vector");
}

TEST(NodeSetList, ReturnsSortedUniqueIndices) {
  NodeSetDesc set;
  set.kind = NodeSetDesc::Kind::List;
  set.indices = {5, 0, 5, 23};
  EXPECT_EQ(resolveOk(set), (std::vector<std::uint32_t>{0, 5, 23}));
}

TEST(NodeSetList, OutOfRangeIndexNamesTheIndexAndTheNodeCount) {
  NodeSetDesc set;
  set.kind = NodeSetDesc::Kind::List;
  set.indices = {0, 24};
  EXPECT_EQ(resolveError(set),
            "the list node set (2 indices): node index 24 is out of range: the mesh has 24 nodes (0-based indices 0 to 23)");
}

TEST(NodeSetBou, ReadsOneBasedIdsWithCommasSpacesAndComments) {
  const auto dir = test::tempDir();
  std::ofstream(dir / "fixed.bou") << "# fixed vertices\n1, 2,3\n\n  # another comment\n 24\t4,\n5 ,\n";
  // Relative to baseDir, as a scene file's paths are.
  EXPECT_EQ(resolveOk(bou("fixed.bou"), dir.string()), (std::vector<std::uint32_t>{0, 1, 2, 3, 4, 23}));
  // An absolute path ignores baseDir.
  EXPECT_EQ(resolveOk(bou((dir / "fixed.bou").string()), "/elsewhere").size(), 6u);
}

TEST(NodeSetBou, ErrorsNameTheFileAndLine) {
  const auto dir = test::tempDir();
  const std::string path = (dir / "bad.bou").string();
  std::ofstream(dir / "bad.bou") << "# ids\n1, 2,\n3, x7,\n";
  EXPECT_EQ(resolveError(bou(path)),
            "file " + path + ":3: \"x7\" is not a node id (a .bou file lists 1-based node ids separated by commas)");
  std::ofstream(dir / "zero.bou") << "0,1\n";
  EXPECT_EQ(resolveError(bou("zero.bou"), ErrorCode::BadInput, dir.string()),
            "file " + (dir / "zero.bou").string() + ":1: node id 0 is invalid: .bou node ids are 1-based");
  std::ofstream(dir / "big.bou") << "1\n2\n25\n";
  EXPECT_EQ(resolveError(bou("big.bou"), ErrorCode::BadInput, dir.string()),
            "file " + (dir / "big.bou").string() + ":3: node id 25 is out of range: the mesh has 24 nodes (1-based ids 1 to 24)");
  std::ofstream(dir / "empty.bou") << "# nothing\n";
  EXPECT_EQ(resolveError(bou("empty.bou"), ErrorCode::BadInput, dir.string()),
            "the .bou node set \"empty.bou\" selects no nodes (it lists none)");
}

TEST(NodeSetBou, MissingFileIsAnIoErrorNamingBothPaths) {
  const std::string message = resolveError(bou("nope.bou"), ErrorCode::IoError, "/nonexistent/scenes");
  EXPECT_EQ(message, "cannot open the .bou file \"/nonexistent/scenes/nope.bou\" (\"nope.bou\" relative to "
                     "\"/nonexistent/scenes\"): No such file or directory");
}

TEST(NodeSet, EmptyMeshIsAnError) {
  auto r = resolveNodeSet(box({0, 0, 0}, {1, 1, 1}), TetMesh{});
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::BadInput);
  EXPECT_NE(r.message().find("the mesh has no nodes"), std::string::npos) << r.message();
}

}  // namespace
}  // namespace corofem
