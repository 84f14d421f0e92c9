// Regression tests of issue 27 (what fuzzing and fault injection found) for mesh reading, writing
// and generation: files that are not regular files, the input size limit, messages that quote a
// huge token, 64-bit ids and counts, a full disk, non-finite values, the box generator's limit.
// Each test names the item of the issue it covers.
#include "mesh/mesh_test_util.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <limits>

#include <sys/stat.h>

namespace {

using corofem::ErrorCode;
using corofem::test::contains;
using corofem::test::tempDir;
using corofem::test::writeTemp;
namespace fs = std::filesystem;

const std::string kGmsh = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n"
                          "$EndNodes\n$Elements\n1\n1 4 2 0 1 1 2 3 4\n$EndElements\n";

std::string tetFailure(const std::string& path, ErrorCode code = ErrorCode::BadInput,
                       const corofem::InputLimits& limits = {}) {
  auto r = corofem::readTetMesh(path, nullptr, {}, limits);
  EXPECT_FALSE(r.isOk()) << path;
  EXPECT_EQ(r.status().code(), code) << r.message();
  return r.isOk() ? std::string() : r.message();
}

// ------------------------------------------------------------------ item 4: not regular files
TEST(Issue27Item4, ADirectoryAsAMeshIsBadInputNotAnInternalError) {
  const fs::path dir = tempDir() / "looks_like.msh";
  fs::create_directories(dir);
  const std::string msg = tetFailure(dir.string());
  EXPECT_TRUE(contains(msg, "looks_like.msh"));
  EXPECT_TRUE(contains(msg, "is a directory, not a regular file"));
  fs::create_directories(dir.parent_path() / "surface.obj");
  auto surface = corofem::readSurfaceMesh((dir.parent_path() / "surface.obj").string());
  EXPECT_EQ(surface.status().code(), ErrorCode::BadInput) << surface.message();
  EXPECT_TRUE(contains(surface.message(), "is a directory"));
}

TEST(Issue27Item4, DevZeroIsRefusedBeforeAnyRead) {
  if (!fs::exists("/dev/zero")) GTEST_SKIP() << "no /dev/zero";
  const fs::path dir = tempDir();
  fs::create_symlink("/dev/zero", dir / "zero.msh");
  fs::create_symlink("/dev/zero", dir / "zero.obj");
  EXPECT_TRUE(contains(tetFailure((dir / "zero.msh").string()), "is a character device, not a regular file"));
  auto surface = corofem::readSurfaceMesh((dir / "zero.obj").string());
  EXPECT_EQ(surface.status().code(), ErrorCode::BadInput) << surface.message();
}

TEST(Issue27Item4, AFifoIsRefusedWithoutBlocking) {
  const fs::path dir = tempDir();
  const std::string fifo = (dir / "pipe.msh").string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0) << std::strerror(errno);
  // No writer: opening it for reading the usual way would wait forever.
  EXPECT_TRUE(contains(tetFailure(fifo), "is a FIFO (a named pipe), not a regular file"));
  // TetGen reads two files: a FIFO as the .ele beside a good .node.
  writeTemp(dir, "t.node", "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n");
  ASSERT_EQ(::mkfifo((dir / "t.ele").string().c_str(), 0600), 0);
  EXPECT_TRUE(contains(tetFailure((dir / "t.node").string()), "t.ele: it is a FIFO"));
}

TEST(Issue27Item4, TheInputSizeLimitHoldsAndCanBeRaised) {
  const fs::path dir = tempDir();
  const std::string path = writeTemp(dir, "small.msh", kGmsh);  // 129 bytes
  corofem::InputLimits limits;
  EXPECT_EQ(limits.maxInputBytes, std::uint64_t(1) << 30);  // the defaults
  EXPECT_EQ(limits.maxSceneBytes, std::uint64_t(16) << 20);
  EXPECT_EQ(limits.maxBoxTets, 50'000'000u);
  limits.maxInputBytes = 100;
  {
    const std::string msg = tetFailure(path, ErrorCode::BadInput, limits);
    EXPECT_TRUE(
        contains(msg, "small.msh: it has 129 bytes, more than the limit of 100 bytes (InputLimits::maxInputBytes)"))
        << msg;
    EXPECT_TRUE(contains(msg, "raise the limit: InputLimits::maxInputBytes (C API: "
                              "corofem_input_limits.max_input_bytes; the corofem command: --max-input-bytes, "
                              "e.g. --max-input-bytes 4G)"))
        << msg;
  }
  // Every reader: TetGen reads its two files under the limit, OBJ surfaces too.
  writeTemp(dir, "t.node", "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n");
  writeTemp(dir, "t.ele", "1 4 0\n1 1 2 3 4\n" + std::string(200, '#') + "\n");
  limits.maxInputBytes = 100;
  EXPECT_TRUE(contains(tetFailure((dir / "t.node").string(), ErrorCode::BadInput, limits), "t.ele: it has "));
  const std::string obj = writeTemp(dir, "s.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n" + std::string(200, '#'));
  auto surface = corofem::readSurfaceMesh(obj, nullptr, limits);
  EXPECT_EQ(surface.status().code(), ErrorCode::BadInput) << surface.message();
  EXPECT_TRUE(contains(surface.message(), "more than the limit of 100 bytes")) << surface.message();
  limits.maxInputBytes = 1024;  // raised
  EXPECT_TRUE(corofem::readTetMesh(path, nullptr, {}, limits).isOk());
  EXPECT_TRUE(corofem::readTetMesh((dir / "t.node").string(), nullptr, {}, limits).isOk());
  EXPECT_TRUE(corofem::readSurfaceMesh(obj, nullptr, limits).isOk());
  EXPECT_TRUE(corofem::readTetMesh(path).isOk());  // the default: 1 GiB
  // At the limit exactly is allowed.
  limits.maxInputBytes = 129;
  EXPECT_TRUE(corofem::readTetMesh(path, nullptr, {}, limits).isOk());
  limits.maxInputBytes = 128;
  EXPECT_FALSE(corofem::readTetMesh(path, nullptr, {}, limits).isOk());
}

// ------------------------------------------------------------------ item 5: bounded messages
TEST(Issue27Item5, AHugeTokenGivesAShortMessageInEveryReader) {
  const std::string big(1 << 20, 'x');  // 1 MiB
  const fs::path dir = tempDir();
  struct Case {
    const char* file;
    std::string text;
  };
  const Case cases[] = {
      {"section.msh", "$" + big + "\n"},                                   // "section $x... has no $Endx..."
      {"word.msh", big + "\n"},                                           // "expected a section header"
      {"end.msh", "$MeshFormat\n2.2 0 8\n" + big + "\n"},                 // "expected $EndMeshFormat"
      {"keyword.vtk", "# vtk DataFile Version 3.0\nt\nASCII\n" + big + "\n"},
      {"dataset.vtk", "# vtk DataFile Version 3.0\nt\nASCII\nDATASET " + big + "\n"},
      {"encoding.vtk", "# vtk DataFile Version 3.0\nt\n" + big + "\n"},
      {"scalars.vtk", "# vtk DataFile Version 3.0\nt\nASCII\nCELL_DATA 1\nSCALARS " + big + " int 9\n"},
      {"section.veg", big + "\n"},
      {"type.veg", "*ELEMENTS\n" + big + "\n"},
      {"keyword.mesh", "MeshVersionFormatted 1\n" + big + "\n"},
      {"trailing.node", "1 3 0 0\n1 0 0 0\n" + big + "\n"},
  };
  for (const Case& c : cases) {
    const std::string msg = tetFailure(writeTemp(dir, c.file, c.text));
    EXPECT_TRUE(contains(msg, c.file));
    EXPECT_LT(msg.size(), 1000u) << c.file << ": " << msg.substr(0, 300);
  }
  auto obj = corofem::readSurfaceMesh(writeTemp(dir, "corner.obj", "v 0 0 0\nf 1/" + big + "\n"));
  ASSERT_FALSE(obj.isOk());
  EXPECT_EQ(obj.status().code(), ErrorCode::BadInput);
  EXPECT_LT(obj.message().size(), 1000u) << obj.message().substr(0, 300);
}

// ------------------------------------------------------------------ item 6: 64-bit ids and counts
// The sums and differences of ids at the 64-bit limits overflowed (undefined behaviour, reported by
// the sanitizer job's UndefinedBehaviorSanitizer; a plain build happened to compute the same).
TEST(Issue27Item6, NodeIdsAtThe64BitLimitsMapCorrectly) {
  const fs::path dir = tempDir();
  auto gmsh = [](const std::string& ids, const std::string& element) {
    std::string nodes;
    std::size_t start = 0;
    const char* xyz[] = {" 0 0 0\n", " 1 0 0\n", " 0 1 0\n", " 0 0 1\n"};
    for (int k = 0; k < 4; ++k) {
      const std::size_t stop = ids.find(' ', start);
      nodes += ids.substr(start, stop - start) + xyz[k];
      start = stop + 1;
    }
    return "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n" + nodes + "$EndNodes\n$Elements\n1\n1 4 2 0 1 " +
           element + "\n$EndElements\n";
  };
  // Consecutive up to INT64_MAX, then more ids: the "consecutive" test's ids[0] + i overflowed.
  const std::string a = "9223372036854775806 9223372036854775807 1 2 ";
  auto ma = corofem::readTetMesh(writeTemp(dir, "a.msh", gmsh(a, "9223372036854775806 9223372036854775807 1 2")));
  ASSERT_TRUE(ma.isOk()) << ma.message();
  EXPECT_EQ(ma->tetCount(), 1u);
  // Ids spanning the whole range: max - min overflowed.
  const std::string b = "-9223372036854775808 9223372036854775807 0 1 ";
  auto mb = corofem::readTetMesh(writeTemp(dir, "b.msh", gmsh(b, "-9223372036854775808 9223372036854775807 0 1")));
  ASSERT_TRUE(mb.isOk()) << mb.message();
  // Consecutive ids 1..4 and an element naming INT64_MIN: id - base overflowed.
  const std::string msg = tetFailure(writeTemp(dir, "c.msh", gmsh("1 2 3 4 ", "1 2 3 -9223372036854775808")));
  EXPECT_TRUE(contains(msg, "refers to node -9223372036854775808, but the file defines nodes 1..4"));
  // Consecutive ids ending at INT64_MAX: the message's range end is exact.
  const std::string d = "9223372036854775804 9223372036854775805 9223372036854775806 9223372036854775807 ";
  EXPECT_TRUE(contains(tetFailure(writeTemp(dir, "d.msh", gmsh(d, "9223372036854775804 9223372036854775805 "
                                                                   "9223372036854775806 5"))),
                       "the file defines nodes 9223372036854775804..9223372036854775807"));
}

TEST(Issue27Item6, ATetGenAttributeCountAtTheLimitIsAnError) {
  // attributes + markers overflowed to a negative count: no attribute was read and the header
  // announcing 2^63 - 1 attributes per node was accepted.
  const fs::path dir = tempDir();
  writeTemp(dir, "t.node", "4 3 9223372036854775807 1\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n");
  writeTemp(dir, "t.ele", "1 4 0\n1 1 2 3 4\n");
  const std::string msg = tetFailure((dir / "t.node").string());
  EXPECT_TRUE(contains(msg, "t.node line 2"));
  EXPECT_TRUE(contains(msg, "a value is missing"));
  // A region attribute beyond the 32-bit region ids is an error, not a wrapped id.
  writeTemp(dir, "r.node", "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n");
  writeTemp(dir, "r.ele", "1 4 1\n1 1 2 3 4 1e300\n");
  EXPECT_TRUE(contains(tetFailure((dir / "r.ele").string()), "region attribute 1e+300"));
}

// ------------------------------------------------------------------ item 3: a full disk
TEST(Issue27Item3, AFullDiskIsReportedAsSuchByTheMeshWriters) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  const fs::path dir = tempDir();
  const auto mesh = corofem::test::loadTet(writeTemp(dir, "ok.msh", kGmsh));
  // Writers go through "<path>.tmp"; that name leading to /dev/full makes every write ENOSPC.
  for (const char* name : {"full.vtu", "full.msh", "full.vtk"}) {
    fs::create_symlink("/dev/full", dir / (std::string(name) + ".tmp"));
    errno = 0;  // a stale errno used to be reported ("Success", "No such file or directory")
    const corofem::Status st = corofem::writeTetMesh((dir / name).string(), mesh);
    EXPECT_EQ(st.code(), ErrorCode::IoError) << name;
    EXPECT_TRUE(contains(st.message(), std::string(name) + ": " + std::strerror(ENOSPC)));
    EXPECT_FALSE(fs::exists(dir / name)) << "nothing is renamed into place after a failed write";
  }
}

// ------------------------------------------------------------------ item 8: no NaN or inf in files
TEST(Issue27Item8, WritersRefuseNonFiniteValues) {
  const fs::path dir = tempDir();
  auto mesh = corofem::test::loadTet(writeTemp(dir, "ok.msh", kGmsh));
  corofem::TetMesh nanMesh = mesh;
  nanMesh.nodes[4] = std::numeric_limits<double>::quiet_NaN();
  for (const char* name : {"n.vtu", "n.vtk", "n.msh", "n.mesh", "n.node", "n.veg"}) {
    const corofem::Status st = corofem::writeTetMesh((dir / name).string(), nanMesh);
    EXPECT_EQ(st.code(), ErrorCode::BadInput) << name;
    EXPECT_TRUE(contains(st.message(), "node 1 is nan (component 1)")) << name;
  }
  const corofem::MeshField field{"speed", 1, false, {0, 1, std::numeric_limits<double>::infinity(), 3}};
  const corofem::Status st = corofem::writeTetMesh((dir / "f.vtu").string(), mesh, {field});
  EXPECT_EQ(st.code(), ErrorCode::BadInput);
  EXPECT_TRUE(contains(st.message(), "field 'speed' of node 2 is inf"));
  EXPECT_FALSE(fs::exists(dir / "f.vtu"));
}

TEST(Issue27Item8, ObjTextureCoordinatesMustBeFiniteFloats) {
  // 1e300 became an infinite float texcoord, written back as "inf" by `corofem convert`.
  auto r = corofem::readSurfaceMesh(
      writeTemp(tempDir(), "uv.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1e300 0\nvt 0 1\nf 1/1 2/2 3/3\n"));
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(contains(r.message(), "uv.obj line 5: texture coordinate 2 has the value 1e+300"));
}

// ------------------------------------------------------------------ item 9: the box generator's limit
TEST(Issue27Item9, AHugeBoxIsBadInputNamingTheLimit) {
  corofem::BoxSpec spec;
  spec.cells = {1000, 1000, 200};  // 1e9 tetrahedra: "internal error: out of memory" before
  auto r = corofem::generateBox(spec);
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::BadInput) << r.message();
  EXPECT_TRUE(contains(r.message(), "1000 x 1000 x 200 cells of 5 tetrahedra give 1000000000 tetrahedra, more "
                                    "than the limit of 50000000 (InputLimits::maxBoxTets, the default); use fewer "
                                    "cells, or raise the limit if the machine has the memory: InputLimits::maxBoxTets "
                                    "(C API: corofem_input_limits.max_box_tets; the corofem command: --max-box-tets"))
      << r.message();
  corofem::InputLimits limits;
  limits.maxBoxTets = 100;
  spec.cells = {2, 2, 2};  // 40
  EXPECT_TRUE(corofem::generateBox(spec, limits).isOk());
  spec.cells = {3, 3, 3};  // 135
  EXPECT_TRUE(
      contains(corofem::generateBox(spec, limits).message(), "more than the limit of 100 (InputLimits::maxBoxTets)"));
  EXPECT_TRUE(corofem::generateBox(spec).isOk());  // the default
}

}  // namespace
