// Robustness: real files truncated at random places or with random bytes replaced must load or fail
// with BadInput naming the file, never crash, never report an internal error. Deterministic seeds.
#include "mesh/mesh_test_util.hpp"

#include <fstream>
#include <random>
#include <sstream>

namespace {

using corofem::test::dataPath;

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// One mutation: truncate, overwrite a byte, delete a line, or duplicate a line.
std::string mutate(const std::string& text, std::mt19937& rng) {
  std::string s = text;
  std::uniform_int_distribution<std::size_t> pos(0, s.size() - 1);
  static const char kBytes[] = "0123456789-+.eE \n\t$*#/abcnNaIf";
  std::uniform_int_distribution<std::size_t> byte(0, sizeof kBytes - 2);
  switch (rng() % 4) {
    case 0: s.resize(pos(rng)); break;
    case 1:
      for (int k = 0; k < 3; ++k) s[pos(rng)] = kBytes[byte(rng)];
      break;
    case 2: {
      const std::size_t a = s.rfind('\n', pos(rng));
      const std::size_t b = s.find('\n', a == std::string::npos ? 0 : a + 1);
      if (a != std::string::npos && b != std::string::npos) s.erase(a, b - a);
      break;
    }
    default: {
      const std::size_t a = s.rfind('\n', pos(rng));
      const std::size_t b = s.find('\n', a == std::string::npos ? 0 : a + 1);
      if (a != std::string::npos && b != std::string::npos) s.insert(a, s.substr(a, b - a));
      break;
    }
  }
  return s;
}

struct FuzzCase {
  const char* file;  // relative to meshes/
  const char* companion;  // TetGen partner copied unchanged, or nullptr
};

void PrintTo(const FuzzCase& c, std::ostream* os) { *os << c.file; }

class Fuzz : public ::testing::TestWithParam<FuzzCase> {};

TEST_P(Fuzz, MutatedFilesLoadOrFailWithBadInputNamingTheFile) {
  const FuzzCase& c = GetParam();
  COROFEM_REQUIRE_DATA(std::string("meshes/") + c.file);
  const std::string original = slurp(dataPath(std::string("meshes/") + c.file));
  const auto dir = corofem::test::tempDir();
  const std::string name = std::filesystem::path(c.file).filename().string();
  if (c.companion)
    corofem::test::writeTemp(dir, std::filesystem::path(c.companion).filename().string(),
                             slurp(dataPath(std::string("meshes/") + c.companion)));
  const bool surface = std::filesystem::path(name).extension() == ".obj";
  std::mt19937 rng(12345);
  int failures = 0;
  for (int i = 0; i < 150; ++i) {
    const std::string path = corofem::test::writeTemp(dir, name, mutate(original, rng));
    const corofem::Status st = surface ? corofem::readSurfaceMesh(path).status() : corofem::readTetMesh(path).status();
    if (st.isOk()) continue;
    ++failures;
    ASSERT_EQ(st.code(), corofem::ErrorCode::BadInput) << "mutation " << i << ": " << st.message();
    // The error names the file read (for TetGen possibly the partner file).
    const bool named = st.message().find(name) != std::string::npos ||
                       (c.companion && st.message().find(std::filesystem::path(c.companion).filename().string()) !=
                                           std::string::npos);
    ASSERT_TRUE(named) << st.message();
  }
  EXPECT_GT(failures, 10);  // the mutations do break files; the test exercises the error paths
}

INSTANTIATE_TEST_SUITE_P(SharedMeshes, Fuzz,
                         ::testing::Values(FuzzCase{"sofa/liver.msh", nullptr}, FuzzCase{"ipc/bar-186.msh", nullptr},
                                           FuzzCase{"sfepy/msh_tetra.msh", nullptr},
                                           FuzzCase{"sfepy/cylinder.vtk", nullptr},
                                           FuzzCase{"sfepy/cylinder.mesh", nullptr},
                                           FuzzCase{"vega/beam3/beam3_tet.veg", nullptr},
                                           FuzzCase{"sfepy/octahedron.ele", "sfepy/octahedron.node"},
                                           FuzzCase{"sfepy/octahedron.node", "sfepy/octahedron.ele"},
                                           FuzzCase{"sofa/liver.obj", nullptr}),
                         [](const ::testing::TestParamInfo<FuzzCase>& info) {
                           std::string n = info.param.file;
                           for (char& ch : n)
                             if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                           return n;
                         });

}  // namespace
