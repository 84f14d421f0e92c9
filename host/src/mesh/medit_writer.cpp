// Medit .mesh ASCII writer: Vertices (reference 0), Tetrahedra (1-based, reference = region or 0).
#include "mesh/text_writer.hpp"

namespace corofem::mesh {

void writeMedit(const std::string& path, const TetMesh& mesh) {
  const std::size_t n = mesh.nodeCount(), m = mesh.tetCount();
  TextWriter w;
  w.reserve(64 * n + 48 * m + 256);
  w << "MeshVersionFormatted 2\nDimension 3\nVertices\n" << std::uint64_t(n) << '\n';
  for (std::size_t i = 0; i < n; ++i)
    w << mesh.nodes[3 * i] << ' ' << mesh.nodes[3 * i + 1] << ' ' << mesh.nodes[3 * i + 2] << " 0\n";
  w << "Tetrahedra\n" << std::uint64_t(m) << '\n';
  for (std::size_t e = 0; e < m; ++e) {
    const std::uint32_t* t = &mesh.tets[4 * e];
    w << (t[0] + 1) << ' ' << (t[1] + 1) << ' ' << (t[2] + 1) << ' ' << (t[3] + 1) << ' '
      << (mesh.regions.empty() ? std::int32_t(0) : mesh.regions[e]) << '\n';
  }
  w << "End\n";
  w.save(path);
}

}  // namespace corofem::mesh
