// Node sets: the mesh nodes a box, a plane, an index list or a Vega .bou file selects.
#include <corofem/scene.hpp>

#include "mesh/input_file.hpp"
#include "scene/json_path.hpp"
#include "scene/scene_paths.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

namespace corofem {

namespace {

using scene::formatNumber;
using scene::formatVec3;

struct Bounds {
  Vec3 min{0, 0, 0}, max{0, 0, 0};
  double diagonal() const {
    return std::sqrt((max[0] - min[0]) * (max[0] - min[0]) + (max[1] - min[1]) * (max[1] - min[1]) +
                     (max[2] - min[2]) * (max[2] - min[2]));
  }
  std::string text() const { return formatVec3(min.data()) + " to " + formatVec3(max.data()); }
};

Bounds boundsOf(const TetMesh& mesh) {
  Bounds b;
  for (int a = 0; a < 3; ++a) {
    b.min[a] = std::numeric_limits<double>::infinity();
    b.max[a] = -std::numeric_limits<double>::infinity();
  }
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n)
    for (int a = 0; a < 3; ++a) {
      b.min[a] = std::min(b.min[a], mesh.nodes[3 * n + a]);
      b.max[a] = std::max(b.max[a], mesh.nodes[3 * n + a]);
    }
  return b;
}

/// The set as a user wrote it, for messages.
std::string describeSet(const NodeSetDesc& set) {
  switch (set.kind) {
    case NodeSetDesc::Kind::Box:
      return "the box node set (min " + formatVec3(set.boxMin.data()) + ", max " + formatVec3(set.boxMax.data()) + ")";
    case NodeSetDesc::Kind::Plane:
      return "the plane node set (point " + formatVec3(set.planePoint.data()) + ", normal " +
             formatVec3(set.planeNormal.data()) + ", tolerance " + formatNumber(set.planeTolerance) + ")";
    case NodeSetDesc::Kind::List:
      return "the list node set (" + std::to_string(set.indices.size()) + " indices)";
    case NodeSetDesc::Kind::BouFile:
      return "the .bou node set \"" + set.bouFile + "\"";
  }
  return "the node set";
}

std::vector<std::uint32_t> selectBox(const NodeSetDesc& set, const TetMesh& mesh, const Bounds& bounds) {
  // Inclusive, widened by 1e-9 of the mesh's diagonal: a face of the box placed exactly on a row of
  // nodes must catch them although the coordinates were rounded when written or scaled.
  const double slack = 1e-9 * bounds.diagonal();
  std::vector<std::uint32_t> selected;
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
    bool inside = true;
    for (int a = 0; a < 3 && inside; ++a) {
      const double x = mesh.nodes[3 * n + a];
      inside = x >= set.boxMin[a] - slack && x <= set.boxMax[a] + slack;
    }
    if (inside) selected.push_back(static_cast<std::uint32_t>(n));
  }
  return selected;
}

std::vector<std::uint32_t> selectPlane(const NodeSetDesc& set, const TetMesh& mesh, const Bounds& bounds) {
  const Vec3& nrm = set.planeNormal;
  const double length = std::sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
  if (!(length > 0) || !std::isfinite(length))
    detail::fail(ErrorCode::BadInput, describeSet(set), ": the normal must be a non-zero, finite vector");
  if (!(set.planeTolerance >= 0) || !std::isfinite(set.planeTolerance))
    detail::fail(ErrorCode::BadInput, describeSet(set), ": the tolerance must be a finite number >= 0");
  // Distance of node x from the plane through p with normal n: |n . (x - p)| / |n|.
  std::vector<std::uint32_t> selected;
  double nearest = std::numeric_limits<double>::infinity();
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
    double dot = 0;
    for (int a = 0; a < 3; ++a) dot += nrm[a] * (mesh.nodes[3 * n + a] - set.planePoint[a]);
    const double distance = std::abs(dot) / length;
    nearest = std::min(nearest, distance);
    if (distance <= set.planeTolerance) selected.push_back(static_cast<std::uint32_t>(n));
  }
  if (selected.empty())
    detail::fail(ErrorCode::BadInput, describeSet(set), " selects no nodes: the nearest node is ",
                 formatNumber(nearest), " from the plane; the mesh's bounding box is ", bounds.text(),
                 ". Move the point onto a row of nodes or raise the tolerance");
  return selected;
}

std::vector<std::uint32_t> selectList(const NodeSetDesc& set, const TetMesh& mesh) {
  for (std::uint32_t index : set.indices)
    if (index >= mesh.nodeCount())
      detail::fail(ErrorCode::BadInput, describeSet(set), ": node index ", index, " is out of range: the mesh has ",
                   mesh.nodeCount(), " nodes (0-based indices 0 to ", mesh.nodeCount() - 1, ")");
  return set.indices;
}

/// Vega .bou: 1-based node ids separated by commas and/or white space; lines whose first
/// non-blank character is '#' are comments.
std::vector<std::uint32_t> selectBou(const NodeSetDesc& set, const TetMesh& mesh, const std::string& baseDir,
                                     const InputLimits& limits) {
  const std::string path = scene::resolveScenePath(baseDir, set.bouFile);
  const std::string text = mesh::readInputFile(
      path, "the .bou file \"" + path + "\"" +
                (path == set.bouFile ? "" : " (\"" + set.bouFile + "\" relative to \"" + baseDir + "\")"),
      "", limits);
  std::vector<std::uint32_t> selected;
  std::size_t lineNumber = 0;
  for (std::size_t start = 0; start < text.size();) {
    std::size_t stop = text.find('\n', start);
    if (stop == std::string::npos) stop = text.size();
    const std::string_view line(text.data() + start, stop - start);
    start = stop + 1;
    ++lineNumber;
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string_view::npos || line[first] == '#') continue;
    std::size_t i = first;
    while (i < line.size()) {
      while (i < line.size() && (line[i] == ',' || std::isspace(static_cast<unsigned char>(line[i])))) ++i;
      if (i >= line.size()) break;
      std::size_t end = i;
      while (end < line.size() && line[end] != ',' && !std::isspace(static_cast<unsigned char>(line[end]))) ++end;
      const std::string_view token = line.substr(i, end - i);
      std::uint64_t id = 0;
      const auto parsed = std::from_chars(token.data(), token.data() + token.size(), id);
      if (parsed.ec != std::errc() || parsed.ptr != token.data() + token.size())
        detail::fail(ErrorCode::BadInput, "file ", path, ":", lineNumber, ": \"", detail::shorten(token),
                     "\" is not a node id (a .bou file lists 1-based node ids separated by commas)");
      if (id == 0)
        detail::fail(ErrorCode::BadInput, "file ", path, ":", lineNumber,
                     ": node id 0 is invalid: .bou node ids are 1-based");
      if (id > mesh.nodeCount())
        detail::fail(ErrorCode::BadInput, "file ", path, ":", lineNumber, ": node id ", id,
                     " is out of range: the mesh has ", mesh.nodeCount(), " nodes (1-based ids 1 to ",
                     mesh.nodeCount(), ")");
      selected.push_back(static_cast<std::uint32_t>(id - 1));
      i = end;
    }
  }
  return selected;
}

}  // namespace

Result<std::vector<std::uint32_t>> resolveNodeSet(const NodeSetDesc& set, const TetMesh& mesh,
                                                  const std::string& baseDir, const InputLimits& limits) {
  return detail::guardResult<std::vector<std::uint32_t>>([&] {
    if (mesh.nodeCount() == 0) detail::fail(ErrorCode::BadInput, describeSet(set), ": the mesh has no nodes");
    const Bounds bounds = boundsOf(mesh);
    std::vector<std::uint32_t> selected;
    switch (set.kind) {
      case NodeSetDesc::Kind::Box: selected = selectBox(set, mesh, bounds); break;
      case NodeSetDesc::Kind::Plane: selected = selectPlane(set, mesh, bounds); break;
      case NodeSetDesc::Kind::List: selected = selectList(set, mesh); break;
      case NodeSetDesc::Kind::BouFile: selected = selectBou(set, mesh, baseDir, limits); break;
    }
    std::sort(selected.begin(), selected.end());
    selected.erase(std::unique(selected.begin(), selected.end()), selected.end());
    if (selected.empty()) {
      if (set.kind == NodeSetDesc::Kind::Box)
        detail::fail(ErrorCode::BadInput, describeSet(set), " selects no nodes; the mesh's bounding box is ",
                     bounds.text(), ". Fix the box's coordinates so that it contains some nodes");
      detail::fail(ErrorCode::BadInput, describeSet(set), " selects no nodes (it lists none)");
    }
    return selected;
  });
}

}  // namespace corofem
