// Wavefront OBJ writer: v, vt and vn (one of each per vertex, when the surface has texcoords or
// normals), f (1-based; corners v, v/vt, v//vn or v/vt/vn, the same index for each).
#include "mesh/text_writer.hpp"

namespace corofem::mesh {

void writeObj(const std::string& path, const SurfaceMesh& mesh) {
  const std::size_t n = mesh.vertexCount(), m = mesh.triangleCount();
  const bool uv = !mesh.texcoords.empty(), normals = !mesh.normals.empty();
  TextWriter w;
  w.reserve(64 * n + (normals ? 40 * n : 0) + 40 * m + 64);
  w << "# written by corofem: " << std::uint64_t(n) << " vertices, " << std::uint64_t(m) << " triangles\n";
  for (std::size_t i = 0; i < n; ++i)
    w << "v " << mesh.vertices[3 * i] << ' ' << mesh.vertices[3 * i + 1] << ' ' << mesh.vertices[3 * i + 2] << '\n';
  if (uv)
    for (std::size_t i = 0; i < n; ++i) w << "vt " << mesh.texcoords[2 * i] << ' ' << mesh.texcoords[2 * i + 1] << '\n';
  if (normals)
    for (std::size_t i = 0; i < n; ++i)
      w << "vn " << mesh.normals[3 * i] << ' ' << mesh.normals[3 * i + 1] << ' ' << mesh.normals[3 * i + 2] << '\n';
  for (std::size_t t = 0; t < m; ++t) {
    w << 'f';
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = mesh.triangles[3 * t + k] + 1;
      w << ' ' << v;
      if (uv || normals) w << '/';
      if (uv) w << v;
      if (normals) w << '/' << v;
    }
    w << '\n';
  }
  w.save(path);
}

}  // namespace corofem::mesh
