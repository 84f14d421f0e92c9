// Writers: write then read back equals the original for every format with a reader; the .vtu and
// .pvd files parse as well-formed XML (with a small XML reader of our own) with the right counts and
// values; writer errors.
#include "mesh/mesh_test_util.hpp"

#include <cstdlib>
#include <map>
#include <sstream>

namespace {

using corofem::test::contains;
using corofem::test::dataPath;
using corofem::test::tempDir;

// ---- a minimal XML reader: elements, attributes, text; enough to check structure and counts ----
struct XmlNode {
  std::string name;
  std::map<std::string, std::string> attrs;
  std::vector<XmlNode> children;
  std::string text;
  const XmlNode* child(const std::string& n) const {
    for (const auto& c : children)
      if (c.name == n) return &c;
    return nullptr;
  }
  std::vector<const XmlNode*> all(const std::string& n) const {
    std::vector<const XmlNode*> r;
    for (const auto& c : children)
      if (c.name == n) r.push_back(&c);
    return r;
  }
};

class XmlReader {
 public:
  explicit XmlReader(std::string text) : s_(std::move(text)) {}
  /// Parses the document; throws std::runtime_error on malformed input.
  XmlNode parse() {
    skipSpace();
    if (s_.compare(p_, 5, "<?xml") == 0) {
      p_ = s_.find("?>", p_);
      if (p_ == std::string::npos) throw std::runtime_error("unterminated <?xml");
      p_ += 2;
    }
    skipSpace();
    XmlNode root = element();
    skipSpace();
    if (p_ != s_.size()) throw std::runtime_error("content after the root element");
    return root;
  }

 private:
  void skipSpace() {
    while (p_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[p_]))) ++p_;
  }
  std::string name() {
    const std::size_t b = p_;
    while (p_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[p_])) || s_[p_] == '_' || s_[p_] == ':')) ++p_;
    if (b == p_) throw std::runtime_error("expected a name at " + std::to_string(p_));
    return s_.substr(b, p_ - b);
  }
  static std::string unescape(const std::string& v) {
    std::string r;
    for (std::size_t i = 0; i < v.size(); ++i) {
      if (v[i] != '&') { r += v[i]; continue; }
      const auto semi = v.find(';', i);
      const std::string ent = v.substr(i, semi - i + 1);
      if (ent == "&amp;") r += '&';
      else if (ent == "&lt;") r += '<';
      else if (ent == "&gt;") r += '>';
      else if (ent == "&quot;") r += '"';
      else throw std::runtime_error("unknown entity " + ent);
      i = semi;
    }
    return r;
  }
  XmlNode element() {
    if (s_[p_] != '<') throw std::runtime_error("expected '<'");
    ++p_;
    XmlNode node;
    node.name = name();
    for (;;) {
      skipSpace();
      if (s_.compare(p_, 2, "/>") == 0) { p_ += 2; return node; }
      if (s_[p_] == '>') { ++p_; break; }
      const std::string key = name();
      if (s_[p_] != '=' || s_[p_ + 1] != '"') throw std::runtime_error("expected =\" after " + key);
      p_ += 2;
      const auto end = s_.find('"', p_);
      if (end == std::string::npos) throw std::runtime_error("unterminated attribute");
      if (!node.attrs.emplace(key, unescape(s_.substr(p_, end - p_))).second)
        throw std::runtime_error("duplicate attribute " + key);
      p_ = end + 1;
    }
    for (;;) {
      const auto lt = s_.find('<', p_);
      if (lt == std::string::npos) throw std::runtime_error("unclosed <" + node.name + ">");
      node.text += s_.substr(p_, lt - p_);
      p_ = lt;
      if (s_.compare(p_, 2, "</") == 0) {
        p_ += 2;
        if (name() != node.name) throw std::runtime_error("mismatched closing tag in <" + node.name + ">");
        skipSpace();
        if (s_[p_] != '>') throw std::runtime_error("expected '>'");
        ++p_;
        return node;
      }
      node.children.push_back(element());
    }
  }
  std::string s_;
  std::size_t p_ = 0;
};

XmlNode parseXmlFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return XmlReader(ss.str()).parse();
}

std::vector<double> numbers(const std::string& text) {
  std::vector<double> r;
  std::istringstream in(text);
  double v;
  while (in >> v) r.push_back(v);
  return r;
}

corofem::TetMesh box(int tetsPerCell) {
  corofem::BoxSpec spec;
  spec.min = {-0.1, 0.2, 0.3};
  spec.max = {1.7, 0.9, 1.3};
  spec.cells = {3, 2, 2};
  spec.tetsPerCell = tetsPerCell;
  auto r = corofem::generateBox(spec);
  EXPECT_TRUE(r.isOk()) << r.message();
  return std::move(r).value();
}

void expectSameMesh(const corofem::TetMesh& a, const corofem::TetMesh& b, bool compareRegions, const std::string& what) {
  ASSERT_EQ(a.nodeCount(), b.nodeCount()) << what;
  ASSERT_EQ(a.tetCount(), b.tetCount()) << what;
  // Written with the shortest decimal that reads back to the same double: exact equality.
  for (std::size_t i = 0; i < a.nodes.size(); ++i) ASSERT_EQ(a.nodes[i], b.nodes[i]) << what << " value " << i;
  EXPECT_EQ(a.tets, b.tets) << what;
  if (compareRegions) EXPECT_EQ(a.regions, b.regions) << what;
}

// ---- round trips ----

struct Format {
  const char* ext;
  bool keepsRegions;
};
const Format kFormats[] = {{".vtk", true}, {".msh", true}, {".mesh", true}, {".node", true}, {".ele", true}, {".veg", false}};

TEST(RoundTrip, EveryTetFormatReadsBackTheCylinderWithRegions) {
  COROFEM_REQUIRE_DATA("meshes/sfepy/cylinder.mesh");
  const auto original = corofem::test::loadTet(dataPath("meshes/sfepy/cylinder.mesh"));
  ASSERT_FALSE(original.regions.empty());
  const auto dir = tempDir();
  for (const Format& f : kFormats) {
    const std::string path = (dir / (std::string("cyl") + f.ext)).string();
    const corofem::Status st = corofem::writeTetMesh(path, original);
    ASSERT_TRUE(st.isOk()) << st.message();
    corofem::MeshReadReport report;
    const auto back = corofem::test::loadTet(path, &report);
    EXPECT_EQ(report.reorientedElements, 0u) << f.ext;
    expectSameMesh(original, back, f.keepsRegions, f.ext);
  }
}

TEST(RoundTrip, EveryTetFormatReadsBackABoxWithoutRegions) {
  for (int tetsPerCell : {5, 6}) {
    const auto original = box(tetsPerCell);
    const auto dir = tempDir();
    for (const Format& f : kFormats) {
      const std::string path = (dir / (std::string("box") + f.ext)).string();
      ASSERT_TRUE(corofem::writeTetMesh(path, original).isOk()) << f.ext;
      const auto back = corofem::test::loadTet(path);
      expectSameMesh(original, back, true, f.ext);  // no regions in, none out
    }
  }
}

TEST(RoundTrip, ArmadilloThroughGmshAndVtkPreservesEverything) {
  COROFEM_REQUIRE_DATA("meshes/ipc/Armadillo13K.msh");
  const auto original = corofem::test::loadTet(dataPath("meshes/ipc/Armadillo13K.msh"));
  const auto dir = tempDir();
  for (const char* ext : {".msh", ".vtk"}) {
    const std::string path = (dir / (std::string("arm") + ext)).string();
    ASSERT_TRUE(corofem::writeTetMesh(path, original).isOk());
    expectSameMesh(original, corofem::test::loadTet(path), true, ext);
  }
}

TEST(RoundTrip, ObjWithAndWithoutTexcoords) {
  corofem::SurfaceMesh s;
  s.vertices = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0.1};
  s.triangles = {0, 1, 2, 0, 2, 3};
  const auto dir = tempDir();
  for (bool uv : {false, true}) {
    s.texcoords = uv ? std::vector<float>{0, 0, 1, 0, 1, 1, 0.125f, 0.75f} : std::vector<float>{};
    const std::string path = (dir / (uv ? "uv.obj" : "plain.obj")).string();
    ASSERT_TRUE(corofem::writeSurfaceMesh(path, s).isOk());
    auto back = corofem::readSurfaceMesh(path);
    ASSERT_TRUE(back.isOk()) << back.message();
    EXPECT_EQ(back.value().vertices, s.vertices);
    EXPECT_EQ(back.value().triangles, s.triangles);
    EXPECT_EQ(back.value().texcoords, s.texcoords);
  }
}

TEST(RoundTrip, RealObjSurface) {
  COROFEM_REQUIRE_DATA("meshes/sofa/liver-smooth.obj");
  auto original = corofem::readSurfaceMesh(dataPath("meshes/sofa/liver-smooth.obj"));
  ASSERT_TRUE(original.isOk());
  const std::string path = (tempDir() / "liver.obj").string();
  ASSERT_TRUE(corofem::writeSurfaceMesh(path, original.value()).isOk());
  auto back = corofem::readSurfaceMesh(path);
  ASSERT_TRUE(back.isOk()) << back.message();
  EXPECT_EQ(back.value().vertices, original.value().vertices);
  EXPECT_EQ(back.value().triangles, original.value().triangles);
}

// ---- VTK XML ----

TEST(Vtu, WellFormedWithCountsConnectivityAndFields) {
  const auto mesh = box(5);
  const std::size_t n = mesh.nodeCount(), m = mesh.tetCount();
  corofem::MeshField disp{"displacement", 3, false, {}};
  for (std::size_t i = 0; i < 3 * n; ++i) disp.values.push_back(0.001 * double(i) - 0.1 / 3);
  corofem::MeshField stress{"von Mises <&>", 1, true, {}};
  for (std::size_t e = 0; e < m; ++e) stress.values.push_back(1e5 * double(e) + 0.5);
  corofem::TetMesh withRegions = mesh;
  withRegions.regions.assign(m, 3);
  const std::string path = (tempDir() / "box.vtu").string();
  ASSERT_TRUE(corofem::writeTetMesh(path, withRegions, {disp, stress}).isOk());

  XmlNode root;
  ASSERT_NO_THROW(root = parseXmlFile(path));
  EXPECT_EQ(root.name, "VTKFile");
  EXPECT_EQ(root.attrs["type"], "UnstructuredGrid");
  const XmlNode* grid = root.child("UnstructuredGrid");
  ASSERT_TRUE(grid);
  const XmlNode* piece = grid->child("Piece");
  ASSERT_TRUE(piece);
  EXPECT_EQ(piece->attrs.at("NumberOfPoints"), std::to_string(n));
  EXPECT_EQ(piece->attrs.at("NumberOfCells"), std::to_string(m));

  const XmlNode* points = piece->child("Points");
  ASSERT_TRUE(points && points->child("DataArray"));
  EXPECT_EQ(points->child("DataArray")->attrs.at("type"), "Float64");
  EXPECT_EQ(numbers(points->child("DataArray")->text), mesh.nodes);

  std::map<std::string, const XmlNode*> cells;
  for (const XmlNode* a : piece->child("Cells")->all("DataArray")) cells[a->attrs.at("Name")] = a;
  ASSERT_EQ(cells.size(), 3u);
  const auto conn = numbers(cells["connectivity"]->text);
  ASSERT_EQ(conn.size(), 4 * m);
  for (std::size_t i = 0; i < conn.size(); ++i) ASSERT_EQ(conn[i], double(mesh.tets[i]));
  const auto offsets = numbers(cells["offsets"]->text);
  ASSERT_EQ(offsets.size(), m);
  for (std::size_t c = 0; c < m; ++c) ASSERT_EQ(offsets[c], double(4 * (c + 1)));
  const auto types = numbers(cells["types"]->text);
  ASSERT_EQ(types.size(), m);
  for (double t : types) ASSERT_EQ(t, 10.0);

  const XmlNode* pd = piece->child("PointData");
  ASSERT_TRUE(pd);
  const XmlNode* d = pd->child("DataArray");
  EXPECT_EQ(d->attrs.at("Name"), "displacement");
  EXPECT_EQ(d->attrs.at("NumberOfComponents"), "3");
  EXPECT_EQ(numbers(d->text), disp.values);
  const XmlNode* cd = piece->child("CellData");
  ASSERT_TRUE(cd);
  std::map<std::string, const XmlNode*> cellArrays;
  for (const XmlNode* a : cd->all("DataArray")) cellArrays[a->attrs.at("Name")] = a;
  ASSERT_TRUE(cellArrays.count("von Mises <&>"));  // escaped in the file, unescaped here
  EXPECT_EQ(numbers(cellArrays["von Mises <&>"]->text), stress.values);
  ASSERT_TRUE(cellArrays.count("region"));
  EXPECT_EQ(numbers(cellArrays["region"]->text), std::vector<double>(m, 3.0));
}

TEST(Vtu, SurfaceAsTriangleCells) {
  corofem::SurfaceMesh s;
  s.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  s.triangles = {0, 1, 2, 0, 1, 3, 0, 2, 3};
  const std::string path = (tempDir() / "s.vtu").string();
  ASSERT_TRUE(corofem::writeSurfaceMesh(path, s).isOk());
  const XmlNode root = parseXmlFile(path);
  const XmlNode* piece = root.child("UnstructuredGrid")->child("Piece");
  EXPECT_EQ(piece->attrs.at("NumberOfCells"), "3");
  for (const XmlNode* a : piece->child("Cells")->all("DataArray"))
    if (a->attrs.at("Name") == "types") EXPECT_EQ(numbers(a->text), std::vector<double>(3, 5.0));
}

TEST(Pvd, SeriesIsRewrittenWholeAndWellFormed) {
  const auto dir = tempDir();
  corofem::PvdSeries series((dir / "run.pvd").string());
  series.add(0.0, "frame_0000.vtu");
  series.add(0.01, "frame_0001.vtu");
  ASSERT_TRUE(series.write().isOk());
  EXPECT_EQ(parseXmlFile(series.path()).child("Collection")->all("DataSet").size(), 2u);
  series.add(0.02, "a&b/frame_0002.vtu");
  ASSERT_TRUE(series.write().isOk());
  const XmlNode root = parseXmlFile(series.path());
  EXPECT_EQ(root.attrs.at("type"), "Collection");
  const auto sets = root.child("Collection")->all("DataSet");
  ASSERT_EQ(sets.size(), 3u);
  EXPECT_EQ(std::atof(sets[1]->attrs.at("timestep").c_str()), 0.01);
  EXPECT_EQ(sets[2]->attrs.at("file"), "a&b/frame_0002.vtu");
}

TEST(LegacyVtk, PolyDataSurfaceHasPointsAndPolygons) {
  corofem::SurfaceMesh s;
  s.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  s.triangles = {0, 1, 2};
  const std::string path = (tempDir() / "s.vtk").string();
  ASSERT_TRUE(corofem::writeSurfaceMesh(path, s).isOk());
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  EXPECT_TRUE(contains(ss.str(), "DATASET POLYDATA\nPOINTS 3 double\n"));
  EXPECT_TRUE(contains(ss.str(), "POLYGONS 1 4\n3 0 1 2\n"));
}

TEST(LegacyVtk, FieldsWrittenAndTheFileStillReads) {
  const auto mesh = box(6);
  corofem::MeshField u{"u", 3, false, std::vector<double>(3 * mesh.nodeCount(), 0.5)};
  corofem::MeshField s{"s", 1, true, std::vector<double>(mesh.tetCount(), 2.0)};
  const std::string path = (tempDir() / "f.vtk").string();
  ASSERT_TRUE(corofem::writeTetMesh(path, mesh, {u, s}).isOk());
  expectSameMesh(mesh, corofem::test::loadTet(path), true, "vtk with fields");
}

// ---- writer errors ----

TEST(WriterErrors, UnknownExtensionBadFieldBadIndexUnwritablePath) {
  const auto mesh = box(5);
  const auto dir = tempDir();
  corofem::Status st = corofem::writeTetMesh((dir / "m.stl").string(), mesh);
  EXPECT_EQ(st.code(), corofem::ErrorCode::BadInput);
  EXPECT_TRUE(contains(st.message(), "m.stl"));
  EXPECT_TRUE(contains(st.message(), ".vtu"));
  st = corofem::writeTetMesh((dir / "m.vtu").string(), mesh, {{"short", 3, false, {1.0, 2.0}}});
  EXPECT_EQ(st.code(), corofem::ErrorCode::BadInput);
  EXPECT_TRUE(contains(st.message(), "field 'short' has 2 values, expected 3 x " + std::to_string(mesh.nodeCount())));
  corofem::TetMesh broken = mesh;
  broken.tets[5] = 100000;
  st = corofem::writeTetMesh((dir / "b.msh").string(), broken);
  EXPECT_EQ(st.code(), corofem::ErrorCode::BadInput);
  EXPECT_TRUE(contains(st.message(), "element 1 refers to node 100000"));
  const std::string nowhere = (dir / "no" / "such" / "dir" / "m.vtu").string();
  st = corofem::writeTetMesh(nowhere, mesh);
  EXPECT_EQ(st.code(), corofem::ErrorCode::IoError);
  EXPECT_TRUE(contains(st.message(), nowhere));
  corofem::SurfaceMesh s;
  s.vertices = {0, 0, 0};
  s.triangles = {0, 0, 1};
  st = corofem::writeSurfaceMesh((dir / "s.obj").string(), s);
  EXPECT_EQ(st.code(), corofem::ErrorCode::BadInput);
  EXPECT_TRUE(contains(st.message(), "triangle 0 refers to vertex 1"));
}

}  // namespace
