// Vega FEM .veg reader: "*VERTICES" (header "n 3 0 0", then "id x y z"), "*ELEMENTS" + "TET" (header
// "m 4 0", then "id a b c d", 1-based). *MATERIAL, *REGION, *SET and other sections are tolerated
// and skipped: corofem takes materials from the scene file.
#include "mesh/readers.hpp"
#include "mesh/text_scanner.hpp"

#include <cctype>

namespace corofem::mesh {
namespace {

std::string upper(std::string_view s) {
  std::string r(s);
  for (char& c : r) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return r;
}

}  // namespace

ParsedTetMesh parseVeg(const std::string& text, const std::string& path, MeshReadReport& report) {
  TextScanner sc(text, path);
  sc.setCommentChar('#');
  ParsedTetMesh out;
  bool sawVertices = false, sawElements = false;
  auto skipSection = [&] {
    while (!sc.atEnd() && *sc.position() != '*') sc.skipLine();
  };
  while (!sc.atEnd()) {
    sc.setContext(nullptr);
    const std::string_view tok = sc.token();
    const std::string key = upper(tok);
    if (key == "*VERTICES") {
      if (sawVertices) sc.fail("a second *VERTICES section");
      sawVertices = true;
      sc.setContext("the *VERTICES header");
      const std::size_t n = sc.readCount("vertices", 8);
      const std::int64_t dim = sc.readIntOnLine();
      if (dim != 3) sc.fail("vertices of dimension ", dim, "; expected 3");
      sc.skipLine();
      out.nodes.reserve(3 * n);
      out.nodeIds.reserve(n);
      out.nodeLines.reserve(n);
      for (std::size_t i = 0; i < n; ++i) {
        sc.setContext("vertex", std::int64_t(i + 1), std::int64_t(n));
        const std::int64_t id = sc.readInt();
        out.nodeIds.push_back(id);
        out.nodeLines.push_back(static_cast<std::uint32_t>(sc.line()));
        double xyz[3];
        sc.readPoint(xyz, id, true);
        out.nodes.insert(out.nodes.end(), xyz, xyz + 3);
        sc.expectLineEnd();
      }
    } else if (key == "*ELEMENTS") {
      if (sawElements) sc.fail("a second *ELEMENTS section");
      sawElements = true;
      sc.setContext("the element type after *ELEMENTS");
      const std::string type = upper(sc.token());
      if (type != "TET")
        sc.fail("element type ", detail::shorten(type), " is not supported; corofem reads TET elements (linear tetrahedra)");
      sc.setContext("the *ELEMENTS header");
      const std::size_t m = sc.readCount("elements", 10);
      const std::int64_t perElement = sc.readIntOnLine();
      if (perElement != 4) sc.fail("TET elements with ", perElement, " nodes; expected 4");
      sc.skipLine();
      out.tets.reserve(4 * m);
      out.elementIds.reserve(m);
      out.elementLines.reserve(m);
      for (std::size_t e = 0; e < m; ++e) {
        sc.setContext("element", std::int64_t(e + 1), std::int64_t(m));
        out.elementIds.push_back(sc.readInt());
        out.elementLines.push_back(static_cast<std::uint32_t>(sc.line()));
        for (int k = 0; k < 4; ++k) out.tets.push_back(sc.readIntOnLine());
        sc.expectLineEnd();
      }
    } else if (key == "*INCLUDE") {
      sc.fail("*INCLUDE is not supported; merge the included file into this one");
    } else if (!key.empty() && key[0] == '*') {
      sc.skipLine();  // *MATERIAL name, *REGION, *SET name, ...: tolerated, content skipped
      skipSection();
    } else {
      sc.fail("expected a section such as *VERTICES or *ELEMENTS, found '", detail::shorten(tok), "'");
    }
  }
  if (!sawVertices) sc.fail("the file has no *VERTICES section; is this a Vega .veg file?");
  if (!sawElements) sc.fail("the file has no *ELEMENTS section");
  report.format = "vega";
  return out;
}

}  // namespace corofem::mesh
