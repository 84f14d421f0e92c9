// Medit .mesh (ASCII) reader: "Vertices n" (x y z ref), "Tetrahedra m" (a b c d ref, 1-based; the
// reference becomes the region; all references 0 means no regions). Other sections (Triangles, Edges, Corners, ...) are skipped.
#include "mesh/readers.hpp"
#include "mesh/text_scanner.hpp"

#include <cctype>

namespace corofem::mesh {
namespace {

bool equalsNoCase(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  return true;
}

bool startsLikeNumber(std::string_view tok) {
  if (tok.empty()) return false;
  const char c = tok[0];
  return (c >= '0' && c <= '9') || c == '-' || c == '+' || c == '.';
}

bool isElementSection(std::string_view tok) {
  for (const char* s : {"Edges", "Triangles", "Quadrilaterals", "Hexahedra", "Prisms", "Pyramids"})
    if (equalsNoCase(tok, s)) return true;
  return false;
}

}  // namespace

ParsedTetMesh parseMedit(const std::string& text, const std::string& path, MeshReadReport& report) {
  TextScanner sc(text, path);
  sc.setCommentChar('#');
  ParsedTetMesh out;
  out.nodeBase = 1;
  bool sawVertices = false, sawTets = false, sawVersion = false;
  while (!sc.atEnd()) {
    sc.setContext(nullptr);
    const std::string_view tok = sc.token();
    if (equalsNoCase(tok, "MeshVersionFormatted")) {
      sc.setContext("MeshVersionFormatted");
      sc.readInt();
      sawVersion = true;
    } else if (equalsNoCase(tok, "Dimension")) {
      sc.setContext("Dimension");
      const std::int64_t dim = sc.readInt();
      if (dim != 3) sc.fail("the mesh has dimension ", dim, "; corofem reads 3-D meshes only");
    } else if (equalsNoCase(tok, "Vertices")) {
      if (sawVertices) sc.fail("a second Vertices section; a Medit file has one");
      sawVertices = true;
      const std::size_t n = sc.readCount("vertices", 8);
      out.nodes.reserve(3 * n);
      for (std::size_t i = 0; i < n; ++i) {
        sc.setContext("vertex", std::int64_t(i + 1), std::int64_t(n));
        double xyz[3];
        sc.readPoint(xyz, std::int64_t(i + 1), false);
        out.nodes.insert(out.nodes.end(), xyz, xyz + 3);
        sc.readInt();  // reference
      }
    } else if (equalsNoCase(tok, "Tetrahedra")) {
      if (sawTets) sc.fail("a second Tetrahedra section; a Medit file has one");
      sawTets = true;
      const std::size_t m = sc.readCount("tetrahedra", 10);
      out.tets.reserve(4 * m);
      out.elementLines.reserve(m);
      out.regions.reserve(m);
      for (std::size_t e = 0; e < m; ++e) {
        sc.setContext("tetrahedron", std::int64_t(e + 1), std::int64_t(m));
        out.tets.push_back(sc.readInt());
        out.elementLines.push_back(static_cast<std::uint32_t>(sc.line()));
        for (int k = 0; k < 3; ++k) out.tets.push_back(sc.readInt());
        out.regions.push_back(static_cast<std::int32_t>(sc.readInt()));
      }
    } else if (equalsNoCase(tok, "End")) {
      break;
    } else if (!tok.empty() && !startsLikeNumber(tok)) {
      // Another section: its entries are numbers up to the next keyword.
      if (isElementSection(tok)) {
        sc.setContext("the size of section", -1, -1);
        const std::int64_t count = sc.readInt();
        report.skippedElements += std::size_t(count > 0 ? count : 0);
        report.skippedByType[std::string(tok) + " (medit)"] += std::size_t(count > 0 ? count : 0);
      }
      while (!sc.atEnd() && startsLikeNumber(sc.peekToken())) sc.token();
    } else {
      sc.fail("expected a Medit keyword (Vertices, Tetrahedra, ...), found '", detail::shorten(tok), "'");
    }
  }
  if (!sawVersion && !sawVertices) sc.fail("no MeshVersionFormatted or Vertices keyword; is this a Medit .mesh file?");
  if (!sawVertices) sc.fail("the file has no Vertices section");
  // Reference 0 everywhere is Medit's "no reference": no regions.
  bool anyRegion = false;
  for (std::int32_t r : out.regions) anyRegion = anyRegion || r != 0;
  if (!anyRegion) out.regions.clear();
  report.format = "medit";
  return out;
}

}  // namespace corofem::mesh
