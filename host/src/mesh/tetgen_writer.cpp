// TetGen .node/.ele writer, 1-based; the region, when the mesh has regions, is the one element
// attribute.
#include "mesh/text_writer.hpp"

namespace corofem::mesh {

void writeTetGen(const std::string& nodePath, const std::string& elePath, const TetMesh& mesh) {
  const std::size_t n = mesh.nodeCount(), m = mesh.tetCount();
  TextWriter node;
  node.reserve(64 * n + 64);
  node << std::uint64_t(n) << " 3 0 0\n";
  for (std::size_t i = 0; i < n; ++i)
    node << std::uint64_t(i + 1) << ' ' << mesh.nodes[3 * i] << ' ' << mesh.nodes[3 * i + 1] << ' '
         << mesh.nodes[3 * i + 2] << '\n';
  node << "# written by corofem\n";
  TextWriter ele;
  ele.reserve(48 * m + 64);
  const bool regions = !mesh.regions.empty();
  ele << std::uint64_t(m) << " 4 " << (regions ? "1" : "0") << '\n';
  for (std::size_t e = 0; e < m; ++e) {
    const std::uint32_t* t = &mesh.tets[4 * e];
    ele << std::uint64_t(e + 1) << ' ' << (t[0] + 1) << ' ' << (t[1] + 1) << ' ' << (t[2] + 1) << ' ' << (t[3] + 1);
    if (regions) ele << ' ' << mesh.regions[e];
    ele << '\n';
  }
  ele << "# written by corofem\n";
  node.save(nodePath);
  ele.save(elePath);
}

}  // namespace corofem::mesh
