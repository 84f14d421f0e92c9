// Regression tests of issue 27 (what fuzzing and fault injection found) for scene files: a crash on
// malformed JSON quoting a long token, names that would be paths, unbounded --set messages, files
// that are not regular files, the caps on max_substeps and on generated boxes, probe names that
// would break probes.csv. Each test names the item of the issue it covers.
#include "scene/scene_test_util.hpp"

#include <corofem/simulation.hpp>

#include "common/test_data.hpp"

#include <gtest/gtest.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <sys/stat.h>

namespace corofem {
namespace {

namespace fs = std::filesystem;
using test::overrideError;
using test::parseError;

bool has(const std::string& haystack, const std::string& needle) { return haystack.find(needle) != std::string::npos; }

const std::string kBodies = R"("bodies": [{"mesh": {"box": {}}}])";

// ------------------------------------------------------------------ item 1: a crash on malformed JSON
// The parse-error path ran std::regex over the JSON library's message, which quotes the token; the
// regex recursed once per character and a 40,000-character token overflowed the stack (SIGSEGV).
TEST(Issue27Item1, AnUnterminatedLongStringIsBadInputNotACrash) {
  const std::string text = "{" + kBodies + ", \"name\": \"" + std::string(40000, 'a');
  const std::string msg = parseError(text);
  EXPECT_TRUE(has(msg, "line 1, column ")) << msg.substr(0, 300);
  EXPECT_TRUE(has(msg, "invalid JSON")) << msg.substr(0, 300);
  EXPECT_LT(msg.size(), 400u) << msg.substr(0, 400);
}

TEST(Issue27Item1, ALongNumberLiteralIsBadInputNotACrash) {
  // Out of the double range: the JSON library's out_of_range error quotes the literal.
  const std::string tooLarge = "{" + kBodies + ",\n \"x\": " + std::string(40000, '1') + "e99999}";
  std::string msg = parseError(tooLarge);
  EXPECT_TRUE(has(msg, "line 2, column 7: the number 1111")) << msg.substr(0, 300);
  EXPECT_TRUE(has(msg, "is too large (numbers must be finite)")) << msg.substr(0, 300);
  EXPECT_LT(msg.size(), 400u);
  // Malformed (no digit after the exponent): the parse error quotes it.
  msg = parseError("{" + kBodies + ", \"x\": -" + std::string(40000, '1') + "ex}");
  EXPECT_TRUE(has(msg, "last read: '-1111")) << msg.substr(0, 300);
  EXPECT_TRUE(has(msg, "invalid JSON")) << msg.substr(0, 300);
  EXPECT_LT(msg.size(), 400u);
}

TEST(Issue27Item1, ATokenHoldingTheLibrarysOwnWordsIsShortenedToo) {
  // Found by fuzz_scene: the token quoted after "last read: '" held "'; expected ", which the first
  // fix took for the end of the token, and the rest (1,500 characters) was quoted whole.
  const std::string msg = parseError("{\"name\": \"st'; expected aan[" + std::string(1500, 'z'));
  EXPECT_TRUE(has(msg, "last read: '\"st'; expected aan[zzz")) << msg;
  EXPECT_LT(msg.size(), 400u) << msg;
}

TEST(Issue27Item1, LoadSceneToo) {
  const fs::path path = test::tempDir() / "long.json";
  std::ofstream(path) << "{\"bodies\": [], \"name\": \"" << std::string(40000, 'a');
  auto scene = loadScene(path.string());
  ASSERT_FALSE(scene.isOk());
  EXPECT_EQ(scene.status().code(), ErrorCode::BadInput);
  EXPECT_LT(scene.message().size(), 400u + path.string().size());
}

// ------------------------------------------------------------------ item 2: names used as paths
TEST(Issue27Item2, BodyNamesThatArePathsAreRefused) {
  for (const char* name : {"../../x", "/abs/path", "a\\\\b", "..", "."}) {
    const std::string msg =
        parseError(std::string(R"({"bodies": [{"name": ")") + name + R"(", "mesh": {"box": {}}}]})");
    EXPECT_TRUE(has(msg, "bodies[0].name: the name")) << msg;
    EXPECT_TRUE(has(msg, "file name in the output folder")) << msg;
  }
  // --set goes through the same check.
  EXPECT_TRUE(has(overrideError({"bodies.0.name=../../etc/x"}), "contains '/'"));
}

TEST(Issue27Item2, SceneNamesThatArePathsAreRefused) {
  EXPECT_TRUE(has(parseError("{" + kBodies + R"(, "name": "../../outside"})"), "name: the name \"../../outside\" contains '/'"));
  EXPECT_TRUE(has(overrideError({"name=/tmp/x"}), "contains '/'"));
  // A name taken from the file name is checked too.
  const fs::path path = test::tempDir() / "..json";  // its stem is "."
  std::ofstream(path) << "{" << kBodies << "}";
  auto scene = loadScene(path.string());
  ASSERT_FALSE(scene.isOk());
  EXPECT_TRUE(has(scene.message(), "(taken from the file name, as the scene sets no \"name\")")) << scene.message();
}

TEST(Issue27Item2, NamesAreShortAndPrintable) {
  const std::string msg = overrideError({"bodies.0.name=" + std::string(200, 'b')});
  EXPECT_TRUE(has(msg, "is 200 bytes long; a name may have at most 128 bytes")) << msg;
  EXPECT_EQ(test::parseOk(R"j({"name": "my scene (v2)", "bodies": [{"name": "left beam", "mesh": {"box": {}}}]})j")
                .bodies.size(),
            1u);
}

// ------------------------------------------------------------------ item 7: probe names in probes.csv
TEST(Issue27Item7, ProbeNamesWithALineBreakAreRefused) {
  const std::string scene = "{" + kBodies + R"(, "output": {"probes": [{"name": "tip\nx", "nodes": {"list": [0]}}]}})";
  EXPECT_TRUE(has(parseError(scene), "output.probes[0].name: the name \"tip\nx\" contains a control character (byte 0x0a)"));
  // A comma is fine: probes.csv quotes such a column name.
  test::parseOk("{" + kBodies + R"(, "output": {"probes": [{"name": "tip, left", "nodes": {"list": [0]}}]}})");
}

// ------------------------------------------------------------------ item 5: bounded --set messages
TEST(Issue27Item5, OverridesQuotingAHugePieceGiveShortMessages) {
  const std::string big(1 << 20, 'q');
  const std::vector<std::string> overrides{
      big,                                      // no '='
      "analysis.." + big + "=1",                // empty segment: the path was echoed whole, twice
      "bodies." + big + "=1",                   // not an index
      "name." + big + "=1",                     // through a string
      big + "=1",                               // unknown key
      "bodies.0.formulation=" + big,            // unknown value
      "bodies[" + big + "]=1",                  // not an index in brackets
      "bodies.0.name=" + big,                   // a name too long
  };
  for (const std::string& o : overrides) {
    const std::string msg = overrideError({o});
    EXPECT_LT(msg.size(), 800u) << msg.substr(0, 300);
  }
  EXPECT_TRUE(has(overrideError({std::string(40, 'a') + std::string(60, '.') + "=1"}), "empty segment"));
  EXPECT_TRUE(has(overrideError({"a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a.a=1"}),
                  "the key path has 33 segments"));
}

// ------------------------------------------------------------------ item 9: caps
TEST(Issue27Item9, MaxSubstepsHasAnUpperBound) {
  const std::string msg = overrideError({"analysis.max_substeps=2147483647"});
  EXPECT_TRUE(has(msg, "analysis.max_substeps: 2147483647 is out of range: must satisfy 1 <= max_substeps <= 1024"))
      << msg;
  EXPECT_EQ(test::parseOk(test::kMinimalScene, {"analysis.max_substeps=1024"}).analysis.dynamics.maxSubsteps, 1024);
}

TEST(Issue27Item9, AHugeBoxIsBadInputAtItsKey) {
  const std::string msg = overrideError({"bodies.0.mesh.box.cells=[1000, 1000, 200]"});
  EXPECT_TRUE(has(msg, "bodies[0].mesh.box.cells: 1000 x 1000 x 200 cells of 5 tetrahedra give 1000000000 "
                       "tetrahedra, more than the limit of 50000000 (InputLimits::maxBoxTets, the default)"))
      << msg;
  EXPECT_TRUE(has(msg, "--max-box-tets")) << msg;
  // InputLimits::maxBoxTets moves the limit both ways.
  InputLimits limits;
  limits.maxBoxTets = 2'000'000'000;
  EXPECT_TRUE(parseScene(test::kMinimalScene, "", {"bodies.0.mesh.box.cells=[1000, 1000, 200]"}, limits).isOk());
  limits.maxBoxTets = 4;  // the unit box has 5
  auto small = parseScene(test::kMinimalScene, "", {}, limits);
  ASSERT_FALSE(small.isOk());
  EXPECT_EQ(small.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(has(small.message(), "bodies[0].mesh.box.cells: 1 x 1 x 1 cells of 5 tetrahedra give 5 tetrahedra, "
                                   "more than the limit of 4 (InputLimits::maxBoxTets)"))
      << small.message();
}

// ------------------------------------------------------------------ item 4: not regular files
TEST(Issue27Item4, ASceneThatIsADirectoryOrAFifoIsRefused) {
  const fs::path dir = test::tempDir() / "scene.json";
  fs::create_directories(dir);
  auto scene = loadScene(dir.string());
  ASSERT_FALSE(scene.isOk());
  EXPECT_EQ(scene.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(has(scene.message(), "is a directory, not a regular file")) << scene.message();
  const std::string fifo = (test::tempDir() / "fifo.json").string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0) << std::strerror(errno);
  scene = loadScene(fifo);  // blocked forever, waiting for a writer
  ASSERT_FALSE(scene.isOk());
  EXPECT_TRUE(has(scene.message(), "is a FIFO")) << scene.message();
}

TEST(Issue27Item4, ADeeplyNestedOrHugeSceneIsBadInputNotOutOfMemory) {
  // 50 MB of "[" ran out of memory ("internal error: out of memory"): the parsed document takes
  // many times the text's size. Nesting is limited to 64 levels, scene files to 16 MiB.
  const std::string msg = parseError("{" + kBodies + ", \"x\": " + std::string(100000, '['));
  EXPECT_TRUE(has(msg, "x[0][0][0]")) << msg;
  EXPECT_TRUE(has(msg, "nest more than 64 levels deep")) << msg;
  EXPECT_LT(msg.size(), 400u);
  const fs::path path = test::tempDir() / "big.json";
  std::ofstream(path) << "{" << kBodies << std::string(17 << 20, ' ') << "}";
  auto scene = loadScene(path.string());
  ASSERT_FALSE(scene.isOk());
  EXPECT_EQ(scene.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(has(scene.message(), "more than the limit of 16777216 bytes (InputLimits::maxSceneBytes, the default)"))
      << scene.message();
  EXPECT_TRUE(has(scene.message(), "--max-scene-bytes")) << scene.message();
  // Raised, the scene loads; the limit of the other inputs does not apply to scene files.
  InputLimits limits;
  limits.maxSceneBytes = 32 << 20;
  limits.maxInputBytes = 100;
  EXPECT_TRUE(loadScene(path.string(), {}, limits).isOk());
  limits.maxSceneBytes = 17 << 20;  // exactly too small: the file has 17 MiB and 27 bytes
  scene = loadScene(path.string(), {}, limits);
  ASSERT_FALSE(scene.isOk());
  EXPECT_TRUE(has(scene.message(), "more than the limit of 17825792 bytes (InputLimits::maxSceneBytes)"))
      << scene.message();
}

/// The limits reach every file and box behind a scene: loadBodyMesh, resolveNodeSet, and a
/// Simulation's (SimulationOptions::inputLimits) meshes, surfaces, .bou files and added bodies.
TEST(Issue27Item4, TheInputLimitsReachEveryFileOfAScene) {
  const fs::path dir = test::tempDir();
  std::ofstream(dir / "tet.msh") << "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n"
                                    "4 0 0 1\n$EndNodes\n$Elements\n1\n1 4 2 0 1 1 2 3 4\n$EndElements\n";  // 129 bytes
  std::ofstream(dir / "fix.bou") << "1, 2\n# " << std::string(200, 'x') << "\n";
  InputLimits tight;
  tight.maxInputBytes = 100;
  tight.maxBoxTets = 4;
  InputLimits raised = tight;
  raised.maxInputBytes = 1000;
  raised.maxBoxTets = 5;

  BodyDesc file;
  file.mesh.file = "tet.msh";
  MeshReadReport report;
  auto mesh = loadBodyMesh(file, dir.string(), &report, tight);
  ASSERT_FALSE(mesh.isOk());
  EXPECT_TRUE(has(mesh.message(), "tet.msh: it has 129 bytes, more than the limit of 100 bytes")) << mesh.message();
  EXPECT_TRUE(loadBodyMesh(file, dir.string(), &report, raised).isOk());
  BodyDesc box;
  box.mesh.box = BoxSpec{};  // 5 tetrahedra
  mesh = loadBodyMesh(box, dir.string(), &report, tight);
  ASSERT_FALSE(mesh.isOk());
  EXPECT_TRUE(has(mesh.message(), "more than the limit of 4 (InputLimits::maxBoxTets)")) << mesh.message();
  EXPECT_TRUE(loadBodyMesh(box, dir.string(), &report, raised).isOk());

  NodeSetDesc bou;
  bou.kind = NodeSetDesc::Kind::BouFile;
  bou.bouFile = "fix.bou";
  const TetMesh unit = generateBox(BoxSpec{}).value();
  auto nodes = resolveNodeSet(bou, unit, dir.string(), tight);
  ASSERT_FALSE(nodes.isOk());
  EXPECT_TRUE(has(nodes.message(), "fix.bou")) << nodes.message();
  EXPECT_TRUE(has(nodes.message(), "InputLimits::maxInputBytes")) << nodes.message();
  EXPECT_TRUE(resolveNodeSet(bou, unit, dir.string(), raised).isOk());

  // A Simulation reads its files under SimulationOptions::inputLimits.
  Scene scene = test::parseOk(R"({"backend": "reference", "analysis": {"steps": 0},
      "bodies": [{"name": "a", "mesh": {"box": {}}, "fixed": [{"bou": "fix.bou"}]}]})");
  scene.baseDir = dir.string();
  SimulationOptions options;
  options.inputLimits = tight;
  options.inputLimits.maxBoxTets = 5;  // the box passes; the .bou file does not
  auto sim = Simulation::create(scene, options);
  ASSERT_FALSE(sim.isOk());
  EXPECT_TRUE(has(sim.message(), "fix.bou")) << sim.message();
  EXPECT_TRUE(has(sim.message(), "more than the limit of 100 bytes (InputLimits::maxInputBytes)")) << sim.message();
  options.inputLimits = tight;  // the box is refused first
  sim = Simulation::create(scene, options);
  ASSERT_FALSE(sim.isOk());
  EXPECT_TRUE(has(sim.message(), "more than the limit of 4 (InputLimits::maxBoxTets)")) << sim.message();
  options.inputLimits = raised;
  sim = Simulation::create(scene, options);
  ASSERT_TRUE(sim.isOk()) << sim.message();
  // addBody: under the same limits.
  BodyDesc added;
  added.name = "b";
  added.mesh.file = "tet.msh";
  added.surface = "big.obj";
  std::ofstream(dir / "big.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# " << std::string(1000, 'x') << "\n";
  auto index = sim->addBody(added);
  ASSERT_FALSE(index.isOk());
  EXPECT_TRUE(has(index.message(), "big.obj: it has ")) << index.message();
  EXPECT_TRUE(has(index.message(), "more than the limit of 1000 bytes (InputLimits::maxInputBytes)"))
      << index.message();
  added.surface.clear();
  EXPECT_TRUE(sim->addBody(added).isOk());
}

TEST(Issue27Item4, ABouFileThatIsADeviceOrAFifoIsRefused) {
  const TetMesh mesh = generateBox(BoxSpec{}).value();
  const fs::path dir = test::tempDir();
  NodeSetDesc set;
  set.kind = NodeSetDesc::Kind::BouFile;
  if (fs::exists("/dev/zero")) {
    set.bouFile = "/dev/zero";  // one endless line: read until memory ran out
    auto r = resolveNodeSet(set, mesh, dir.string());
    ASSERT_FALSE(r.isOk());
    EXPECT_TRUE(has(r.message(), "is a character device, not a regular file")) << r.message();
  }
  set.bouFile = "pipe.bou";
  ASSERT_EQ(::mkfifo((dir / "pipe.bou").string().c_str(), 0600), 0);
  auto r = resolveNodeSet(set, mesh, dir.string());
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::BadInput);
  EXPECT_TRUE(has(r.message(), "pipe.bou")) << r.message();
}

// ------------------------------------------------------------------ found by fuzz_scene
TEST(FuzzFinding, AScaleThatOverflowsOrUnderflowsTheMeshIsBadInput) {
  // Scene values in range (a finite scale > 0) gave a mesh with infinite coordinates or elements of
  // zero volume; loadBodyMesh returned it as good (Simulation::create refused it later, without
  // naming the scale).
  for (const char* scale : {"1e+308", "1e+120", "1e-120"}) {  // 1e+120: coordinates finite, volumes not
    const Scene scene = test::parseOk(std::string(R"({"bodies": [{"name": "b", "mesh": {"box": {"max": [2, 2, 2]},)") +
                                      R"( "scale": )" + scale + "}}]}");
    const Result<TetMesh> mesh = loadBodyMesh(scene.bodies[0], "");
    ASSERT_FALSE(mesh.isOk()) << scale;
    EXPECT_EQ(mesh.status().code(), ErrorCode::BadInput);
    EXPECT_TRUE(has(mesh.message(), std::string("body \"b\": the mesh scale ") + scale)) << mesh.message();
  }
  const Scene far = test::parseOk(R"({"bodies": [{"mesh": {"box": {}, "translate": [1e300, 0, 0]}}]})");
  EXPECT_TRUE(has(loadBodyMesh(far.bodies[0], "").message(), "volume round to zero"));
  const Scene huge = test::parseOk(R"({"bodies": [{"mesh": {"box": {}, "scale": 1e+120}}]})");
  EXPECT_TRUE(has(loadBodyMesh(huge.bodies[0], "").message(), "volume overflow")) << loadBodyMesh(huge.bodies[0], "").message();
  const Scene fine = test::parseOk(R"({"bodies": [{"mesh": {"box": {}, "scale": 1e-3, "translate": [5, 0, 0]}}]})");
  EXPECT_TRUE(loadBodyMesh(fine.bodies[0], "").isOk());
}

}  // namespace
}  // namespace corofem
