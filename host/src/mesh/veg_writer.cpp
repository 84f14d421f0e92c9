// Vega .veg writer: *VERTICES and *ELEMENTS TET, 1-based. No *MATERIAL is written: corofem keeps
// materials in the scene, and inventing one here would mislead.
#include "mesh/text_writer.hpp"

namespace corofem::mesh {

void writeVeg(const std::string& path, const TetMesh& mesh) {
  const std::size_t n = mesh.nodeCount(), m = mesh.tetCount();
  TextWriter w;
  w.reserve(64 * n + 48 * m + 256);
  w << "# Vega mesh file.\n# " << std::uint64_t(n) << " vertices, " << std::uint64_t(m)
    << " elements (written by corofem)\n\n*VERTICES\n" << std::uint64_t(n) << " 3 0 0\n";
  for (std::size_t i = 0; i < n; ++i)
    w << std::uint64_t(i + 1) << ' ' << mesh.nodes[3 * i] << ' ' << mesh.nodes[3 * i + 1] << ' '
      << mesh.nodes[3 * i + 2] << '\n';
  w << "\n*ELEMENTS\nTET\n" << std::uint64_t(m) << " 4 0\n";
  for (std::size_t e = 0; e < m; ++e) {
    const std::uint32_t* t = &mesh.tets[4 * e];
    w << std::uint64_t(e + 1) << ' ' << (t[0] + 1) << ' ' << (t[1] + 1) << ' ' << (t[2] + 1) << ' ' << (t[3] + 1)
      << '\n';
  }
  w.save(path);
}

}  // namespace corofem::mesh
