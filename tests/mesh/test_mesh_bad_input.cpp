// Bad input: every validation error and malformed-file path, with its message checked (file name,
// line, element or node), plus small inline files for reader details the shared meshes do not cover.
#include "mesh/mesh_test_util.hpp"

#include <set>

namespace {

using corofem::ErrorCode;
using corofem::test::contains;
using corofem::test::tempDir;
using corofem::test::writeTemp;

std::string gmsh22(const std::string& nodes, const std::string& elements) {
  return "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n" + nodes + "$EndNodes\n$Elements\n" + elements +
         "$EndElements\n";
}

const std::string kFourNodes = "4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n";  // lines 5-9

/// Reads and expects failure with the code; returns the message.
std::string failure(const std::string& path, ErrorCode code = ErrorCode::BadInput) {
  auto r = corofem::readTetMesh(path);
  EXPECT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), code) << r.message();
  return r.isOk() ? std::string() : r.message();
}

TEST(BadInput, GoodInlineGmshLoads) {  // the base file the cases below break
  const auto path = writeTemp(tempDir(), "ok.msh", gmsh22(kFourNodes, "1\n1 4 2 0 1 1 2 3 4\n"));
  const auto mesh = corofem::test::loadTet(path);
  EXPECT_EQ(mesh.nodeCount(), 4u);
  EXPECT_EQ(mesh.tetCount(), 1u);
  EXPECT_NEAR(corofem::signedVolume(mesh, 0), 1.0 / 6.0, 1e-15);
}

TEST(BadInput, TruncatedNodeList) {
  // Long enough that 4 nodes could fit in the remaining bytes (so the count check passes), but
  // the file stops after node 2.
  const auto path = writeTemp(tempDir(), "trunc.msh",
                              "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0.000000 0.000000 0.000000\n"
                              "2 1.000000 0.000000 0.000000\n");
  const std::string msg = failure(path);
  EXPECT_TRUE(contains(msg, "trunc.msh"));
  EXPECT_TRUE(contains(msg, "line 8"));  // the end of the file, after line 7's newline
  EXPECT_TRUE(contains(msg, "node 3 of 4"));
  EXPECT_TRUE(contains(msg, "truncated"));
}

TEST(BadInput, TruncatedInsideAnElementLine) {
  const auto path = writeTemp(tempDir(), "cut.msh",
                              "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n" + kFourNodes +
                                  "$EndNodes\n$Elements\n1\n1 4 2 0 1 1 2 3");
  const std::string msg = failure(path);
  EXPECT_TRUE(contains(msg, "cut.msh line 13"));
  EXPECT_TRUE(contains(msg, "element 1 of 1"));
  EXPECT_TRUE(contains(msg, "truncated"));
}

TEST(BadInput, NanCoordinateNamesTheNode) {
  const auto path = writeTemp(tempDir(), "nan.msh",
                              gmsh22("4\n1 0 0 0\n2 1 0 0\n3 0 nan 0\n4 0 0 1\n", "1\n1 4 2 0 1 1 2 3 4\n"));
  const std::string msg = failure(path);
  EXPECT_TRUE(contains(msg, "nan.msh line 8"));
  EXPECT_TRUE(contains(msg, "node 3 has a non-finite y coordinate"));
}

TEST(BadInput, InfiniteAndOverflowingCoordinates) {
  const auto inf = writeTemp(tempDir(), "inf.mesh",
                             "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 inf 0\n"
                             "Tetrahedra\n1\n1 2 3 4 1\nEnd\n");
  std::string msg = failure(inf);
  EXPECT_TRUE(contains(msg, "inf.mesh line 8"));
  EXPECT_TRUE(contains(msg, "node 4 has a non-finite z coordinate"));
  const auto big = writeTemp(tempDir(), "big.mesh",
                             "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 0\n1e999 0 0 0\n0 1 0 0\n0 0 1 0\n"
                             "Tetrahedra\n1\n1 2 3 4 1\nEnd\n");
  msg = failure(big);
  EXPECT_TRUE(contains(msg, "big.mesh line 6"));
  EXPECT_TRUE(contains(msg, "vertex 2 of 4"));
  EXPECT_TRUE(contains(msg, "1e999"));
}

TEST(BadInput, OutOfRangeNodeIndex) {
  const auto path = writeTemp(tempDir(), "range.msh", gmsh22(kFourNodes, "2\n1 4 2 0 1 1 2 3 4\n2 4 2 0 1 1 2 3 9\n"));
  const std::string msg = failure(path);
  EXPECT_TRUE(contains(msg, "range.msh line 14"));
  EXPECT_TRUE(contains(msg, "element 2"));
  EXPECT_TRUE(contains(msg, "refers to node 9"));
  EXPECT_TRUE(contains(msg, "nodes 1..4"));
}

TEST(BadInput, OutOfRangeInZeroBasedVtk) {
  const auto path = writeTemp(tempDir(), "range.vtk",
                              "# vtk DataFile Version 2.0\nt\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 double\n"
                              "0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 1 5\n4 0 1 2 4\nCELL_TYPES 1\n10\n");
  const std::string msg = failure(path);
  EXPECT_TRUE(contains(msg, "range.vtk line 8"));
  EXPECT_TRUE(contains(msg, "cell 0"));
  EXPECT_TRUE(contains(msg, "refers to node 4"));
  EXPECT_TRUE(contains(msg, "nodes 0..3"));
}

TEST(BadInput, RepeatedNodeInAnElement) {
  const auto path = writeTemp(tempDir(), "repeat.msh", gmsh22(kFourNodes, "1\n7 4 2 0 1 1 2 2 4\n"));
  const std::string msg = failure(path);
  EXPECT_TRUE(contains(msg, "repeat.msh line 13"));
  EXPECT_TRUE(contains(msg, "element 7"));
  EXPECT_TRUE(contains(msg, "uses node 2 twice"));
}

TEST(BadInput, ZeroVolumeElement) {
  // Nodes 1-4 coplanar (z = 0).
  const auto path = writeTemp(tempDir(), "flat.msh",
                              gmsh22("4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 1 1 0\n", "1\n5 4 2 0 1 1 2 3 4\n"));
  const std::string msg = failure(path);
  EXPECT_TRUE(contains(msg, "flat.msh line 13"));
  EXPECT_TRUE(contains(msg, "element 5"));
  EXPECT_TRUE(contains(msg, "zero volume"));
  EXPECT_TRUE(contains(msg, "(nodes 1, 2, 3, 4)"));
}

TEST(BadInput, NearZeroVolumeRelativeToTheMean) {
  // Element 2 is 1e-14 as tall as element 1: below the default 1e-12 of the mean.
  const auto path = writeTemp(tempDir(), "sliver.msh",
                              gmsh22("5\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 0 0 1e-14\n",
                                     "2\n1 4 2 0 1 1 2 3 4\n2 4 2 0 1 1 2 3 5\n"));
  const std::string msg = failure(path);
  EXPECT_TRUE(contains(msg, "sliver.msh line 15"));
  EXPECT_TRUE(contains(msg, "element 2"));
  EXPECT_TRUE(contains(msg, "near-zero volume"));
  // With the relative test off the same file loads.
  corofem::MeshValidation lax;
  lax.minRelativeVolume = 0;
  EXPECT_TRUE(corofem::readTetMesh(path, nullptr, lax).isOk());
}

TEST(BadInput, WrongHeaders) {
  const auto dir = tempDir();
  std::string msg = failure(writeTemp(dir, "v3.msh", "$MeshFormat\n3.0 0 8\n$EndMeshFormat\n"));
  EXPECT_TRUE(contains(msg, "v3.msh line 2"));
  EXPECT_TRUE(contains(msg, "version 3"));
  msg = failure(writeTemp(dir, "bin.msh", "$MeshFormat\n2.2 1 8\n$EndMeshFormat\n"));
  EXPECT_TRUE(contains(msg, "binary"));
  msg = failure(writeTemp(dir, "text.msh", "hello world\n"));
  EXPECT_TRUE(contains(msg, "text.msh line 1"));
  EXPECT_TRUE(contains(msg, "'hello'"));
  msg = failure(writeTemp(dir, "bad.vtk", "# not vtk\n"));
  EXPECT_TRUE(contains(msg, "bad.vtk line"));
  EXPECT_TRUE(contains(msg, "vtk DataFile Version"));
  msg = failure(writeTemp(dir, "poly.vtk", "# vtk DataFile Version 2.0\nt\nASCII\nDATASET POLYDATA\n"));
  EXPECT_TRUE(contains(msg, "poly.vtk line 4"));
  EXPECT_TRUE(contains(msg, "UNSTRUCTURED_GRID"));
  msg = failure(writeTemp(dir, "flat.node", "3 2 0 0\n1 0 0\n2 1 0\n3 0 1\n"));
  EXPECT_TRUE(contains(msg, "flat.node line 1"));
  EXPECT_TRUE(contains(msg, "dimension 2"));
  msg = failure(writeTemp(dir, "d2.mesh", "MeshVersionFormatted 2\nDimension 2\n"));
  EXPECT_TRUE(contains(msg, "d2.mesh line 2"));
  msg = failure(writeTemp(dir, "hex.veg", "*VERTICES\n1 3 0 0\n1 0 0 0\n*ELEMENTS\nCUBIC\n"));
  EXPECT_TRUE(contains(msg, "hex.veg line 5"));
  EXPECT_TRUE(contains(msg, "CUBIC"));
}

// A header announcing 2e9 entries in a tiny file must fail at once, naming the count, instead of
// reserving memory for it (2e9 nodes would be 48 GB).
TEST(BadInput, HugeAnnouncedCountFailsFastWithoutAllocating) {
  const auto dir = tempDir();
  struct Case { const char* name; std::string text; const char* line; };
  const Case cases[] = {
      {"huge.msh", "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n2000000000\n1 0 0 0\n", "line 5"},
      {"huge41.msh", "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 2000000000 1 2000000000\n", "line 5"},
      {"huge.node", "2000000000 3 0 0\n1 0 0 0\n", "line 1"},
      {"huge.mesh", "MeshVersionFormatted 2\nDimension 3\nVertices\n2000000000\n0 0 0 0\n", "line 4"},
      {"huge.vtk", "# vtk DataFile Version 2.0\nt\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 2000000000 float\n0 0 0\n",
       "line 5"},
      {"huge.veg", "*VERTICES\n2000000000 3 0 0\n1 0 0 0\n", "line 2"},
  };
  for (const Case& c : cases) {
    const std::string msg = failure(writeTemp(dir, c.name, c.text));
    EXPECT_TRUE(contains(msg, std::string(c.name) + " " + c.line));
    EXPECT_TRUE(contains(msg, "announces 2000000000"));
    EXPECT_TRUE(contains(msg, "truncated or the count is wrong"));
  }
  // Elements too: a Gmsh element count after valid nodes.
  const std::string msg = failure(writeTemp(dir, "hugeel.msh", gmsh22(kFourNodes, "2000000000\n1 4 2 0 1 1 2 3 4\n")));
  EXPECT_TRUE(contains(msg, "hugeel.msh line 12"));
  EXPECT_TRUE(contains(msg, "announces 2000000000 elements"));
}

TEST(BadInput, UnknownExtensionListsTheSupportedOnes) {
  const auto path = writeTemp(tempDir(), "part.stl", "solid x\n");
  const std::string msg = failure(path);
  EXPECT_TRUE(contains(msg, "part.stl"));
  for (const char* ext : {".msh", ".node", ".ele", ".mesh", ".vtk", ".veg"}) EXPECT_TRUE(contains(msg, ext));
  auto s = corofem::readSurfaceMesh(path);
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(contains(s.message(), ".obj"));
}

TEST(BadInput, MissingFileIsAnIoErrorNamingThePath) {
  const std::string path = (tempDir() / "nowhere" / "absent.msh").string();
  const std::string msg = failure(path, ErrorCode::IoError);
  EXPECT_TRUE(contains(msg, path));
  auto s = corofem::readSurfaceMesh((tempDir() / "absent.obj").string());
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.status().code(), ErrorCode::IoError);
  EXPECT_TRUE(contains(s.message(), "absent.obj"));
}

TEST(BadInput, MissingTetGenCompanionFile) {
  const auto path = writeTemp(tempDir(), "lonely.node", "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n");
  const std::string msg = failure(path, ErrorCode::IoError);
  EXPECT_TRUE(contains(msg, "lonely.ele"));
}

TEST(BadInput, DuplicateNodeIdAndMalformedNumber) {
  const auto dir = tempDir();
  std::string msg = failure(writeTemp(dir, "dup.msh", gmsh22("4\n1 0 0 0\n2 1 0 0\n2 0 1 0\n4 0 0 1\n", "1\n1 4 2 0 1 1 2 3 4\n")));
  EXPECT_TRUE(contains(msg, "dup.msh line 8"));
  EXPECT_TRUE(contains(msg, "node 2 is defined twice (first on line 7)"));
  msg = failure(writeTemp(dir, "word.msh", gmsh22("4\n1 0 0 0\n2 1 x 0\n3 0 1 0\n4 0 0 1\n", "1\n1 4 2 0 1 1 2 3 4\n")));
  EXPECT_TRUE(contains(msg, "word.msh line 7"));
  EXPECT_TRUE(contains(msg, "found 'x'"));
  msg = failure(writeTemp(dir, "short.msh", gmsh22("4\n1 0 0 0\n2 1 0\n3 0 1 0\n4 0 0 1\n", "1\n1 4 2 0 1 1 2 3 4\n")));
  EXPECT_TRUE(contains(msg, "short.msh line 7"));
  EXPECT_TRUE(contains(msg, "a value is missing"));
}

TEST(BadInput, ObjFaceIndexOutOfRangeAndNanVertex) {
  const auto dir = tempDir();
  auto r = corofem::readSurfaceMesh(writeTemp(dir, "bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n"));
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(contains(r.message(), "bad.obj line 5"));
  EXPECT_TRUE(contains(r.message(), "vertex 4"));
  r = corofem::readSurfaceMesh(writeTemp(dir, "nan.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n"));
  ASSERT_FALSE(r.isOk());
  EXPECT_TRUE(contains(r.message(), "nan.obj line 2"));
  EXPECT_TRUE(contains(r.message(), "node 2 has a non-finite y coordinate"));
  r = corofem::readSurfaceMesh(writeTemp(dir, "zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"));
  ASSERT_FALSE(r.isOk());
  EXPECT_TRUE(contains(r.message(), "zero.obj line 4"));
  EXPECT_TRUE(contains(r.message(), "start at 1"));
}

TEST(BadInput, NoTetrahedraAtAll) {
  const auto path = writeTemp(tempDir(), "tri.msh", gmsh22(kFourNodes, "1\n1 2 2 0 1 1 2 3\n"));
  const std::string msg = failure(path);
  EXPECT_TRUE(contains(msg, "tri.msh"));
  EXPECT_TRUE(contains(msg, "no tetrahedra"));
  EXPECT_TRUE(contains(msg, "1 non-tetrahedral"));
}

// ---- reader details on small inline files ----

TEST(InlineReaders, Gmsh41SkipsOtherTypesCountsThemAndMapsSparseTags) {
  // Nodes with tags 10, 20, 30, 40, 1000 (non-consecutive), one triangle block, one tet block.
  const std::string text =
      "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n"
      "$Entities\n0 0 1 1\n1 0 0 0 1 1 0 0\n1 0 0 0 1 1 1 0 1 1\n$EndEntities\n"
      "$Nodes\n2 5 10 1000\n2 1 0 4\n10\n20\n30\n40\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
      "3 7 1 1\n1000\n1 1 1 0.5 0.5 0.5\n$EndNodes\n"
      "$Elements\n2 3 1 3\n2 1 2 2\n1 10 20 30\n2 10 20 40\n3 7 4 1\n3 10 30 20 1000\n$EndElements\n";
  corofem::MeshReadReport report;
  const auto mesh = corofem::test::loadTet(writeTemp(tempDir(), "mixed41.msh", text), &report);
  EXPECT_EQ(report.format, "gmsh 4.1");
  EXPECT_EQ(mesh.nodeCount(), 5u);
  ASSERT_EQ(mesh.tetCount(), 1u);
  EXPECT_EQ(report.skippedElements, 2u);
  EXPECT_EQ(report.skippedByType.at("triangle (gmsh type 2)"), 2u);
  // Tet "10 30 20 1000" is negative (x, z swapped order); it is reoriented and counted.
  EXPECT_EQ(report.reorientedElements, 1u);
  std::multiset<std::uint32_t> nodes(mesh.tets.begin(), mesh.tets.end());
  EXPECT_EQ(nodes, (std::multiset<std::uint32_t>{0, 1, 2, 4}));
  EXPECT_GT(corofem::signedVolume(mesh, 0), 0.0);
  EXPECT_EQ(mesh.regions, std::vector<std::int32_t>{7});  // the volume entity tag
}

TEST(InlineReaders, Gmsh22MixedTypesAndPhysicalRegions) {
  corofem::MeshReadReport report;
  const auto mesh = corofem::test::loadTet(
      writeTemp(tempDir(), "mixed22.msh",
                gmsh22(kFourNodes, "3\n1 15 2 0 1 1\n2 2 2 0 1 1 2 3\n3 4 2 5 9 1 2 3 4\n")),
      &report);
  EXPECT_EQ(report.skippedByType.at("point (gmsh type 15)"), 1u);
  EXPECT_EQ(report.skippedByType.at("triangle (gmsh type 2)"), 1u);
  EXPECT_EQ(mesh.regions, std::vector<std::int32_t>{5});
}

TEST(InlineReaders, Vtk51OffsetsConnectivitySkipsTrianglesAndKeepsMatId) {
  const std::string text =
      "# vtk DataFile Version 5.1\nmeshio\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 5 double\n"
      "0 0 0 1 0 0 0 1 0 0 0 1 1 1 1\n"
      "CELLS 4 11\nOFFSETS vtktypeint64\n0 4 7 11\nCONNECTIVITY vtktypeint64\n0 1 2 3\n0 1 2\n1 2 3 4\n"
      "CELL_TYPES 3\n10\n5\n10\n"
      "POINT_DATA 5\nFIELD FieldData 1\nnode_groups 1 5 vtktypeint64\n0 0 0 0 0\n"
      "CELL_DATA 3\nSCALARS other double\nLOOKUP_TABLE default\n1.5 2.5 3.5\n"
      "FIELD FieldData 1\nmat_id 1 3 vtktypeint64\n7 8 9\n";
  corofem::MeshReadReport report;
  const auto mesh = corofem::test::loadTet(writeTemp(tempDir(), "v51.vtk", text), &report);
  EXPECT_EQ(report.format, "vtk legacy 5.1");
  ASSERT_EQ(mesh.tetCount(), 2u);
  EXPECT_EQ(report.skippedByType.at("triangle (vtk cell type 5)"), 1u);
  EXPECT_EQ(mesh.regions, (std::vector<std::int32_t>{7, 9}));
}

TEST(InlineReaders, ObjIndexFormsNegativeIndicesPolygonsAndTexcoords) {
  const std::string text =
      "# comment\r\nv 0 0 0\r\nv 1 0 0\r\nv 1 1 0\r\nv 0 1 0\r\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
      "g quad\nusemtl m\nf 1/1/1 2/2/1 3/3/1 4/4/1\nv 0 0 1\nf -5//1 -4//1 -1//1\nf 5 2 1\n";
  corofem::MeshReadReport report;
  auto r = corofem::readSurfaceMesh(writeTemp(tempDir(), "forms.obj", text), &report);
  ASSERT_TRUE(r.isOk()) << r.message();
  const auto& s = r.value();
  EXPECT_EQ(s.vertexCount(), 5u);
  EXPECT_EQ(s.triangles, (std::vector<std::uint32_t>{0, 1, 2, 0, 2, 3, 0, 1, 4, 4, 1, 0}));
  EXPECT_EQ(report.splitPolygons, 1u);
  EXPECT_TRUE(s.texcoords.empty());  // vertex 5 has corners without vt: not consistent

  auto uv = corofem::readSurfaceMesh(
      writeTemp(tempDir(), "uv.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.25 0.5\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"));
  ASSERT_TRUE(uv.isOk()) << uv.message();
  EXPECT_EQ(uv.value().texcoords, (std::vector<float>{0.25f, 0.5f, 1, 0, 0, 1}));
}

TEST(InlineReaders, VegToleratesMaterialsSetsAndComments) {
  const std::string text =
      "# Vega mesh file.\n\n*VERTICES\n4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n# a comment\n"
      "*ELEMENTS\nTET\n1 4 0\n1 1 2 3 4\n\n*MATERIAL BODY\nENU, 1000, 1e7, 0.45\n\n*SET mine\n1,\n\n*REGION\n"
      "allElements, BODY\n";
  const auto mesh = corofem::test::loadTet(writeTemp(tempDir(), "t.veg", text));
  EXPECT_EQ(mesh.tetCount(), 1u);
  EXPECT_TRUE(mesh.regions.empty());
}

TEST(InlineReaders, MeditSkipsOtherSectionsAndCountsThem) {
  const std::string text =
      "MeshVersionFormatted 1\nDimension\n3\nVertices\n4\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n"
      "Triangles\n2\n1 2 3 1\n1 2 4 1\nCorners\n1\n1\nTetrahedra\n1\n1 2 3 4 3\nEnd\n";
  corofem::MeshReadReport report;
  const auto mesh = corofem::test::loadTet(writeTemp(tempDir(), "t.mesh", text), &report);
  EXPECT_EQ(mesh.tetCount(), 1u);
  EXPECT_EQ(mesh.regions, std::vector<std::int32_t>{3});
  EXPECT_EQ(report.skippedByType.at("Triangles (medit)"), 2u);
}

TEST(InlineReaders, TetGenMinimalFilesWithoutFinalNewlineAndZeroBasedRegions) {
  const auto dir = tempDir();
  // Single-digit entries and no final newline: exactly at the minimal size the count check allows.
  writeTemp(dir, "min.node", "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1");
  writeTemp(dir, "min.ele", "1 4 0\n1 1 2 3 4");
  const auto mesh = corofem::test::loadTet((dir / "min.ele").string());
  EXPECT_EQ(mesh.tetCount(), 1u);
  // 0-based, comments, a boundary marker column and a region attribute.
  writeTemp(dir, "z.node", "# header next\n5 3 0 1\n0 0 0 0 1\n1 1 0 0 1\n2 0 1 0 1\n3 0 0 1 1\n4 1 1 1 0 # last\n");
  writeTemp(dir, "z.ele", "2 4 1\n0 0 1 2 3 -2\n1 1 2 3 4 7\n");
  corofem::MeshReadReport report;
  const auto z = corofem::test::loadTet((dir / "z.node").string(), &report);
  EXPECT_EQ(report.format, "tetgen");
  EXPECT_EQ(z.tetCount(), 2u);
  EXPECT_EQ(z.regions, (std::vector<std::int32_t>{-2, 7}));
  std::multiset<std::uint32_t> second(z.tets.begin() + 4, z.tets.end());
  EXPECT_EQ(second, (std::multiset<std::uint32_t>{1, 2, 3, 4}));
}

TEST(InlineReaders, Gmsh1SkipsNonTetElements) {
  const std::string text =
      "$NOD\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$ENDNOD\n$ELM\n2\n1 2 1 1 3 1 2 3\n2 4 3 1 4 1 2 3 4\n$ENDELM\n";
  corofem::MeshReadReport report;
  const auto mesh = corofem::test::loadTet(writeTemp(tempDir(), "v1.msh", text), &report);
  EXPECT_EQ(report.format, "gmsh 1");
  EXPECT_EQ(mesh.tetCount(), 1u);
  EXPECT_EQ(report.skippedByType.at("triangle (gmsh type 2)"), 1u);
  EXPECT_EQ(mesh.regions, std::vector<std::int32_t>{3});
}

}  // namespace
