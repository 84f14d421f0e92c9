// A body's mesh: read from a file, generated as a box or given in memory, then scaled and translated.
#include <corofem/scene.hpp>

#include "mesh/mesh_validation.hpp"
#include "scene/json_path.hpp"
#include "scene/scene_paths.hpp"
#include "util/error.hpp"

#include <cmath>
#include <utility>

namespace corofem {

namespace {

/// The application's mesh, checked as a reader checks a file's, inverted elements reoriented.
Result<TetMesh> checkedMemoryMesh(const TetMesh& given, MeshReadReport* report) {
  return detail::guardResult<TetMesh>([&] {
    const std::string what = "the mesh in memory (MeshSourceDesc::mesh)";
    if (given.nodes.size() % 3 != 0 || given.tets.size() % 4 != 0)
      detail::fail(ErrorCode::BadInput, what, " has ", given.nodes.size(), " coordinates and ", given.tets.size(),
                   " element indices; give 3 per node and 4 per element");
    if (given.nodeCount() == 0 || given.tetCount() == 0)
      detail::fail(ErrorCode::BadInput, what, " has no ", given.nodeCount() == 0 ? "nodes" : "tetrahedra");
    if (!given.regions.empty() && given.regions.size() != given.tetCount())
      detail::fail(ErrorCode::BadInput, what, " has ", given.regions.size(), " region ids for ", given.tetCount(),
                   " elements; give one per element or none");
    for (std::size_t i = 0; i < given.nodes.size(); ++i)
      if (!std::isfinite(given.nodes[i]))
        detail::fail(ErrorCode::BadInput, what, ": node ", i / 3, " has a coordinate that is not finite");
    TetMesh mesh = given;
    const std::size_t n = mesh.nodeCount();
    double meanVolume = 0.0;
    std::vector<double> volumes(mesh.tetCount());
    for (std::size_t e = 0; e < mesh.tetCount(); ++e) {
      const std::uint32_t* t = &mesh.tets[4 * e];
      for (int k = 0; k < 4; ++k) {
        if (t[k] >= n)
          detail::fail(ErrorCode::BadInput, what, ": element ", e, " names node ", t[k], ", but the mesh has ", n,
                       " nodes (0-based indices)");
        for (int j = 0; j < k; ++j)
          if (t[j] == t[k]) detail::fail(ErrorCode::BadInput, what, ": element ", e, " uses node ", t[k], " twice");
      }
      double d[3][3];
      for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 3; ++a) d[k][a] = mesh.nodes[3 * t[k + 1] + a] - mesh.nodes[3 * t[0] + a];
      volumes[e] = std::abs(d[0][0] * (d[1][1] * d[2][2] - d[1][2] * d[2][1]) -
                            d[0][1] * (d[1][0] * d[2][2] - d[1][2] * d[2][0]) +
                            d[0][2] * (d[1][0] * d[2][1] - d[1][1] * d[2][0])) / 6.0;
      meanVolume += volumes[e] / static_cast<double>(mesh.tetCount());
    }
    const MeshValidation validation;
    for (std::size_t e = 0; e < mesh.tetCount(); ++e)
      if (!(volumes[e] > validation.minRelativeVolume * meanVolume))
        detail::fail(ErrorCode::BadInput, what, ": element ", e, " has ", volumes[e] == 0.0 ? "zero" : "near-zero",
                     " volume (", volumes[e], " against a mean of ", meanVolume, "); remove or fix it");
    const std::size_t reoriented = mesh::reorientElements(mesh);
    if (report) {
      *report = MeshReadReport{};
      report->format = "in memory";
      report->reorientedElements = reoriented;
    }
    return mesh;
  });
}

}  // namespace

Result<TetMesh> loadBodyMesh(const BodyDesc& body, const std::string& baseDir, MeshReadReport* report,
                             const InputLimits& limits) {
  const MeshSourceDesc& source = body.mesh;
  const std::string where = "body \"" + body.name + "\": ";
  const int sources = (source.box ? 1 : 0) + (source.file.empty() ? 0 : 1) + (source.mesh ? 1 : 0);
  if (sources > 1)
    return Result<TetMesh>(ErrorCode::BadInput,
                           where + (source.mesh ? "the mesh has more than one of a file, a box and a mesh in memory"
                                                : "the mesh has both a file and a box") + "; give exactly one");
  if (sources == 0) return Result<TetMesh>(ErrorCode::BadInput, where + "the mesh needs a file or a box (or, through the API, a mesh in memory)");
  if (!(source.scale > 0) || !std::isfinite(source.scale))
    return Result<TetMesh>(ErrorCode::BadInput,
                           where + "mesh scale " + scene::formatNumber(source.scale) + " must be a finite number > 0");
  for (double t : source.translate)
    if (!std::isfinite(t))
      return Result<TetMesh>(ErrorCode::BadInput, where + "mesh translation must be finite");

  Result<TetMesh> loaded =
      source.mesh  ? checkedMemoryMesh(*source.mesh, report)
      : source.box ? generateBox(*source.box, limits)
                   : readTetMesh(scene::resolveScenePath(baseDir, source.file), report, {}, limits);
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
  // A finite scale and translation can still overflow a coordinate (scale 1e308), an element's
  // volume (scale 1e120) or round it to zero (scale 1e-120: the volume goes as scale^3); the mesh
  // as loaded had none of these, so the transformation is to blame.
  const std::string transform = "mesh scale " + scene::formatNumber(source.scale) + " and translation " +
                                scene::formatVec3(source.translate.data());
  for (std::size_t i = 0; i < mesh.nodes.size(); ++i)
    if (!std::isfinite(mesh.nodes[i]))
      return Result<TetMesh>(ErrorCode::BadInput, where + "the " + transform + " move node " +
                                                      std::to_string(i / 3) +
                                                      " to a non-finite coordinate; use a smaller scale or translation");
  for (std::size_t e = 0; e < mesh.tetCount(); ++e) {
    const double v = signedVolume(mesh, e);
    if (!(v > 0))
      return Result<TetMesh>(ErrorCode::BadInput, where + "the " + transform + " make element " + std::to_string(e) +
                                                      "'s volume round to zero; use a scale closer to 1");
    if (!std::isfinite(v))  // finite coordinates whose product overflows (scale 1e120: the volume goes as scale^3)
      return Result<TetMesh>(ErrorCode::BadInput, where + "the " + transform + " make element " + std::to_string(e) +
                                                      "'s volume overflow; use a scale closer to 1");
  }
  return mesh;
}

}  // namespace corofem
