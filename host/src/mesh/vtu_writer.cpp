// VTK XML UnstructuredGrid (.vtu) writer, ASCII data arrays: Float64 points, Int64 connectivity and
// offsets, UInt8 cell types (10 = tetra, 5 = triangle), point and cell data from MeshField.
#include "mesh/text_writer.hpp"

namespace corofem::mesh {
namespace {

constexpr std::uint32_t kVtkTetra = 10, kVtkTriangle = 5;

void beginArray(TextWriter& w, const char* type, const std::string& name, int components) {
  w << "        <DataArray type=\"" << type << '"';
  if (!name.empty()) w << " Name=\"" << xmlEscape(name) << '"';
  if (components > 1) w << " NumberOfComponents=\"" << std::int32_t(components) << '"';
  w << " format=\"ascii\">\n";
}

void endArray(TextWriter& w) { w << "\n        </DataArray>\n"; }

/// Values, several per line (ParaView does not care; people reading the file do).
template <class T>
void values(TextWriter& w, const std::vector<T>& v, std::size_t perLine) {
  for (std::size_t i = 0; i < v.size(); ++i) {
    w << (i == 0 ? "          " : (i % perLine == 0 ? "\n          " : " ")) << v[i];
  }
}

void dataSection(TextWriter& w, const char* tag, const std::vector<MeshField>& fields, bool perElement,
                 const std::vector<std::int32_t>* regions) {
  bool any = regions && !regions->empty();
  for (const MeshField& f : fields) any = any || f.perElement == perElement;
  if (!any) return;
  w << "      <" << tag << ">\n";
  if (regions && !regions->empty()) {
    beginArray(w, "Int32", "region", 1);
    values(w, *regions, 12);
    endArray(w);
  }
  for (const MeshField& f : fields) {
    if (f.perElement != perElement) continue;
    beginArray(w, "Float64", f.name, f.components);
    values(w, f.values, std::size_t(3 * f.components));
    endArray(w);
  }
  w << "      </" << tag << ">\n";
}

void writeGrid(const std::string& path, const std::vector<double>& points, const std::vector<std::uint32_t>& cells,
               std::size_t perCell, std::uint32_t cellType, const std::vector<MeshField>& fields,
               const std::vector<std::int32_t>* regions, const std::vector<float>* texcoords) {
  const std::size_t nPoints = points.size() / 3, nCells = cells.size() / perCell;
  TextWriter w;
  w.reserve(64 * nPoints + 40 * nCells + 1024);
  w << "<?xml version=\"1.0\"?>\n"
    << "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
    << "  <UnstructuredGrid>\n"
    << "    <Piece NumberOfPoints=\"" << std::uint64_t(nPoints) << "\" NumberOfCells=\"" << std::uint64_t(nCells)
    << "\">\n";
  if (texcoords && !texcoords->empty()) {
    w << "      <PointData TCoords=\"texcoords\">\n";
    beginArray(w, "Float32", "texcoords", 2);
    values(w, *texcoords, 6);
    endArray(w);
    w << "      </PointData>\n";
  } else {
    dataSection(w, "PointData", fields, false, nullptr);
  }
  dataSection(w, "CellData", fields, true, regions);
  w << "      <Points>\n";
  beginArray(w, "Float64", "Points", 3);
  values(w, points, 3);
  endArray(w);
  w << "      </Points>\n      <Cells>\n";
  beginArray(w, "Int64", "connectivity", 1);
  values(w, cells, perCell);
  endArray(w);
  beginArray(w, "Int64", "offsets", 1);
  std::vector<std::uint64_t> offsets(nCells);
  for (std::size_t c = 0; c < nCells; ++c) offsets[c] = perCell * (c + 1);
  values(w, offsets, 12);
  endArray(w);
  beginArray(w, "UInt8", "types", 1);
  values(w, std::vector<std::uint32_t>(nCells, cellType), 24);
  endArray(w);
  w << "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n";
  w.save(path);
}

}  // namespace

void writeVtu(const std::string& path, const TetMesh& mesh, const std::vector<MeshField>& fields) {
  writeGrid(path, mesh.nodes, mesh.tets, 4, kVtkTetra, fields, &mesh.regions, nullptr);
}

void writeVtuSurface(const std::string& path, const SurfaceMesh& mesh) {
  writeGrid(path, mesh.vertices, mesh.triangles, 3, kVtkTriangle, {}, nullptr, &mesh.texcoords);
}

}  // namespace corofem::mesh
