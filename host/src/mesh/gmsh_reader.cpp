// Gmsh .msh ASCII reader: format 1 ($NOD/$ELM), 2.x ($MeshFormat 2.2) and 4.1 (entity blocks).
// Only linear tetrahedra (Gmsh element type 4) are kept; every other element is skipped and counted.
#include "mesh/readers.hpp"
#include "mesh/text_scanner.hpp"

#include <algorithm>
#include <string>

namespace corofem::mesh {
namespace {

constexpr std::int64_t kGmshTet = 4;

std::string gmshTypeName(std::int64_t type) {
  const char* name = nullptr;
  switch (type) {
    case 1: name = "line"; break;
    case 2: name = "triangle"; break;
    case 3: name = "quadrangle"; break;
    case 4: name = "tetrahedron"; break;
    case 5: name = "hexahedron"; break;
    case 6: name = "prism"; break;
    case 7: name = "pyramid"; break;
    case 8: name = "line3"; break;
    case 9: name = "triangle6"; break;
    case 10: name = "quadrangle9"; break;
    case 11: name = "tetrahedron10"; break;
    case 15: name = "point"; break;
    case 16: name = "quadrangle8"; break;
    default: name = "element"; break;
  }
  return std::string(name) + " (gmsh type " + std::to_string(type) + ")";
}

class GmshParser {
 public:
  GmshParser(const std::string& text, const std::string& path, MeshReadReport& report)
      : sc_(text, path), report_(report) {}

  ParsedTetMesh run() {
    bool sawNodes = false, sawElements = false;
    while (!sc_.atEnd()) {
      sc_.setContext(nullptr);
      const std::string_view tok = sc_.token();
      if (tok == "$MeshFormat") {
        readFormat();
      } else if (tok == "$NOD" || tok == "$NOE") {
        version_ = 1;
        readNodesV1();
        sawNodes = true;
      } else if (tok == "$ELM") {
        version_ = 1;
        readElementsV1();
        sawElements = true;
      } else if (tok == "$Nodes") {
        requireFormat("$Nodes");
        if (version_ >= 4) readNodesV4(); else readNodesV2();
        sawNodes = true;
      } else if (tok == "$Elements") {
        requireFormat("$Elements");
        if (version_ >= 4) readElementsV4(); else readElementsV2();
        sawElements = true;
      } else if (!tok.empty() && tok[0] == '$') {
        // Any other section ($PhysicalNames, $Entities, $NodeData, IPC's $Surface, ...): skip it.
        const std::string end = "$End" + std::string(tok.substr(1));
        const std::string endV1 = "$END" + std::string(tok.substr(1));
        if (!sc_.skipPast(version_ == 1 ? endV1 : end))
          sc_.fail("section ", detail::shorten(tok), " has no ", detail::shorten(version_ == 1 ? endV1 : end),
                   "; the file is truncated");
      } else {
        sc_.fail("expected a section header such as $Nodes or $Elements, found '", detail::shorten(tok),
                 "'; is this a Gmsh ASCII .msh file?");
      }
    }
    if (!sawNodes || !sawElements)
      sc_.fail("the file has no ", sawNodes ? "$Elements" : "$Nodes", " section; is this a Gmsh .msh file?");
    report_.format = version_ == 1 ? "gmsh 1" : version_ >= 4 ? "gmsh 4.1" : "gmsh 2.2";
    if (std::all_of(out_.regions.begin(), out_.regions.end(), [](std::int32_t r) { return r == 0; }))
      out_.regions.clear();  // tag 0 everywhere: no physical groups (v1, v2) or entities (v4.1), so no regions
    return std::move(out_);
  }

 private:
  void requireFormat(const char* section) {
    if (version_ == 0) sc_.fail(section, " before $MeshFormat; the file has no Gmsh format header");
  }

  void expectEnd(std::string_view end) {
    const std::string_view tok = sc_.token();
    if (tok != end)
      sc_.fail("expected ", end, " after ", sc_.context(), ", found '", detail::shorten(tok),
               "'; the count in the section header does not match the entries");
  }

  void readFormat() {
    sc_.setContext("the $MeshFormat line");
    const double version = sc_.readDouble();
    const std::int64_t fileType = sc_.readInt();
    sc_.readInt();  // data size
    if (fileType != 0)
      sc_.fail("binary Gmsh files are not supported; save the mesh as ASCII (gmsh -save_all -format msh22 or msh41)");
    if (version >= 2 && version < 3) {
      version_ = 2;
    } else if (version >= 4.1 && version < 5) {
      version_ = 4;
    } else {
      sc_.fail("Gmsh format version ", version, " is not supported; save as version 2.2 or 4.1");
    }
    expectEnd("$EndMeshFormat");
  }

  void addTet(std::int64_t id, std::uint32_t line, const std::int64_t nodes[4], std::int32_t region) {
    out_.tets.insert(out_.tets.end(), nodes, nodes + 4);
    out_.elementIds.push_back(id);
    out_.elementLines.push_back(line);
    out_.regions.push_back(region);
  }

  void skipElement(std::int64_t type) {
    ++report_.skippedElements;
    ++report_.skippedByType[gmshTypeName(type)];
    sc_.skipLine();
  }

  void reserveNodes(std::size_t n) {
    out_.nodes.reserve(3 * n);
    out_.nodeIds.reserve(n);
    out_.nodeLines.reserve(n);
  }

  void reserveElements(std::size_t n) {
    out_.tets.reserve(4 * n);
    out_.elementIds.reserve(n);
    out_.elementLines.reserve(n);
    out_.regions.reserve(n);
  }

  // Format 1 and 2: "count" then "id x y z" per line.
  void readNodesV1V2(const char* endMarker) {
    const std::size_t n = sc_.readCount("nodes", 8);  // "i x y z" needs >= 8 bytes
    reserveNodes(n);
    for (std::size_t i = 0; i < n; ++i) {
      sc_.setContext("node", std::int64_t(i + 1), std::int64_t(n));
      const std::int64_t id = sc_.readInt();
      out_.nodeIds.push_back(id);
      out_.nodeLines.push_back(static_cast<std::uint32_t>(sc_.line()));
      double xyz[3];
      sc_.readPoint(xyz, id, true);
      out_.nodes.insert(out_.nodes.end(), xyz, xyz + 3);
      sc_.expectLineEnd();
    }
    expectEnd(endMarker);
  }
  void readNodesV1() { readNodesV1V2("$ENDNOD"); }
  void readNodesV2() { readNodesV1V2("$EndNodes"); }

  // Format 1: "id type reg-phys reg-elem nnodes n1 ... nn".
  void readElementsV1() {
    const std::size_t n = sc_.readCount("elements", 12);
    reserveElements(n);
    for (std::size_t i = 0; i < n; ++i) {
      sc_.setContext("element", std::int64_t(i + 1), std::int64_t(n));
      const std::int64_t id = sc_.readInt();
      const auto line = static_cast<std::uint32_t>(sc_.line());
      const std::int64_t type = sc_.readIntOnLine();
      const std::int64_t physical = sc_.readIntOnLine();
      sc_.readIntOnLine();  // elementary region
      const std::int64_t count = sc_.readIntOnLine();
      if (type != kGmshTet) {
        skipElement(type);
        continue;
      }
      if (count != 4) sc_.fail("element ", id, " is a tetrahedron (type 4) with ", count, " nodes; it needs 4");
      std::int64_t nodes[4];
      for (auto& v : nodes) v = sc_.readIntOnLine();
      sc_.expectLineEnd();
      addTet(id, line, nodes, static_cast<std::int32_t>(physical));
    }
    expectEnd("$ENDELM");
  }

  // Format 2: "id type ntags tag1 ... tagk n1 ... nn"; tag1 is the physical group.
  void readElementsV2() {
    const std::size_t n = sc_.readCount("elements", 8);
    reserveElements(n);
    for (std::size_t i = 0; i < n; ++i) {
      sc_.setContext("element", std::int64_t(i + 1), std::int64_t(n));
      const std::int64_t id = sc_.readInt();
      const auto line = static_cast<std::uint32_t>(sc_.line());
      const std::int64_t type = sc_.readIntOnLine();
      if (type != kGmshTet) {
        skipElement(type);
        continue;
      }
      const std::int64_t tagCount = sc_.readIntOnLine();
      if (tagCount < 0 || tagCount > 64) sc_.fail("element ", id, " has ", tagCount, " tags; expected 0 to 64");
      std::int64_t physical = 0;
      for (std::int64_t t = 0; t < tagCount; ++t) {
        const std::int64_t tag = sc_.readIntOnLine();
        if (t == 0) physical = tag;
      }
      std::int64_t nodes[4];
      for (auto& v : nodes) v = sc_.readIntOnLine();
      sc_.expectLineEnd();
      addTet(id, line, nodes, static_cast<std::int32_t>(physical));
    }
    expectEnd("$EndElements");
  }

  // Format 4.1: "numBlocks numNodes minTag maxTag", then per block "dim entity parametric count",
  // count tags (one per line), then count coordinate lines (plus dim parametric values if parametric).
  void readNodesV4() {
    sc_.setContext("the $Nodes header");
    const std::int64_t blocks = sc_.readInt();
    const std::size_t n = sc_.readCount("nodes", 8);  // a tag and three coordinates
    sc_.readInt();
    sc_.readInt();
    sc_.checkCount(blocks, "node blocks", 8);
    reserveNodes(n);
    std::size_t read = 0;
    for (std::int64_t b = 0; b < blocks; ++b) {
      sc_.setContext("node block", b + 1, blocks);
      const std::int64_t dim = sc_.readInt();
      sc_.readInt();  // entity tag
      const std::int64_t parametric = sc_.readInt();
      const std::int64_t count = sc_.readInt();
      sc_.checkCount(count, "nodes in the block", 8);
      if (read + std::size_t(count) > n)
        sc_.fail("node block ", b + 1, " brings the node count above the ", n, " announced in the $Nodes header");
      const std::size_t first = out_.nodeIds.size();
      for (std::int64_t i = 0; i < count; ++i) {
        sc_.setContext("node tag", std::int64_t(read) + i + 1, std::int64_t(n));
        out_.nodeIds.push_back(sc_.readInt());
      }
      const int extra = parametric ? static_cast<int>(dim) : 0;
      for (std::int64_t i = 0; i < count; ++i) {
        sc_.setContext("node", std::int64_t(read) + i + 1, std::int64_t(n));
        double xyz[3];
        sc_.readPoint(xyz, out_.nodeIds[first + std::size_t(i)], false);
        out_.nodeLines.push_back(static_cast<std::uint32_t>(sc_.line()));
        out_.nodes.insert(out_.nodes.end(), xyz, xyz + 3);
        for (int k = 0; k < extra; ++k) sc_.readDoubleOnLine();
        sc_.expectLineEnd();
      }
      read += std::size_t(count);
    }
    if (read != n) sc_.fail("the $Nodes header announces ", n, " nodes but the blocks hold ", read);
    sc_.setContext("the node blocks");
    expectEnd("$EndNodes");
  }

  // Format 4.1: "numBlocks numElements minTag maxTag", then per block "dim entity type count" and
  // count lines "tag n1 ... nk".
  void readElementsV4() {
    sc_.setContext("the $Elements header");
    const std::int64_t blocks = sc_.readInt();
    const std::size_t n = sc_.readCount("elements", 4);  // a tag and a node at least
    sc_.readInt();
    sc_.readInt();
    sc_.checkCount(blocks, "element blocks", 8);
    std::size_t read = 0;
    for (std::int64_t b = 0; b < blocks; ++b) {
      sc_.setContext("element block", b + 1, blocks);
      const std::int64_t dim = sc_.readInt();
      const std::int64_t entity = sc_.readInt();
      const std::int64_t type = sc_.readInt();
      const std::int64_t count = sc_.readInt();
      (void)dim;
      sc_.checkCount(count, "elements in the block", 4);
      if (read + std::size_t(count) > n)
        sc_.fail("element block ", b + 1, " brings the element count above the ", n,
                 " announced in the $Elements header");
      sc_.skipLine();
      if (type != kGmshTet) {
        report_.skippedElements += std::size_t(count);
        report_.skippedByType[gmshTypeName(type)] += std::size_t(count);
        for (std::int64_t i = 0; i < count; ++i) {
          if (sc_.atEnd()) {
            sc_.setContext("element", std::int64_t(read) + i + 1, std::int64_t(n));
            sc_.readInt();  // reports the truncation
          }
          sc_.skipLine();
        }
      } else {
        reserveElements(out_.elementIds.size() + std::size_t(count));
        for (std::int64_t i = 0; i < count; ++i) {
          sc_.setContext("element", std::int64_t(read) + i + 1, std::int64_t(n));
          const std::int64_t id = sc_.readInt();
          const auto line = static_cast<std::uint32_t>(sc_.line());
          std::int64_t nodes[4];
          for (auto& v : nodes) v = sc_.readIntOnLine();
          sc_.expectLineEnd();
          addTet(id, line, nodes, static_cast<std::int32_t>(entity));
        }
      }
      read += std::size_t(count);
    }
    if (read != n) sc_.fail("the $Elements header announces ", n, " elements but the blocks hold ", read);
    sc_.setContext("the element blocks");
    expectEnd("$EndElements");
  }

  TextScanner sc_;
  MeshReadReport& report_;
  ParsedTetMesh out_;
  int version_ = 0;  // 1, 2 (2.x) or 4 (4.1)
};

}  // namespace

ParsedTetMesh parseGmsh(const std::string& text, const std::string& path, MeshReadReport& report) {
  return GmshParser(text, path, report).run();
}

}  // namespace corofem::mesh
