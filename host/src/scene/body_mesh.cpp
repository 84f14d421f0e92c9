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
  if (source.scale == 1 && source.translate == Vec3{0, 0, 0}) return mesh;
  // A finite scale and translation can still overflow a coordinate (scale 1e308) or round an
  // element's volume to zero (scale 1e-120: the volume goes as scale^3); the mesh as loaded had
  // neither, so the transformation is to blame.
  const std::string transform = "mesh scale " + scene::formatNumber(source.scale) + " and translation " +
                                scene::formatVec3(source.translate.data());
  for (std::size_t i = 0; i < mesh.nodes.size(); ++i)
    if (!std::isfinite(mesh.nodes[i]))
      return Result<TetMesh>(ErrorCode::BadInput, where + "the " + transform + " move node " +
                                                      std::to_string(i / 3) +
                                                      " to a non-finite coordinate; use a smaller scale or translation");
  for (std::size_t e = 0; e < mesh.tetCount(); ++e)
    if (!(signedVolume(mesh, e) > 0))
      return Result<TetMesh>(ErrorCode::BadInput, where + "the " + transform + " make element " + std::to_string(e) +
                                                      "'s volume round to zero; use a scale closer to 1");
  return mesh;
}

}  // namespace corofem
