// VTK legacy ASCII UNSTRUCTURED_GRID reader. Versions up to 4.2 store "CELLS n size" as n records
// "k i1 .. ik"; version 5.1 stores "CELLS nOffsets nConnectivity" followed by OFFSETS and CONNECTIVITY
// arrays. Cells of type 10 (VTK_TETRA) are kept, others skipped and counted. POINT_DATA, CELL_DATA,
// FIELD and METADATA sections are skipped, except a one-component cell array named like mat_id or
// region, which becomes the element regions.
#include "mesh/readers.hpp"
#include "mesh/text_scanner.hpp"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace corofem::mesh {
namespace {

constexpr std::int64_t kVtkTetraCell = 10;

std::string lower(std::string_view s) {
  std::string r(s);
  for (char& c : r) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return r;
}

bool isRegionArrayName(std::string_view name) {
  const std::string n = lower(name);
  for (const char* s : {"mat_id", "material", "materials", "material_id", "materialid", "region", "regions",
                        "region_id", "cellentityids", "gmsh:physical", "medit:ref", "tetgen:ref"})
    if (n == s) return true;
  return false;
}

std::string vtkCellTypeName(std::int64_t type) {
  const char* name = "cell";
  switch (type) {
    case 1: name = "vertex"; break;
    case 3: name = "line"; break;
    case 5: name = "triangle"; break;
    case 7: name = "polygon"; break;
    case 9: name = "quad"; break;
    case 10: name = "tetra"; break;
    case 12: name = "hexahedron"; break;
    case 13: name = "wedge"; break;
    case 14: name = "pyramid"; break;
    case 24: name = "quadratic tetra"; break;
    default: break;
  }
  return std::string(name) + " (vtk cell type " + std::to_string(type) + ")";
}

class VtkParser {
 public:
  VtkParser(const std::string& text, const std::string& path, MeshReadReport& report)
      : sc_(text, path), report_(report) {}

  ParsedTetMesh run() {
    readHeader();
    while (!sc_.atEnd()) {
      sc_.setContext(nullptr);
      const std::string key = lower(sc_.token());
      if (key == "dataset") {
        const std::string type = lower(sc_.token());
        if (type != "unstructured_grid")
          sc_.fail("DATASET ", detail::shorten(type), " is not supported; corofem reads UNSTRUCTURED_GRID tetrahedral meshes");
      } else if (key == "points") {
        readPoints();
      } else if (key == "cells") {
        if (version_ >= 5) readCellsV5(); else readCellsV2();
      } else if (key == "cell_types") {
        readCellTypes();
      } else if (key == "point_data") {
        scopeCount_ = sc_.readCount("point data values", 2);
        cellScope_ = false;
      } else if (key == "cell_data") {
        scopeCount_ = sc_.readCount("cell data values", 2);
        cellScope_ = true;
      } else if (key == "scalars") {
        readScalars();
      } else if (key == "color_scalars") {
        sc_.token();
        skipValues(scopeCount_ * std::size_t(sc_.readInt()), "COLOR_SCALARS values");
      } else if (key == "vectors" || key == "normals") {
        sc_.token();
        sc_.token();
        skipValues(3 * scopeCount_, "vector values");
      } else if (key == "tensors") {
        sc_.token();
        sc_.token();
        skipValues(9 * scopeCount_, "tensor values");
      } else if (key == "tensors6") {
        sc_.token();
        sc_.token();
        skipValues(6 * scopeCount_, "tensor values");
      } else if (key == "texture_coordinates") {
        sc_.token();
        const std::int64_t dim = sc_.readInt();
        sc_.token();
        skipValues(scopeCount_ * std::size_t(dim > 0 ? dim : 0), "texture coordinates");
      } else if (key == "lookup_table") {
        sc_.token();
        skipValues(4 * sc_.readCount("lookup table entries", 8), "lookup table values");
      } else if (key == "field") {
        readField();
      } else if (key == "metadata") {
        skipMetadata();
      } else {
        sc_.fail("unexpected '", detail::shorten(key), "' in a VTK UNSTRUCTURED_GRID file; expected a keyword such as POINTS, CELLS, "
                 "CELL_TYPES or CELL_DATA");
      }
    }
    return assemble();
  }

 private:
  void readHeader() {
    sc_.setContext("the VTK header");
    const std::string_view first = sc_.restOfLine();
    const std::string_view magic = "# vtk DataFile Version";
    if (first.substr(0, magic.size()) != magic)
      sc_.fail("the first line is not '# vtk DataFile Version x.y'; is this a legacy VTK file?");
    const std::string versionText(first.substr(magic.size()));
    version_ = std::atof(versionText.c_str());
    sc_.restOfLine();  // title
    const std::string encoding = lower(sc_.token());
    if (encoding == "binary")
      sc_.fail("binary legacy VTK files are not supported; write the file as ASCII");
    if (encoding != "ascii") sc_.fail("expected ASCII on line 3, found '", detail::shorten(encoding), "'");
    char buf[16];
    std::snprintf(buf, sizeof buf, "%.1f", version_);
    report_.format = std::string("vtk legacy ") + buf;
  }

  void readPoints() {
    const std::size_t n = sc_.readCount("points", 6);
    sc_.token();  // data type: float, double, int, ...
    nodes_.reserve(3 * n);
    for (std::size_t i = 0; i < n; ++i) {
      sc_.setContext("point", std::int64_t(i), std::int64_t(n));
      double xyz[3];
      sc_.readPoint(xyz, std::int64_t(i), false);
      nodes_.insert(nodes_.end(), xyz, xyz + 3);
    }
    havePoints_ = true;
  }

  // Legacy 2.0-4.2: n records "k i1 .. ik", size = total number of integers.
  void readCellsV2() {
    const std::size_t n = sc_.readCount("cells", 4);
    const std::size_t size = sc_.readCount("cell list integers", 2);
    offsets_.reserve(n + 1);
    connectivity_.reserve(size >= n ? size - n : 0);
    cellLines_.reserve(n);
    offsets_.push_back(0);
    for (std::size_t c = 0; c < n; ++c) {
      sc_.setContext("cell", std::int64_t(c), std::int64_t(n));
      const std::int64_t k = sc_.readInt();
      cellLines_.push_back(static_cast<std::uint32_t>(sc_.line()));
      if (k < 0 || std::size_t(k) > size) sc_.fail("cell ", c, " has ", k, " nodes");
      for (std::int64_t j = 0; j < k; ++j) connectivity_.push_back(sc_.readInt());
      offsets_.push_back(static_cast<std::int64_t>(connectivity_.size()));
    }
    if (connectivity_.size() + n != size)
      sc_.fail("the CELLS header announces ", size, " integers but the cells hold ", connectivity_.size() + n);
  }

  // Legacy 5.1: "CELLS nOffsets nConnectivity", "OFFSETS type" + values, "CONNECTIVITY type" + values.
  void readCellsV5() {
    const std::size_t nOffsets = sc_.readCount("cell offsets", 2);
    const std::size_t nConn = sc_.readCount("connectivity entries", 2);
    if (nOffsets == 0) sc_.fail("CELLS announces 0 offsets; 5.1 files have cell count + 1");
    sc_.setContext("the OFFSETS header");
    if (lower(sc_.token()) != "offsets") sc_.fail("expected OFFSETS after CELLS in a version 5 file");
    sc_.token();
    offsets_.resize(nOffsets);
    for (std::size_t i = 0; i < nOffsets; ++i) {
      sc_.setContext("offset", std::int64_t(i), std::int64_t(nOffsets));
      offsets_[i] = sc_.readInt();
      if (offsets_[i] < 0 || std::size_t(offsets_[i]) > nConn || (i > 0 && offsets_[i] < offsets_[i - 1]))
        sc_.fail("offset ", i, " is ", offsets_[i], "; offsets must rise from 0 to ", nConn);
    }
    if (offsets_.front() != 0 || std::size_t(offsets_.back()) != nConn)
      sc_.fail("the offsets run from ", offsets_.front(), " to ", offsets_.back(), "; expected 0 to ", nConn);
    sc_.setContext("the CONNECTIVITY header");
    if (lower(sc_.token()) != "connectivity") sc_.fail("expected CONNECTIVITY after the offsets");
    sc_.token();
    connectivity_.resize(nConn);
    cellLines_.resize(nOffsets - 1);
    std::size_t cell = 0;
    for (std::size_t i = 0; i < nConn; ++i) {
      sc_.setContext("connectivity entry", std::int64_t(i), std::int64_t(nConn));
      connectivity_[i] = sc_.readInt();
      while (cell + 1 < nOffsets && std::size_t(offsets_[cell]) == i) {
        cellLines_[cell] = static_cast<std::uint32_t>(sc_.line());
        ++cell;
      }
    }
  }

  void readCellTypes() {
    const std::size_t n = sc_.readCount("cell types", 2);
    if (offsets_.empty()) sc_.fail("CELL_TYPES before CELLS");
    if (n != offsets_.size() - 1)
      sc_.fail("CELL_TYPES has ", n, " entries but CELLS has ", offsets_.size() - 1, " cells");
    types_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      sc_.setContext("cell type", std::int64_t(i), std::int64_t(n));
      types_[i] = sc_.readInt();
    }
  }

  void skipValues(std::size_t count, const char* what) {
    sc_.checkCount(std::int64_t(count), what, 2);
    for (std::size_t i = 0; i < count; ++i) {
      sc_.setContext(what, std::int64_t(i), std::int64_t(count));
      const std::string_view tok = sc_.token();
      if (tok.empty()) sc_.readInt();  // reports the truncation
    }
  }

  // Reads count values of an array, keeping them as regions when wanted.
  void readArray(std::size_t count, bool asRegions, const char* what) {
    if (!asRegions) return skipValues(count, what);
    sc_.checkCount(std::int64_t(count), what, 2);
    regions_.resize(count);
    for (std::size_t i = 0; i < count; ++i) {
      sc_.setContext(what, std::int64_t(i), std::int64_t(count));
      regions_[i] = static_cast<std::int32_t>(std::lround(sc_.readDouble()));
    }
    haveRegions_ = true;
  }

  void readScalars() {
    const std::string_view name = sc_.token();
    sc_.token();  // data type
    std::int64_t components = 1;
    if (!sc_.atLineEnd()) components = sc_.readIntOnLine();
    if (components < 1 || components > 4) sc_.fail("SCALARS ", detail::shorten(name), " has ", components, " components; expected 1 to 4");
    const bool asRegions = cellScope_ && components == 1 && !haveRegions_ && isRegionArrayName(name);
    if (lower(sc_.peekToken()) == "lookup_table") {
      sc_.token();
      sc_.token();
    }
    readArray(scopeCount_ * std::size_t(components), asRegions, "scalar value");
  }

  // FIELD name k, then k arrays "name components tuples type" + values.
  void readField() {
    sc_.token();
    const std::int64_t arrays = sc_.readInt();
    sc_.checkCount(arrays, "field arrays", 8);
    for (std::int64_t a = 0; a < arrays; ++a) {
      sc_.setContext("field array", a, arrays);
      const std::string_view name = sc_.token();
      const std::int64_t components = sc_.readInt();
      const std::int64_t tuples = sc_.readInt();
      sc_.token();  // type
      if (components < 0 || tuples < 0) sc_.fail("field array ", detail::shorten(name), " has a negative size");
      const bool asRegions = cellScope_ && components == 1 && std::size_t(tuples) == scopeCount_ && !haveRegions_ &&
                             isRegionArrayName(name);
      const std::string label = "value of field array " + detail::shorten(name);
      readArray(std::size_t(components) * std::size_t(tuples), asRegions, label.c_str());
      // A 5.x file may follow an array with a METADATA block.
      if (lower(sc_.peekToken()) == "metadata") {
        sc_.token();
        skipMetadata();
      }
    }
  }

  // METADATA runs to the first empty line.
  void skipMetadata() {
    sc_.skipLine();
    while (!sc_.atLineEnd()) sc_.skipLine();
    sc_.skipLine();
  }

  ParsedTetMesh assemble() {
    if (!havePoints_) sc_.fail("the file has no POINTS section");
    if (offsets_.empty()) sc_.fail("the file has no CELLS section");
    const std::size_t cells = offsets_.size() - 1;
    if (types_.size() != cells) sc_.fail("the file has no CELL_TYPES section");
    if (haveRegions_ && regions_.size() != cells)
      sc_.fail("the region array has ", regions_.size(), " values for ", cells, " cells");
    ParsedTetMesh out;
    out.elementWord = "cell";
    out.nodes = std::move(nodes_);
    out.nodeBase = 0;
    out.tets.reserve(4 * cells);
    out.elementIds.reserve(cells);
    out.elementLines.reserve(cells);
    for (std::size_t c = 0; c < cells; ++c) {
      const std::int64_t begin = offsets_[c], size = offsets_[c + 1] - offsets_[c];
      if (types_[c] != kVtkTetraCell) {
        ++report_.skippedElements;
        ++report_.skippedByType[vtkCellTypeName(types_[c])];
        continue;
      }
      if (size != 4)
        detail::fail(ErrorCode::BadInput, "file ", sc_.path(), " line ", cellLines_[c], ": cell ", c,
                     " is a tetra (type 10) with ", size, " nodes; it needs 4");
      out.tets.insert(out.tets.end(), connectivity_.begin() + begin, connectivity_.begin() + begin + 4);
      out.elementIds.push_back(std::int64_t(c));
      out.elementLines.push_back(cellLines_[c]);
      if (haveRegions_) out.regions.push_back(regions_[c]);
    }
    return out;
  }

  TextScanner sc_;
  MeshReadReport& report_;
  double version_ = 0;
  bool havePoints_ = false, haveRegions_ = false, cellScope_ = false;
  std::size_t scopeCount_ = 0;
  std::vector<double> nodes_;
  std::vector<std::int64_t> offsets_, connectivity_, types_;
  std::vector<std::uint32_t> cellLines_;
  std::vector<std::int32_t> regions_;
};

}  // namespace

ParsedTetMesh parseVtkLegacy(const std::string& text, const std::string& path, MeshReadReport& report) {
  return VtkParser(text, path, report).run();
}

}  // namespace corofem::mesh
