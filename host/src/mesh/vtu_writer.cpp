// VTK XML UnstructuredGrid (.vtu) writer: Float64 points, Int64 connectivity and offsets, UInt8 cell
// types (10 = tetra, 5 = triangle), point and cell data from MeshField, a surface's texcoords and
// normals (Float32). Arrays as text, inline base64 or one appended raw section, optionally zlib
// compressed (mesh/vtu_encoding.hpp has the binary layout).
#include "mesh/text_writer.hpp"
#include "mesh/vtu_encoding.hpp"

namespace corofem::mesh {
namespace {

constexpr std::uint32_t kVtkTetra = 10, kVtkTriangle = 5;

/// Values, several per line (ParaView does not care; people reading the file do).
template <class T>
void values(TextWriter& w, const std::vector<T>& v, std::size_t perLine) {
  for (std::size_t i = 0; i < v.size(); ++i) {
    w << (i == 0 ? "          " : (i % perLine == 0 ? "\n          " : " ")) << v[i];
  }
}

/// Writes DataArray elements in the chosen format; the raw bytes of the appended format collect
/// here and follow the XML (appendedSection).
class ArrayWriter {
 public:
  ArrayWriter(TextWriter& w, const VtuOptions& options, const std::string& path)
      : w_(w), options_(options), path_(path) {}

  /// One array of VTK type `type` whose values are stored as Out (its C++ counterpart).
  template <class Out, class In>
  void write(const char* type, const std::string& name, int components, const std::vector<In>& v,
             std::size_t perLine) {
    w_ << "        <DataArray type=\"" << type << "\" Name=\"" << xmlEscape(name) << '"';
    if (components > 1) w_ << " NumberOfComponents=\"" << std::int32_t(components) << '"';
    if (options_.format == VtuFormat::Ascii) {
      w_ << " format=\"ascii\">\n";
      values(w_, v, perLine);
      w_ << "\n        </DataArray>\n";
      return;
    }
    const VtuPayload p = encodeVtuArray(littleEndianBytes<Out>(v), options_.compression, path_);
    if (options_.format == VtuFormat::Raw) {
      w_ << " format=\"appended\" offset=\"" << std::uint64_t(appended_.size()) << "\"/>\n";
      appended_ += p.header;
      appended_ += p.data;
      return;
    }
    // Inline base64: uncompressed, header and data are one base64 stream; compressed, the header is
    // encoded on its own, then the blocks (what VTK writes and reads).
    w_ << " format=\"binary\">\n          ";
    if (options_.compression == VtuCompression::None) {
      w_ << base64(p.header + p.data);
    } else {
      w_ << base64(p.header) << base64(p.data);
    }
    w_ << "\n        </DataArray>\n";
  }

  /// The appended section (raw format only), after </UnstructuredGrid>.
  void appendedSection() {
    if (options_.format != VtuFormat::Raw) return;
    w_ << "  <AppendedData encoding=\"raw\">\n   _";
    w_ << std::string_view(appended_);
    w_ << "\n  </AppendedData>\n";
  }

 private:
  TextWriter& w_;
  const VtuOptions& options_;
  const std::string& path_;
  std::string appended_;
};

void dataSection(ArrayWriter& a, TextWriter& w, const char* tag, const std::vector<MeshField>& fields,
                 bool perElement, const std::vector<std::int32_t>* regions) {
  bool any = regions && !regions->empty();
  for (const MeshField& f : fields) any = any || f.perElement == perElement;
  if (!any) return;
  w << "      <" << tag << ">\n";
  if (regions && !regions->empty()) a.write<std::int32_t>("Int32", "region", 1, *regions, 12);
  for (const MeshField& f : fields)
    if (f.perElement == perElement) a.write<double>("Float64", f.name, f.components, f.values, std::size_t(3 * f.components));
  w << "      </" << tag << ">\n";
}

/// The point data of a surface: texture coordinates and normals, each marked as the active one.
void surfaceData(ArrayWriter& a, TextWriter& w, const std::vector<float>& texcoords, const std::vector<float>& normals) {
  if (texcoords.empty() && normals.empty()) return;
  w << "      <PointData";
  if (!normals.empty()) w << " Normals=\"Normals\"";
  if (!texcoords.empty()) w << " TCoords=\"texcoords\"";
  w << ">\n";
  if (!texcoords.empty()) a.write<float>("Float32", "texcoords", 2, texcoords, 6);
  if (!normals.empty()) a.write<float>("Float32", "Normals", 3, normals, 3);
  w << "      </PointData>\n";
}

struct Grid {
  const std::vector<double>& points;
  const std::vector<std::uint32_t>& cells;
  std::size_t perCell;
  std::uint32_t cellType;
  const std::vector<MeshField>& fields;
  const std::vector<std::int32_t>* regions;  ///< tet meshes
  const SurfaceMesh* surface;                ///< surfaces: texcoords and normals
};

void writeGrid(const std::string& path, const Grid& g, const VtuOptions& options) {
  checkVtuOptions(options, path);
  const std::size_t nPoints = g.points.size() / 3, nCells = g.cells.size() / g.perCell;
  TextWriter w;
  w.reserve((options.format == VtuFormat::Ascii ? 64 : 40) * nPoints + 40 * nCells + 1024);
  w << "<?xml version=\"1.0\"?>\n"
    << "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\"";
  if (options.format != VtuFormat::Ascii && options.compression == VtuCompression::Zlib)
    w << " compressor=\"vtkZLibDataCompressor\"";
  w << ">\n"
    << "  <UnstructuredGrid>\n"
    << "    <Piece NumberOfPoints=\"" << std::uint64_t(nPoints) << "\" NumberOfCells=\"" << std::uint64_t(nCells)
    << "\">\n";
  ArrayWriter a(w, options, path);
  if (g.surface) {
    surfaceData(a, w, g.surface->texcoords, g.surface->normals);
  } else {
    dataSection(a, w, "PointData", g.fields, false, nullptr);
  }
  dataSection(a, w, "CellData", g.fields, true, g.regions);
  w << "      <Points>\n";
  a.write<double>("Float64", "Points", 3, g.points, 3);
  w << "      </Points>\n      <Cells>\n";
  a.write<std::int64_t>("Int64", "connectivity", 1, g.cells, g.perCell);
  std::vector<std::uint64_t> offsets(nCells);
  for (std::size_t c = 0; c < nCells; ++c) offsets[c] = g.perCell * (c + 1);
  a.write<std::int64_t>("Int64", "offsets", 1, offsets, 12);
  a.write<std::uint8_t>("UInt8", "types", 1, std::vector<std::uint32_t>(nCells, g.cellType), 24);
  w << "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n";
  a.appendedSection();
  w << "</VTKFile>\n";
  w.save(path);
}

}  // namespace

void writeVtu(const std::string& path, const TetMesh& mesh, const std::vector<MeshField>& fields,
              const VtuOptions& options) {
  writeGrid(path, Grid{mesh.nodes, mesh.tets, 4, kVtkTetra, fields, &mesh.regions, nullptr}, options);
}

void writeVtuSurface(const std::string& path, const SurfaceMesh& mesh, const VtuOptions& options) {
  static const std::vector<MeshField> kNoFields;
  writeGrid(path, Grid{mesh.vertices, mesh.triangles, 3, kVtkTriangle, kNoFields, nullptr, &mesh}, options);
}

}  // namespace corofem::mesh
