// Legacy VTK 2.0 ASCII writers: UNSTRUCTURED_GRID for tet meshes (regions and fields as CELL_DATA /
// POINT_DATA), POLYDATA for surfaces. Readable by parseVtkLegacy (regions come back from "region").
#include "mesh/text_writer.hpp"

namespace corofem::mesh {
namespace {

/// Legacy VTK names cannot hold blanks.
std::string legacyName(const std::string& name) {
  std::string r = name;
  for (char& c : r)
    if (c == ' ' || c == '\t' || c == '\n') c = '_';
  return r;
}

void fieldData(TextWriter& w, const std::vector<MeshField>& fields, bool perElement) {
  for (const MeshField& f : fields) {
    if (f.perElement != perElement) continue;
    if (f.components == 3) {
      w << "VECTORS " << legacyName(f.name) << " double\n";
    } else {
      w << "SCALARS " << legacyName(f.name) << " double " << std::int32_t(f.components) << "\nLOOKUP_TABLE default\n";
    }
    for (std::size_t i = 0; i < f.values.size(); ++i)
      w << f.values[i] << ((i + 1) % std::size_t(f.components) == 0 ? '\n' : ' ');
  }
}

void points(TextWriter& w, const std::vector<double>& xyz) {
  w << "POINTS " << std::uint64_t(xyz.size() / 3) << " double\n";
  for (std::size_t i = 0; i < xyz.size(); i += 3) w << xyz[i] << ' ' << xyz[i + 1] << ' ' << xyz[i + 2] << '\n';
}

}  // namespace

void writeVtkLegacy(const std::string& path, const TetMesh& mesh, const std::vector<MeshField>& fields) {
  const std::size_t n = mesh.nodeCount(), m = mesh.tetCount();
  TextWriter w;
  w.reserve(64 * n + 48 * m + 256);
  w << "# vtk DataFile Version 2.0\ncorofem tetrahedral mesh\nASCII\nDATASET UNSTRUCTURED_GRID\n";
  points(w, mesh.nodes);
  w << "CELLS " << std::uint64_t(m) << ' ' << std::uint64_t(5 * m) << '\n';
  for (std::size_t e = 0; e < m; ++e) {
    const std::uint32_t* t = &mesh.tets[4 * e];
    w << "4 " << t[0] << ' ' << t[1] << ' ' << t[2] << ' ' << t[3] << '\n';
  }
  w << "CELL_TYPES " << std::uint64_t(m) << '\n';
  for (std::size_t e = 0; e < m; ++e) w << "10\n";
  bool cellData = !mesh.regions.empty();
  bool pointData = false;
  for (const MeshField& f : fields) (f.perElement ? cellData : pointData) = true;
  if (cellData) {
    w << "CELL_DATA " << std::uint64_t(m) << '\n';
    if (!mesh.regions.empty()) {
      w << "SCALARS region int 1\nLOOKUP_TABLE default\n";
      for (std::int32_t r : mesh.regions) w << r << '\n';
    }
    fieldData(w, fields, true);
  }
  if (pointData) {
    w << "POINT_DATA " << std::uint64_t(n) << '\n';
    fieldData(w, fields, false);
  }
  w.save(path);
}

void writeVtkPolyData(const std::string& path, const SurfaceMesh& mesh) {
  const std::size_t n = mesh.vertexCount(), m = mesh.triangleCount();
  TextWriter w;
  w.reserve(64 * n + 40 * m + 256);
  w << "# vtk DataFile Version 2.0\ncorofem surface mesh\nASCII\nDATASET POLYDATA\n";
  points(w, mesh.vertices);
  w << "POLYGONS " << std::uint64_t(m) << ' ' << std::uint64_t(4 * m) << '\n';
  for (std::size_t t = 0; t < m; ++t) {
    const std::uint32_t* v = &mesh.triangles[3 * t];
    w << "3 " << v[0] << ' ' << v[1] << ' ' << v[2] << '\n';
  }
  if (!mesh.texcoords.empty()) {
    w << "POINT_DATA " << std::uint64_t(n) << "\nTEXTURE_COORDINATES texcoords 2 float\n";
    for (std::size_t i = 0; i < mesh.texcoords.size(); i += 2)
      w << mesh.texcoords[i] << ' ' << mesh.texcoords[i + 1] << '\n';
  }
  w.save(path);
}

}  // namespace corofem::mesh
