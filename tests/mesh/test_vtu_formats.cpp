// The .vtu formats (ascii, inline base64, appended raw; zlib where built with it): every one read
// back by an independent reader (meshio) with the same coordinates, cells and point/cell data, bit
// for bit; the binary layout itself checked here byte by byte (headers, little endian, zlib block
// table); base64; surfaces' normals in .vtu and .obj; refusals (zlib without zlib or with ascii,
// non-finite values).
#include "common/meshio_reader.hpp"
#include "mesh/mesh_test_util.hpp"
#include "mesh/vtu_encoding.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <tuple>

namespace {

using corofem::VtuCompression;
using corofem::VtuFormat;
using corofem::VtuOptions;
using corofem::test::contains;
using corofem::test::tempDir;
namespace fs = std::filesystem;

std::string readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// A box of 20 x 10 x 10 cells (2541 nodes, 10000 tets: every binary array spans several 32 KiB
/// blocks), regions of both signs, a point field and a cell field of irregular values.
struct FieldCase {
  corofem::TetMesh mesh;
  std::vector<corofem::MeshField> fields;
};

FieldCase fieldCase() {
  corofem::BoxSpec spec;
  spec.min = {-0.1, 0.2, 0.3};
  spec.max = {1.7, 0.9, 1.3};
  spec.cells = {20, 10, 10};
  auto box = corofem::generateBox(spec);
  EXPECT_TRUE(box.isOk()) << box.message();
  FieldCase c{std::move(box).value(), {}};
  for (std::size_t e = 0; e < c.mesh.tetCount(); ++e) c.mesh.regions.push_back(std::int32_t(e % 7) - 3);
  corofem::MeshField disp{"displacement", 3, false, {}};
  for (std::size_t i = 0; i < c.mesh.nodes.size(); ++i) disp.values.push_back(1e-3 * std::sin(double(i)) / 3.0);
  corofem::MeshField stress{"von Mises", 1, true, {}};
  for (std::size_t e = 0; e < c.mesh.tetCount(); ++e) stress.values.push_back(1e5 * std::cos(double(e)) + 0.1);
  c.fields = {disp, stress};
  return c;
}

/// A wavy sheet of 70 x 70 vertices with texture coordinates and unit normals (float), as a render
/// surface has them.
corofem::SurfaceMesh surfaceCase(bool texcoords) {
  constexpr int kN = 70;
  corofem::SurfaceMesh s;
  for (int j = 0; j < kN; ++j)
    for (int i = 0; i < kN; ++i) {
      const double x = 0.01 * i, y = 0.013 * j, z = 0.05 * std::sin(7.0 * x) * std::cos(5.0 * y);
      s.vertices.insert(s.vertices.end(), {x, y, z});
      // The normal of z = f(x, y): (-f_x, -f_y, 1), normalised.
      const double fx = 0.35 * std::cos(7.0 * x) * std::cos(5.0 * y), fy = -0.25 * std::sin(7.0 * x) * std::sin(5.0 * y);
      const double len = std::sqrt(fx * fx + fy * fy + 1.0);
      s.normals.insert(s.normals.end(), {float(-fx / len), float(-fy / len), float(1.0 / len)});
      if (texcoords) s.texcoords.insert(s.texcoords.end(), {float(i) / (kN - 1), float(j) / (kN - 1) / 3.0f});
    }
  for (int j = 0; j + 1 < kN; ++j)
    for (int i = 0; i + 1 < kN; ++i) {
      const std::uint32_t a = std::uint32_t(j * kN + i), b = a + 1, c = a + kN, d = c + 1;
      s.triangles.insert(s.triangles.end(), {a, b, d, a, d, c});
    }
  return s;
}

// ---- meshio reads every format back with the same values ----

struct FormatCase {
  VtuOptions options;
  const char* name;
};

const FormatCase kFormatCases[] = {
    {{VtuFormat::Ascii, VtuCompression::None}, "ascii"},
    {{VtuFormat::Base64, VtuCompression::None}, "base64"},
    {{VtuFormat::Raw, VtuCompression::None}, "raw"},
    {{VtuFormat::Base64, VtuCompression::Zlib}, "base64_zlib"},
    {{VtuFormat::Raw, VtuCompression::Zlib}, "raw_zlib"},
};

void PrintTo(const FormatCase& c, std::ostream* os) { *os << c.name; }

class VtuFormats : public ::testing::TestWithParam<FormatCase> {
 protected:
  void SetUp() override {
    if (GetParam().options.compression == VtuCompression::Zlib && !corofem::vtuZlibAvailable())
      GTEST_SKIP() << "this build has no zlib (zlib1g-dev was absent at configure time); zlib is not tested";
  }
};

/// The values of a meshio JSON array, with its dtype and shape checked.
template <class T>
std::vector<T> arrayOf(const nlohmann::json& a, const std::string& dtype, std::vector<std::size_t> shape) {
  EXPECT_EQ(a.at("dtype").get<std::string>(), dtype);
  EXPECT_EQ(a.at("shape").get<std::vector<std::size_t>>(), shape);
  return a.at("values").get<std::vector<T>>();
}

TEST_P(VtuFormats, MeshioReadsTheTetMeshBackBitForBit) {
  COROFEM_REQUIRE_MESHIO();
  const FieldCase c = fieldCase();
  const std::string path = (tempDir() / (std::string("box_") + GetParam().name + ".vtu")).string();
  const corofem::Status st = corofem::writeTetMesh(path, c.mesh, c.fields, GetParam().options);
  ASSERT_TRUE(st.isOk()) << st.message();
  std::string error;
  const nlohmann::json m = corofem::test::readWithMeshio(path, error);
  ASSERT_FALSE(m.is_null()) << error;
  const std::size_t n = c.mesh.nodeCount(), e = c.mesh.tetCount();
  // Exact equality: shortest round-trip decimals in ascii, the bits themselves in binary.
  EXPECT_EQ(arrayOf<double>(m.at("points"), "float64", {n, 3}), c.mesh.nodes);
  ASSERT_EQ(m.at("cells").size(), 1u);
  EXPECT_EQ(m.at("cells")[0].at("type"), "tetra");
  EXPECT_EQ(m.at("cells")[0].at("values").get<std::vector<std::uint32_t>>(), c.mesh.tets);
  EXPECT_EQ(arrayOf<double>(m.at("point_data").at("displacement"), "float64", {n, 3}), c.fields[0].values);
  EXPECT_EQ(arrayOf<double>(m.at("cell_data").at("von Mises").at(0), "float64", {e}), c.fields[1].values);
  EXPECT_EQ(arrayOf<std::int32_t>(m.at("cell_data").at("region").at(0), "int32", {e}), c.mesh.regions);
}

TEST_P(VtuFormats, MeshioReadsTheSurfaceWithItsNormalsBitForBit) {
  COROFEM_REQUIRE_MESHIO();
  for (bool texcoords : {false, true}) {
    const corofem::SurfaceMesh s = surfaceCase(texcoords);
    const std::string path =
        (tempDir() / (std::string("sheet_") + GetParam().name + (texcoords ? "_uv" : "") + ".vtu")).string();
    const corofem::Status st = corofem::writeSurfaceMesh(path, s, GetParam().options);
    ASSERT_TRUE(st.isOk()) << st.message();
    std::string error;
    const nlohmann::json m = corofem::test::readWithMeshio(path, error);
    ASSERT_FALSE(m.is_null()) << error;
    const std::size_t n = s.vertexCount();
    EXPECT_EQ(arrayOf<double>(m.at("points"), "float64", {n, 3}), s.vertices);
    ASSERT_EQ(m.at("cells").size(), 1u);
    EXPECT_EQ(m.at("cells")[0].at("type"), "triangle");
    EXPECT_EQ(m.at("cells")[0].at("values").get<std::vector<std::uint32_t>>(), s.triangles);
    const std::vector<double> normals = arrayOf<double>(m.at("point_data").at("Normals"), "float32", {n, 3});
    ASSERT_EQ(normals.size(), s.normals.size());
    for (std::size_t i = 0; i < normals.size(); ++i) ASSERT_EQ(normals[i], double(s.normals[i])) << "value " << i;
    EXPECT_EQ(m.at("point_data").contains("texcoords"), texcoords);
    if (texcoords) {
      const std::vector<double> uv = arrayOf<double>(m.at("point_data").at("texcoords"), "float32", {n, 2});
      ASSERT_EQ(uv.size(), s.texcoords.size());
      for (std::size_t i = 0; i < uv.size(); ++i) ASSERT_EQ(uv[i], double(s.texcoords[i])) << "value " << i;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(EveryFormat, VtuFormats, ::testing::ValuesIn(kFormatCases),
                         [](const auto& info) { return std::string(info.param.name); });

// ---- the binary layout, read here without any library ----

/// RFC 4648 base64 decoding, written independently of the writer's encoder. Stops at '='.
std::string decodeBase64(std::string_view text) {
  auto digit = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::string out;
  unsigned acc = 0;
  int bits = 0;
  for (char c : text) {
    if (c == '=') break;
    const int d = digit(c);
    if (d < 0) throw std::runtime_error(std::string("not a base64 digit: ") + c);
    acc = (acc << 6) | unsigned(d);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(char((acc >> bits) & 0xffu));
    }
  }
  return out;
}

std::uint64_t u64At(const std::string& bytes, std::size_t at) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | std::uint8_t(bytes.at(at + std::size_t(i)));
  return v;
}

/// The text of attribute `key` in the opening tag that starts at `tag`.
std::string attribute(const std::string& file, std::size_t tag, const std::string& key) {
  const std::size_t end = file.find('>', tag);
  const std::size_t at = file.find(" " + key + "=\"", tag);
  if (at == std::string::npos || at > end) return "";
  const std::size_t begin = at + key.size() + 3;
  return file.substr(begin, file.find('"', begin) - begin);
}

/// Where the DataArray named `name` starts.
std::size_t arrayTag(const std::string& file, const std::string& name) {
  std::size_t at = file.find("<DataArray ");
  while (at != std::string::npos && attribute(file, at, "Name") != name) at = file.find("<DataArray ", at + 1);
  if (at == std::string::npos) throw std::runtime_error("no array " + name);
  return at;
}

/// What array `name` stores: its base64 text without white space (inline; the caller decodes, a
/// compressed array having two streams), or the appended bytes from its offset on.
std::string storedBytes(const std::string& file, const std::string& name) {
  const std::size_t at = arrayTag(file, name);
  const std::string format = attribute(file, at, "format");
  if (format == "binary") {
    const std::size_t begin = file.find('>', at) + 1;
    std::string text = file.substr(begin, file.find("</DataArray>", begin) - begin);
    text.erase(std::remove_if(text.begin(), text.end(), [](char c) { return std::isspace(static_cast<unsigned char>(c)); }),
               text.end());
    return text;
  }
  if (format != "appended") throw std::runtime_error(name + " has format " + format);
  const std::size_t data = file.find('_', file.find("<AppendedData encoding=\"raw\">")) + 1;
  return file.substr(data + std::stoull(attribute(file, at, "offset")));
}

TEST(VtuBinaryLayout, UncompressedArraysAreAUInt64ByteCountThenLittleEndianValues) {
  const FieldCase c = fieldCase();
  const std::size_t n = c.mesh.nodeCount(), e = c.mesh.tetCount();
  for (VtuFormat format : {VtuFormat::Base64, VtuFormat::Raw}) {
    const std::string path = (tempDir() / "layout.vtu").string();
    ASSERT_TRUE(corofem::writeTetMesh(path, c.mesh, c.fields, {format, VtuCompression::None}).isOk());
    const std::string file = readBytes(path);
    EXPECT_TRUE(contains(file, "header_type=\"UInt64\""));
    EXPECT_TRUE(contains(file, "byte_order=\"LittleEndian\""));
    EXPECT_FALSE(contains(file, "compressor="));
    auto bytesOf = [&](const std::string& name) {
      const std::string s = storedBytes(file, name);
      return format == VtuFormat::Base64 ? decodeBase64(s) : s;
    };
    const std::string points = bytesOf("Points");
    ASSERT_EQ(u64At(points, 0), 24 * n);
    for (std::size_t i = 0; i < 3 * n; ++i) {
      double v;
      const std::uint64_t bits = u64At(points, 8 + 8 * i);
      std::memcpy(&v, &bits, 8);
      ASSERT_EQ(v, c.mesh.nodes[i]) << "point value " << i;
    }
    const std::string conn = bytesOf("connectivity");
    ASSERT_EQ(u64At(conn, 0), 32 * e);
    for (std::size_t i = 0; i < 4 * e; ++i) ASSERT_EQ(u64At(conn, 8 + 8 * i), c.mesh.tets[i]) << "index " << i;
    const std::string offsets = bytesOf("offsets");
    ASSERT_EQ(u64At(offsets, 0), 8 * e);
    EXPECT_EQ(u64At(offsets, 8 + 8 * (e - 1)), 4 * e);
    const std::string types = bytesOf("types");
    ASSERT_EQ(u64At(types, 0), e);
    EXPECT_EQ(types.substr(8, e), std::string(e, '\x0a'));  // VTK_TETRA = 10, one byte each
    if (format == VtuFormat::Raw) {
      // The appended section ends with the last array's bytes, then a newline and the closing tags.
      const std::size_t tail = file.rfind("\n  </AppendedData>\n</VTKFile>\n");
      EXPECT_EQ(tail + std::strlen("\n  </AppendedData>\n</VTKFile>\n"), file.size());
      EXPECT_EQ(file.substr(tail - e, e), std::string(e, '\x0a'));  // types is written last
    }
  }
}

TEST(VtuBinaryLayout, ZlibArraysHaveVtksBlockTable) {
  if (!corofem::vtuZlibAvailable()) GTEST_SKIP() << "this build has no zlib; nothing compressed to check";
  const FieldCase c = fieldCase();
  const std::size_t pointBytes = 24 * c.mesh.nodeCount();  // 60984: two blocks, the last partial
  for (VtuFormat format : {VtuFormat::Base64, VtuFormat::Raw}) {
    const std::string path = (tempDir() / "zlib.vtu").string();
    ASSERT_TRUE(corofem::writeTetMesh(path, c.mesh, c.fields, {format, VtuCompression::Zlib}).isOk());
    const std::string file = readBytes(path);
    EXPECT_TRUE(contains(file, "compressor=\"vtkZLibDataCompressor\""));
    const std::string stored = storedBytes(file, "Points");
    // [nblocks][block size][last block size][compressed size] x nblocks, all UInt64.
    const std::size_t headerBytes = 8 * (3 + 2);
    const std::size_t headerChars = (headerBytes + 2) / 3 * 4;
    const std::string header = format == VtuFormat::Base64 ? decodeBase64(stored.substr(0, headerChars)) : stored;
    ASSERT_EQ(u64At(header, 0), 2u);
    EXPECT_EQ(u64At(header, 8), 32768u);
    EXPECT_EQ(u64At(header, 16), pointBytes - 32768);
    const std::uint64_t c1 = u64At(header, 24), c2 = u64At(header, 32);
    EXPECT_GT(c1, 0u);
    EXPECT_GT(c2, 0u);
    // The compressed blocks follow the header and are exactly as long as it says: in base64 the
    // blocks are one stream of their own after the header's; raw, the next array starts right after.
    if (format == VtuFormat::Base64) {
      EXPECT_EQ(decodeBase64(stored.substr(headerChars)).size(), c1 + c2);
    } else {
      const std::size_t pointsOffset = std::stoull(attribute(file, arrayTag(file, "Points"), "offset"));
      const std::size_t next = std::stoull(attribute(file, arrayTag(file, "connectivity"), "offset"));
      EXPECT_EQ(next - pointsOffset, headerBytes + c1 + c2);
    }
    // zlib streams start with 0x78 (deflate, 32 KiB window).
    const std::string firstBlock = format == VtuFormat::Base64 ? decodeBase64(stored.substr(headerChars, 8)) : stored.substr(headerBytes, 2);
    EXPECT_EQ(std::uint8_t(firstBlock[0]), 0x78u);
  }
}

TEST(VtuEncoding, BlockTableOfExactAndPartialSizes) {
  if (!corofem::vtuZlibAvailable()) GTEST_SKIP() << "this build has no zlib; nothing compressed to check";
  for (const auto& [bytes, blocks, last] : std::vector<std::tuple<std::size_t, std::uint64_t, std::uint64_t>>{
           {0, 0, 0}, {1, 1, 1}, {32768, 1, 0}, {65536, 2, 0}, {65537, 3, 1}}) {
    const std::string data(bytes, '\x5a');
    const auto p = corofem::mesh::encodeVtuArray(data, VtuCompression::Zlib, "x.vtu");
    ASSERT_EQ(p.header.size(), 8 * (3 + blocks)) << bytes;
    EXPECT_EQ(u64At(p.header, 0), blocks) << bytes;
    EXPECT_EQ(u64At(p.header, 8), corofem::mesh::kVtuBlockSize) << bytes;
    EXPECT_EQ(u64At(p.header, 16), last) << bytes;  // VTK: 0 when the last block is full
    std::uint64_t total = 0;
    for (std::uint64_t b = 0; b < blocks; ++b) total += u64At(p.header, 24 + 8 * b);
    EXPECT_EQ(total, p.data.size()) << bytes;
  }
  const auto plain = corofem::mesh::encodeVtuArray("abc", VtuCompression::None, "x.vtu");
  EXPECT_EQ(plain.header, std::string("\x03\0\0\0\0\0\0\0", 8));
  EXPECT_EQ(plain.data, "abc");
}

TEST(VtuEncoding, Base64AndLittleEndianBytes) {
  using corofem::mesh::base64;
  // RFC 4648, section 10.
  EXPECT_EQ(base64(""), "");
  EXPECT_EQ(base64("f"), "Zg==");
  EXPECT_EQ(base64("fo"), "Zm8=");
  EXPECT_EQ(base64("foo"), "Zm9v");
  EXPECT_EQ(base64("foob"), "Zm9vYg==");
  EXPECT_EQ(base64("fooba"), "Zm9vYmE=");
  EXPECT_EQ(base64("foobar"), "Zm9vYmFy");
  EXPECT_EQ(base64(std::string("\xff\xfe\x00", 3)), "//4A");
  std::string le;
  corofem::mesh::appendLittleEndian(le, std::uint32_t(0x01020304));
  corofem::mesh::appendLittleEndian(le, 1.0);
  corofem::mesh::appendLittleEndian(le, -2.0f);
  corofem::mesh::appendLittleEndian(le, std::int64_t(-2));
  EXPECT_EQ(le, std::string("\x04\x03\x02\x01"
                            "\x00\x00\x00\x00\x00\x00\xf0\x3f"
                            "\x00\x00\x00\xc0"
                            "\xfe\xff\xff\xff\xff\xff\xff\xff",
                            24));
}

// ---- ascii stays as it was; refusals ----

TEST(VtuOptions, AsciiIsTheDefaultAndWritesNoBinary) {
  const FieldCase c = fieldCase();
  const std::string a = (tempDir() / "default.vtu").string();
  ASSERT_TRUE(corofem::writeTetMesh(a, c.mesh, c.fields).isOk());
  const std::string file = readBytes(a);
  EXPECT_TRUE(contains(file, "format=\"ascii\""));
  EXPECT_FALSE(contains(file, "format=\"binary\""));
  EXPECT_FALSE(contains(file, "AppendedData"));
  EXPECT_FALSE(contains(file, "compressor"));
  // A surface without normals or texcoords has no point data; one with normals marks them active.
  corofem::SurfaceMesh s = surfaceCase(false);
  const std::string withNormals = (tempDir() / "n.vtu").string();
  ASSERT_TRUE(corofem::writeSurfaceMesh(withNormals, s).isOk());
  EXPECT_TRUE(contains(readBytes(withNormals), "<PointData Normals=\"Normals\">"));
  s.normals.clear();
  ASSERT_TRUE(corofem::writeSurfaceMesh(withNormals, s).isOk());
  EXPECT_FALSE(contains(readBytes(withNormals), "PointData"));
}

TEST(VtuOptions, ZlibWithAsciiIsRefusedNamingTheKeyAndTheFix) {
  const FieldCase c = fieldCase();
  const std::string path = (tempDir() / "z.vtu").string();
  const corofem::Status st = corofem::writeTetMesh(path, c.mesh, {}, {VtuFormat::Ascii, VtuCompression::Zlib});
  EXPECT_EQ(st.code(), corofem::ErrorCode::BadInput);
  EXPECT_TRUE(contains(st.message(), path));
  EXPECT_TRUE(contains(st.message(), "vtu_compression"));
  EXPECT_TRUE(contains(st.message(), "set output.vtu_format to \"base64\" or \"raw\""));
  EXPECT_FALSE(fs::exists(path));
}

TEST(VtuOptions, ZlibInABuildWithoutZlibIsRefusedNamingTheFix) {
  if (corofem::vtuZlibAvailable()) GTEST_SKIP() << "this build has zlib; the refusal is for builds without it";
  const FieldCase c = fieldCase();
  const std::string path = (tempDir() / "z.vtu").string();
  const corofem::Status st = corofem::writeTetMesh(path, c.mesh, {}, {VtuFormat::Raw, VtuCompression::Zlib});
  EXPECT_EQ(st.code(), corofem::ErrorCode::BadInput);
  EXPECT_TRUE(contains(st.message(), "vtu_compression"));
  EXPECT_TRUE(contains(st.message(), "install zlib1g-dev and rebuild, or use \"none\""));
  EXPECT_FALSE(fs::exists(path));
}

TEST(WriterErrors, NonFiniteValuesAreRefusedInEveryFormatAndNothingIsWritten) {
  const auto dir = tempDir();
  for (const FormatCase& f : kFormatCases) {
    if (f.options.compression == VtuCompression::Zlib && !corofem::vtuZlibAvailable()) continue;
    FieldCase c = fieldCase();
    c.mesh.nodes[7] = std::nan("");
    const std::string path = (dir / (std::string("nan_") + f.name + ".vtu")).string();
    corofem::Status st = corofem::writeTetMesh(path, c.mesh, c.fields, f.options);
    EXPECT_EQ(st.code(), corofem::ErrorCode::BadInput) << f.name;
    EXPECT_TRUE(contains(st.message(), "the position of node 2 is nan (component 1)")) << f.name;
    c = fieldCase();
    c.fields[1].values[5] = -INFINITY;
    st = corofem::writeTetMesh(path, c.mesh, c.fields, f.options);
    EXPECT_EQ(st.code(), corofem::ErrorCode::BadInput) << f.name;
    EXPECT_TRUE(contains(st.message(), "field 'von Mises' of element 5 is -inf")) << f.name;
    corofem::SurfaceMesh s = surfaceCase(false);
    s.normals[4] = NAN;
    st = corofem::writeSurfaceMesh(path, s, f.options);
    EXPECT_EQ(st.code(), corofem::ErrorCode::BadInput) << f.name;
    EXPECT_TRUE(contains(st.message(), "the normal of vertex 1 is nan (component 1)")) << f.name;
    EXPECT_FALSE(fs::exists(path)) << f.name;
  }
  corofem::SurfaceMesh s = surfaceCase(true);
  s.normals.pop_back();
  const corofem::Status st = corofem::writeSurfaceMesh((dir / "short.obj").string(), s);
  EXPECT_EQ(st.code(), corofem::ErrorCode::BadInput);
  EXPECT_TRUE(contains(st.message(), "14699 normal values for 4900 vertices; give 3 per vertex or none"));
}

// ---- OBJ normals ----

TEST(ObjNormals, OneUnitVnPerVertexAndFacesReferenceThem) {
  for (bool uv : {false, true}) {
    const corofem::SurfaceMesh s = surfaceCase(uv);
    const std::string path = (tempDir() / (uv ? "uv.obj" : "plain.obj")).string();
    ASSERT_TRUE(corofem::writeSurfaceMesh(path, s).isOk());
    std::istringstream in(readBytes(path));
    std::vector<float> vn;
    std::size_t v = 0, vt = 0, faces = 0;
    for (std::string line; std::getline(in, line);) {
      std::istringstream ls(line);
      std::string key;
      ls >> key;
      if (key == "v") ++v;
      if (key == "vt") ++vt;
      if (key == "vn") {
        float x, y, z;
        ASSERT_TRUE(ls >> x >> y >> z) << line;
        vn.insert(vn.end(), {x, y, z});
      }
      if (key == "f") {
        for (int k = 0; k < 3; ++k) {
          std::string corner;
          ASSERT_TRUE(ls >> corner) << line;
          // v//vn, or v/vt/vn with texture coordinates: the same 1-based index in every slot.
          const std::string i = std::to_string(s.triangles[3 * faces + std::size_t(k)] + 1);
          ASSERT_EQ(corner, uv ? i + "/" + i + "/" + i : i + "//" + i) << line;
        }
        ++faces;
      }
    }
    EXPECT_EQ(v, s.vertexCount());
    EXPECT_EQ(vt, uv ? s.vertexCount() : 0u);
    EXPECT_EQ(faces, s.triangleCount());
    ASSERT_EQ(vn.size(), 3 * s.vertexCount());
    EXPECT_EQ(vn, s.normals);  // shortest float decimals: the same floats
    for (std::size_t i = 0; i < s.vertexCount(); ++i)
      ASSERT_NEAR(std::hypot(vn[3 * i], vn[3 * i + 1], vn[3 * i + 2]), 1.0, 1e-6) << "vn " << i + 1;
    // Our reader still reads it (it ignores normals).
    const auto back = corofem::readSurfaceMesh(path);
    ASSERT_TRUE(back.isOk()) << back.message();
    EXPECT_EQ(back.value().vertices, s.vertices);
    EXPECT_EQ(back.value().triangles, s.triangles);
    EXPECT_EQ(back.value().texcoords, s.texcoords);
  }
}

}  // namespace
