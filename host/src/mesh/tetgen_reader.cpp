// TetGen .node/.ele reader. .node: "n 3 nattr nbm" then "id x y z [attrs] [marker]";
// .ele: "m nodesPerTet nattr" then "id n1 .. nk [attrs]". Ids start at 0 or 1 (the first node id
// decides); the element's first attribute, when present, is its region.
#include "mesh/readers.hpp"
#include "mesh/text_scanner.hpp"

#include <cmath>
#include <limits>

namespace corofem::mesh {

ParsedTetMesh parseTetGen(const std::string& nodePath, const std::string& elePath, MeshReadReport& report,
                          const InputLimits& limits) {
  ParsedTetMesh out;
  {
    const std::string nodeText = readWholeFile(nodePath, limits);
    TextScanner sc(nodeText, nodePath);
    sc.setCommentChar('#');
    sc.setContext("the .node header");
    const std::size_t n = sc.readCount("nodes", 8);
    const std::int64_t dim = sc.readIntOnLine();
    const std::int64_t attributes = sc.readIntOnLine();
    const std::int64_t markers = sc.readIntOnLine();
    if (dim != 3) sc.fail("the .node file has dimension ", dim, "; corofem reads 3-D meshes only");
    if (attributes < 0 || markers < 0 || markers > 1)
      sc.fail("bad .node header: ", attributes, " attributes and ", markers, " boundary markers");
    sc.expectLineEnd();
    out.nodes.reserve(3 * n);
    out.nodeIds.reserve(n);
    out.nodeLines.reserve(n);
    for (std::size_t i = 0; i < n; ++i) {
      sc.setContext("node", std::int64_t(i + 1), std::int64_t(n));
      const std::int64_t id = sc.readInt();
      if (i == 0 && id != 0 && id != 1)
        sc.fail("the first node id is ", id, "; TetGen node ids start at 0 or 1");
      out.nodeIds.push_back(id);
      out.nodeLines.push_back(static_cast<std::uint32_t>(sc.line()));
      double xyz[3];
      sc.readPoint(xyz, id, true);
      out.nodes.insert(out.nodes.end(), xyz, xyz + 3);
      for (std::int64_t k = 0; k < attributes; ++k) sc.readDoubleOnLine();  // (not attributes + markers:
      for (std::int64_t k = 0; k < markers; ++k) sc.readDoubleOnLine();     //  the sum may overflow)
      sc.expectLineEnd();
    }
    if (!sc.atEnd()) {
      sc.setContext("the end of the .node file");
      sc.fail("unexpected '", detail::shorten(sc.peekToken()), "' after the ", n, " nodes announced in the header");
    }
  }
  {
    const std::string eleText = readWholeFile(elePath, limits);
    TextScanner sc(eleText, elePath);
    sc.setCommentChar('#');
    sc.setContext("the .ele header");
    const std::size_t m = sc.readCount("elements", 10);
    const std::int64_t perTet = sc.readIntOnLine();
    const std::int64_t attributes = sc.readIntOnLine();
    if (perTet != 4 && perTet != 10)
      sc.fail("the .ele file has ", perTet, " nodes per tetrahedron; expected 4 (or 10, whose first 4 are used)");
    if (attributes < 0) sc.fail("negative attribute count ", attributes);
    sc.expectLineEnd();
    out.tets.reserve(4 * m);
    out.elementIds.reserve(m);
    out.elementLines.reserve(m);
    if (attributes > 0) out.regions.reserve(m);
    for (std::size_t e = 0; e < m; ++e) {
      sc.setContext("element", std::int64_t(e + 1), std::int64_t(m));
      out.elementIds.push_back(sc.readInt());
      out.elementLines.push_back(static_cast<std::uint32_t>(sc.line()));
      for (std::int64_t k = 0; k < perTet; ++k) {
        const std::int64_t v = sc.readIntOnLine();
        if (k < 4) out.tets.push_back(v);
      }
      for (std::int64_t k = 0; k < attributes; ++k) {
        const double a = sc.readDoubleOnLine();
        if (k == 0) {
          if (!(std::abs(a) <= double(std::numeric_limits<std::int32_t>::max())))
            sc.fail("element ", out.elementIds.back(), " has the region attribute ", a,
                    ", which is not a region id (an integer of at most 2147483647 in magnitude)");
          out.regions.push_back(static_cast<std::int32_t>(std::lround(a)));
        }
      }
      sc.expectLineEnd();
    }
    if (!sc.atEnd()) {
      sc.setContext("the end of the .ele file");
      sc.fail("unexpected '", detail::shorten(sc.peekToken()), "' after the ", m, " elements announced in the header");
    }
  }
  report.format = "tetgen";
  return out;
}

}  // namespace corofem::mesh
