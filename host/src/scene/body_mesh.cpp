// A body's mesh: read from a file or generated as a box, then scaled and translated.
#include <corofem/scene.hpp>

#include "scene/json_path.hpp"
#include "scene/scene_paths.hpp"
#include "util/error.hpp"

#include <cmath>
#include <utility>

namespace corofem {

Result<TetMesh> loadBodyMesh(const BodyDesc& body, const std::string& baseDir, MeshReadReport* report) {
  const MeshSourceDesc& source = body.mesh;
  const std::string where = "body \"" + body.name + "\": ";
  if (source.box && !source.file.empty())
    return Result<TetMesh>(ErrorCode::BadInput, where + "the mesh has both a file and a box; give exactly one");
  if (!source.box && source.file.empty())
    return Result<TetMesh>(ErrorCode::BadInput, where + "the mesh needs a file or a box");
  if (!(source.scale > 0) || !std::isfinite(source.scale))
    return Result<TetMesh>(ErrorCode::BadInput,
                           where + "mesh scale " + scene::formatNumber(source.scale) + " must be a finite number > 0");
  for (double t : source.translate)
    if (!std::isfinite(t))
      return Result<TetMesh>(ErrorCode::BadInput, where + "mesh translation must be finite");

  Result<TetMesh> loaded = source.box ? generateBox(*source.box)
                                      : readTetMesh(scene::resolveScenePath(baseDir, source.file), report);
  if (!loaded) return Result<TetMesh>(loaded.status().code(), where + loaded.message());
  if (source.box && report) {
    *report = MeshReadReport{};
    report->format = "generated box";
  }

  // x <- scale * x + translate, node by node (scale > 0 keeps every element's orientation).
  TetMesh mesh = std::move(loaded).value();
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n)
    for (int a = 0; a < 3; ++a) mesh.nodes[3 * n + a] = source.scale * mesh.nodes[3 * n + a] + source.translate[a];
  return mesh;
}

}  // namespace corofem
