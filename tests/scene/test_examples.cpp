// The documented examples (docs/examples/*.json) and the benchmark scenes (bench/scenes) parse, and where their meshes are available every
// node set in them selects nodes: a typo in a documented coordinate fails here, not in a user's run.
#include "common/test_data.hpp"

#include <corofem/scene.hpp>

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>

namespace corofem {
namespace {

namespace fs = std::filesystem;

std::vector<fs::path> jsonFilesIn(const char* folder) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(fs::path(COROFEM_SOURCE_DIR) / folder))
    if (entry.path().extension() == ".json") files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  return files;
}

std::vector<fs::path> examples() { return jsonFilesIn("docs/examples"); }

/// The documented examples and the benchmark scenes.
std::vector<fs::path> allScenes() {
  std::vector<fs::path> files = examples(), bench = jsonFilesIn("bench/scenes");
  files.insert(files.end(), bench.begin(), bench.end());
  return files;
}

TEST(SceneExamples, EveryExampleParses) {
  const auto files = allScenes();
  // The brief asks for at least: static cantilever, Fig-8 beam, dragged handle, mesh file + .bou.
  ASSERT_GE(examples().size(), 4u);
  for (const fs::path& file : files) {
    const Result<Scene> scene = loadScene(file.string());
    EXPECT_TRUE(scene.isOk()) << file << ": " << scene.message();
    if (scene.isOk()) EXPECT_EQ(scene->name, file.stem().string()) << "example names match their file names";
  }
}

TEST(SceneExamples, EveryNodeSetSelectsNodesWhereTheMeshIsAvailable) {
  int checkedBodies = 0;
  for (const fs::path& file : allScenes()) {
    const Result<Scene> scene = loadScene(file.string());
    ASSERT_TRUE(scene.isOk()) << file << ": " << scene.message();
    for (const BodyDesc& body : scene->bodies) {
      if (!body.mesh.file.empty() && !fs::exists(fs::path(scene->baseDir) / body.mesh.file)) {
        std::cout << "[ note ] " << file.filename() << ": mesh " << body.mesh.file << " absent, not checked\n";
        continue;
      }
      const Result<TetMesh> mesh = loadBodyMesh(body, scene->baseDir);
      ASSERT_TRUE(mesh.isOk()) << file << ": " << mesh.message();
      ++checkedBodies;
      if (!body.surface.empty())
        EXPECT_TRUE(fs::exists(fs::path(scene->baseDir) / body.surface)) << file << ": surface " << body.surface;
      std::vector<const NodeSetDesc*> sets;
      for (const NodeSetDesc& set : body.fixed) sets.push_back(&set);
      for (const LoadDesc& load : body.loads)
        if (load.kind != LoadDesc::Kind::Gravity) sets.push_back(&load.nodes);
      for (const ProbeDesc& probe : scene->output.probes)
        if (probe.body.empty() ? &body == &scene->bodies.front() : probe.body == body.name) sets.push_back(&probe.nodes);
      for (const NodeSetDesc* set : sets) {
        const auto nodes = resolveNodeSet(*set, *mesh, scene->baseDir);
        EXPECT_TRUE(nodes.isOk()) << file << ": body " << body.name << ": " << nodes.message();
      }
    }
  }
  EXPECT_GE(checkedBodies, 3);  // the generated-box examples need no shared data
}

TEST(SceneExamples, DocumentationShowsTheFilesAsTheyAre) {
  // docs/scene-format.md quotes each example after a link "(examples/<file>.json)"; the quoted JSON
  // must equal the file, so the documentation cannot drift from what the tests check.
  std::ifstream in(fs::path(COROFEM_SOURCE_DIR) / "docs" / "scene-format.md");
  ASSERT_TRUE(in) << "docs/scene-format.md is missing";
  std::stringstream text;
  text << in.rdbuf();
  const std::string doc = text.str();
  int quoted = 0;
  for (const fs::path& file : examples()) {
    const std::string link = "(examples/" + file.filename().string() + ")";
    const std::size_t at = doc.find(link);
    if (at == std::string::npos) {
      ADD_FAILURE() << file.filename() << " is not linked from docs/scene-format.md";
      continue;
    }
    const std::size_t open = doc.find("```json\n", at);
    const std::size_t close = doc.find("```", open + 8);
    ASSERT_NE(open, std::string::npos);
    ASSERT_NE(close, std::string::npos);
    std::ifstream f(file);
    std::stringstream content;
    content << f.rdbuf();
    EXPECT_EQ(nlohmann::json::parse(doc.substr(open + 8, close - open - 8)), nlohmann::json::parse(content.str()))
        << "the block quoted after " << link << " differs from the file";
    ++quoted;
  }
  EXPECT_GE(quoted, 4);
}

}  // namespace
}  // namespace corofem
