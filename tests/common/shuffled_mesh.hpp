// A tet mesh with its nodes and elements numbered at random: as far as memory locality goes, what
// Gmsh and TetGen files give (the OpenCL backend's locality order, mesh/locality_order.hpp).
#pragma once

#include <corofem/mesh.hpp>

#include <numeric>
#include <random>
#include <vector>

namespace corofem::test {

inline TetMesh shuffledMesh(const TetMesh& m, unsigned seed) {
  std::vector<std::uint32_t> nodeOf(m.nodeCount()), elements(m.tetCount());
  std::iota(nodeOf.begin(), nodeOf.end(), 0u);
  std::iota(elements.begin(), elements.end(), 0u);
  std::mt19937 rng(seed);
  std::shuffle(nodeOf.begin(), nodeOf.end(), rng);
  std::shuffle(elements.begin(), elements.end(), rng);
  TetMesh r = m;
  for (std::size_t n = 0; n < m.nodeCount(); ++n)
    for (int k = 0; k < 3; ++k) r.nodes[3 * nodeOf[n] + k] = m.nodes[3 * n + k];
  for (std::size_t e = 0; e < m.tetCount(); ++e)
    for (int k = 0; k < 4; ++k) r.tets[4 * e + k] = nodeOf[m.tets[4 * elements[e] + k]];
  if (!m.regions.empty())
    for (std::size_t e = 0; e < m.tetCount(); ++e) r.regions[e] = m.regions[elements[e]];
  return r;
}

}  // namespace corofem::test
