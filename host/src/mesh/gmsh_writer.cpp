// Gmsh 2.2 ASCII writer: nodes 1-based, elements "id 4 2 physical elementary a b c d". The region is
// written as both tags (physical 0 and elementary 1 when the mesh has no regions).
#include "mesh/text_writer.hpp"

namespace corofem::mesh {

void writeGmsh22(const std::string& path, const TetMesh& mesh) {
  const std::size_t n = mesh.nodeCount(), m = mesh.tetCount();
  TextWriter w;
  w.reserve(64 * n + 48 * m + 256);
  w << "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n" << std::uint64_t(n) << '\n';
  for (std::size_t i = 0; i < n; ++i)
    w << std::uint64_t(i + 1) << ' ' << mesh.nodes[3 * i] << ' ' << mesh.nodes[3 * i + 1] << ' '
      << mesh.nodes[3 * i + 2] << '\n';
  w << "$EndNodes\n$Elements\n" << std::uint64_t(m) << '\n';
  for (std::size_t e = 0; e < m; ++e) {
    const std::uint32_t* t = &mesh.tets[4 * e];
    const std::int32_t physical = mesh.regions.empty() ? 0 : mesh.regions[e];
    const std::int32_t elementary = mesh.regions.empty() ? 1 : mesh.regions[e];
    w << std::uint64_t(e + 1) << " 4 2 " << physical << ' ' << elementary << ' ' << (t[0] + 1) << ' ' << (t[1] + 1)
      << ' ' << (t[2] + 1) << ' ' << (t[3] + 1) << '\n';
  }
  w << "$EndElements\n";
  w.save(path);
}

}  // namespace corofem::mesh
