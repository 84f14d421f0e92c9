// mesh/locality_order: the Morton numbering the OpenCL backend gives its kernels (a permutation of
// elements and nodes, elements along the curve, nodes by first use), and the rule that takes it
// only where it is more local than the mesh's own numbering: the box generator's layered numbering
// is kept, a shuffled box and the Gmsh meshes of ../shared/data are reordered. The device side:
// tests/opencl/test_backend.cpp (LocalityOrderChangesNothingTheHostSees) and the suites CTest runs
// again with the order forced (tests/CMakeLists.txt).
#include "mesh/mesh_test_util.hpp"

#include "common/shuffled_mesh.hpp"
#include "common/test_data.hpp"
#include "mesh/locality_order.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

namespace {

using namespace corofem;

TetMesh box(int nx, int ny, int nz) {
  BoxSpec spec;
  spec.max = {0.1 * nx, 0.1 * ny, 0.1 * nz};
  spec.cells = {nx, ny, nz};
  spec.tetsPerCell = 6;
  return generateBox(spec).value();
}

TetMesh shuffled(const TetMesh& m, unsigned seed) { return test::shuffledMesh(m, seed); }

/// The box the Morton codes quantise: the mesh's bounds and their largest extent.
struct MortonBox {
  double lo[3], hi[3], extent;
  explicit MortonBox(const TetMesh& m) {
    for (int k = 0; k < 3; ++k) lo[k] = hi[k] = m.nodes[k];
    for (std::size_t n = 0; n < m.nodeCount(); ++n)
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], m.nodes[3 * n + k]);
        hi[k] = std::max(hi[k], m.nodes[3 * n + k]);
      }
    extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  }
};

/// The Morton code of element e's centroid, bit by bit (the library spreads bits with masks).
std::uint64_t naiveMorton(const TetMesh& m, const MortonBox& box, std::size_t e) {
  std::uint64_t code = 0;
  for (int k = 0; k < 3; ++k) {
    double c = 0.0;
    for (int j = 0; j < 4; ++j) c += m.nodes[3 * m.tets[4 * e + j] + k];
    const auto q = static_cast<std::uint64_t>(
        std::clamp((0.25 * c - box.lo[k]) * (2097151.0 / box.extent), 0.0, 2097151.0));
    for (int bit = 0; bit < 21; ++bit) code |= ((q >> bit) & 1u) << (3 * bit + k);
  }
  return code;
}

void expectValidOrder(const TetMesh& m, const detail::LocalityOrder& o) {
  ASSERT_EQ(o.elements.size(), m.tetCount());
  ASSERT_EQ(o.nodes.size(), m.nodeCount());
  ASSERT_EQ(o.nodeOf.size(), m.nodeCount());
  std::vector<std::uint32_t> sorted = o.elements;
  std::sort(sorted.begin(), sorted.end());
  for (std::size_t i = 0; i < sorted.size(); ++i) ASSERT_EQ(sorted[i], i) << "elements: not a permutation";
  for (std::size_t i = 0; i < o.nodes.size(); ++i) ASSERT_EQ(o.nodeOf[o.nodes[i]], i) << "nodeOf does not invert nodes";
  // Elements along the curve; nodes numbered by first use in that order.
  const MortonBox box(m);
  std::uint32_t nextNew = 0;
  for (std::size_t i = 0; i < o.elements.size(); ++i) {
    if (i > 0) {
      EXPECT_LE(naiveMorton(m, box, o.elements[i - 1]), naiveMorton(m, box, o.elements[i])) << "element " << i;
    }
    for (int k = 0; k < 4; ++k) {
      const std::uint32_t n = o.nodeOf[m.tets[4 * o.elements[i] + k]];
      ASSERT_LE(n, nextNew) << "a node numbered before its first element";
      if (n == nextNew) ++nextNew;
    }
  }
}

TEST(LocalityOrder, MortonOrderIsAPermutationAlongTheCurveWithNodesByFirstUse) {
  const TetMesh m = shuffled(box(7, 4, 3), 5);
  const detail::LocalityOrder o = detail::mortonOrder(m);
  expectValidOrder(m, o);
  const detail::LocalityOrder again = detail::mortonOrder(m);
  EXPECT_EQ(o.elements, again.elements);
  EXPECT_EQ(o.nodes, again.nodes);
}

TEST(LocalityOrder, TheBoxGeneratorsNumberingIsKeptAShuffledOneIsReordered) {
  for (auto cells : {std::array<int, 3>{20, 9, 9}, std::array<int, 3>{5, 5, 5}, std::array<int, 3>{30, 2, 2}}) {
    const TetMesh layered = box(cells[0], cells[1], cells[2]);
    EXPECT_FALSE(detail::localityOrder(layered)) << cells[0] << "x" << cells[1] << "x" << cells[2];
    const TetMesh scattered = shuffled(layered, 9);
    const auto order = detail::localityOrder(scattered);
    ASSERT_TRUE(order);
    expectValidOrder(scattered, *order);
    EXPECT_LT(detail::meanNodeJump(scattered.tets, &order->elements, &order->nodeOf),
              0.35 * detail::meanNodeJump(scattered.tets));
  }
  TetMesh one = box(1, 1, 1);
  one.tets.resize(4);
  EXPECT_FALSE(detail::localityOrder(one)) << "a single element has no order to improve";
}

TEST(LocalityOrder, NonFiniteCoordinatesStillGiveAPermutation) {
  // buildProblem rejects them; a Problem made directly may hold them: their elements take key 0.
  TetMesh m = shuffled(box(4, 3, 2), 3);
  m.nodes[0] = std::nan("");
  m.nodes[3 * 5 + 1] = HUGE_VAL;
  const detail::LocalityOrder o = detail::mortonOrder(m);
  ASSERT_EQ(o.elements.size(), m.tetCount());
  std::vector<std::uint32_t> sorted = o.elements;
  std::sort(sorted.begin(), sorted.end());
  for (std::size_t i = 0; i < sorted.size(); ++i) ASSERT_EQ(sorted[i], i);
  for (std::size_t i = 0; i < o.nodes.size(); ++i) ASSERT_EQ(o.nodeOf[o.nodes[i]], i);
  // Their elements take key 0, so they lead the order (a NaN cast to an integer would not).
  auto touches = [&](std::uint32_t e) {
    for (int k = 0; k < 4; ++k)
      if (m.tets[4 * e + k] == 0 || m.tets[4 * e + k] == 5) return true;
    return false;
  };
  std::size_t first = 0;
  while (first < o.elements.size() && touches(o.elements[first])) ++first;
  ASSERT_GT(first, 0u);
  for (std::size_t i = first; i < o.elements.size(); ++i) EXPECT_FALSE(touches(o.elements[i])) << "position " << i;
}

TEST(LocalityOrder, GmshMeshesFromFilesAreReordered) {
  for (const char* file : {"meshes/ipc/Armadillo13K.msh", "meshes/ipc/dolphin5K.msh", "meshes/sfepy/wheelset.vtk"}) {
    COROFEM_REQUIRE_DATA(file);
    const TetMesh m = test::loadTet(test::dataPath(file));
    const auto order = detail::localityOrder(m);
    ASSERT_TRUE(order) << file;
    expectValidOrder(m, *order);
    // Measured: 3,733 -> 227 (Armadillo), 2,110 -> 153 (dolphin), 519 -> 108 (wheelset).
    EXPECT_LT(detail::meanNodeJump(m.tets, &order->elements, &order->nodeOf), 0.3 * detail::meanNodeJump(m.tets))
        << file;
  }
}

}  // namespace
