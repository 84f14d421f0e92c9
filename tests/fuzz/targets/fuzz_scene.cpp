// libFuzzer target: the scene parser with --set overrides (parseScene), then, for each body on a
// small generated box, its mesh (loadBodyMesh: generation, scale, translation) and its node sets
// (resolveNodeSet; .bou files are not read). The input is the scene's JSON text, then the
// overrides, each after a NUL byte (at most 8).
#include "fuzz_support.hpp"

#include "mesh/mesh_validation.hpp"
#include "scene/scene_paths.hpp"

#include <corofem/scene.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace {

using namespace corofem;

void checkNames(const Scene& scene) {
  fuzz::require(scene::fileNameProblem(scene.name).empty(), "an unsafe scene name was accepted");
  for (const BodyDesc& b : scene.bodies)
    fuzz::require(scene::fileNameProblem(b.name).empty(), "an unsafe body name was accepted: " + b.name.substr(0, 100));
  for (const ProbeDesc& p : scene.output.probes)
    fuzz::require(scene::nameProblem(p.name).empty(), "a bad probe name was accepted");
}

void checkNumbers(const Scene& scene) {
  for (const BodyDesc& b : scene.bodies) {
    const MaterialDesc& m = b.material;
    fuzz::require(std::isfinite(m.youngsModulus) && m.youngsModulus > 0, "E out of range was accepted");
    fuzz::require(m.poissonRatio > -1 && m.poissonRatio < 0.5, "nu out of range was accepted");
    fuzz::require(std::isfinite(m.density) && m.density > 0, "density out of range was accepted");
    fuzz::require(std::isfinite(b.mesh.scale) && b.mesh.scale > 0, "a mesh scale out of range was accepted");
    if (b.mesh.box) {
      const BoxSpec& box = *b.mesh.box;
      for (int a = 0; a < 3; ++a) {
        fuzz::require(std::isfinite(box.min[a]) && std::isfinite(box.max[a]) && box.max[a] > box.min[a],
                      "an empty or non-finite box was accepted");
        fuzz::require(box.cells[a] >= 1, "a box with no cells was accepted");
      }
      fuzz::require(mesh::boxSizeProblem(box, InputLimits{}).empty(), "a box over the limit was accepted");
    }
  }
  const DynamicDesc& d = scene.analysis.dynamics;
  fuzz::require(std::isfinite(d.timeStep) && d.timeStep > 0 && d.steps >= 0, "a bad time step or step count was accepted");
  fuzz::require(d.maxSubsteps >= 1 && d.maxSubsteps <= 1024, "max_substeps out of range was accepted");
  fuzz::require(scene.analysis.statics.increments >= 1, "increments out of range was accepted");
}

void checkNodeSet(const NodeSetDesc& set, const TetMesh& mesh) {
  if (set.kind == NodeSetDesc::Kind::BouFile) return;  // a file named by the input: not read here
  const auto nodes = resolveNodeSet(set, mesh, "");
  if (!nodes.isOk()) return fuzz::checkRefusal(nodes.status(), "resolveNodeSet");
  fuzz::require(!nodes->empty(), "an empty node set was accepted");
  for (std::uint32_t n : nodes.value()) fuzz::require(n < mesh.nodeCount(), "a node set index out of range");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string expanded = fuzz::expandRuns({reinterpret_cast<const char*>(data), size});
  const std::string_view input(expanded);
  std::size_t end = input.find('\0');
  const std::string text(input.substr(0, end));
  std::vector<std::string> overrides;
  while (end != std::string_view::npos && overrides.size() < 8) {
    const std::size_t next = input.find('\0', end + 1);
    overrides.emplace_back(input.substr(end + 1, next == std::string_view::npos ? next : next - end - 1));
    end = next;
  }
  const Result<Scene> scene = parseScene(text, "", overrides);
  if (!scene.isOk()) {
    fuzz::checkRefusal(scene.status(), "parseScene");
    return 0;
  }
  fuzz::require(!scene->bodies.empty(), "a scene without bodies was accepted");
  checkNames(scene.value());
  checkNumbers(scene.value());
  for (const BodyDesc& body : scene->bodies) {
    if (!body.mesh.box) continue;  // files named by the input are not read here
    const BoxSpec& box = *body.mesh.box;
    if (double(box.cells[0]) * box.cells[1] * box.cells[2] * box.tetsPerCell > 3000) continue;  // fast execs
    MeshReadReport report;
    const Result<TetMesh> mesh = loadBodyMesh(body, "", &report);
    if (!mesh.isOk()) {
      fuzz::checkRefusal(mesh.status(), "loadBodyMesh");
      continue;
    }
    fuzz::checkTetMesh(mesh.value(), "loadBodyMesh");
    for (const NodeSetDesc& set : body.fixed) checkNodeSet(set, mesh.value());
    for (const LoadDesc& load : body.loads)
      if (load.kind != LoadDesc::Kind::Gravity) checkNodeSet(load.nodes, mesh.value());
  }
  return 0;
}
