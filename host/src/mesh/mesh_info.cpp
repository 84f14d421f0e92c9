// computeMeshInfo and signedVolume: counts, bounding box, volumes, quality, boundary faces.
//
// Aspect ratio of a tet: longest edge / (2 sqrt(6) r), with inradius r = 3 V / (sum of face areas).
// For the regular tet of edge a, r = a / (2 sqrt(6)), so the ratio is 1; it grows without bound as a
// tet flattens (infinite for zero volume).
#include <corofem/mesh.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace corofem {
namespace {

struct Vec { double x, y, z; };
Vec sub(const Vec& a, const Vec& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Vec cross(const Vec& a, const Vec& b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
double dot(const Vec& a, const Vec& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
double norm(const Vec& a) { return std::sqrt(dot(a, a)); }
Vec nodeAt(const TetMesh& m, std::uint32_t i) { return {m.nodes[3 * i], m.nodes[3 * i + 1], m.nodes[3 * i + 2]}; }

bool elementValid(const TetMesh& mesh, std::size_t e) {
  const std::size_t n = mesh.nodeCount();
  for (int k = 0; k < 4; ++k)
    if (mesh.tets[4 * e + k] >= n) return false;
  return true;
}

}  // namespace

double signedVolume(const TetMesh& mesh, std::size_t element) {
  if (element >= mesh.tetCount() || !elementValid(mesh, element)) return std::numeric_limits<double>::quiet_NaN();
  const std::uint32_t* t = &mesh.tets[4 * element];
  const Vec a = nodeAt(mesh, t[0]);
  return dot(sub(nodeAt(mesh, t[1]), a), cross(sub(nodeAt(mesh, t[2]), a), sub(nodeAt(mesh, t[3]), a))) / 6.0;
}

MeshInfo computeMeshInfo(const TetMesh& mesh) {
  MeshInfo info;
  info.nodes = mesh.nodeCount();
  info.tets = mesh.tetCount();
  if (info.nodes > 0) {
    info.bboxMin = {mesh.nodes[0], mesh.nodes[1], mesh.nodes[2]};
    info.bboxMax = info.bboxMin;
    for (std::size_t i = 0; i < info.nodes; ++i)
      for (int a = 0; a < 3; ++a) {
        info.bboxMin[a] = std::min(info.bboxMin[a], mesh.nodes[3 * i + a]);
        info.bboxMax[a] = std::max(info.bboxMax[a], mesh.nodes[3 * i + a]);
      }
  }
  std::vector<char> used(info.nodes, 0);
  std::vector<std::array<std::uint32_t, 3>> faces;
  faces.reserve(4 * info.tets);
  info.minVolume = std::numeric_limits<double>::infinity();
  info.maxVolume = -std::numeric_limits<double>::infinity();
  info.minAspect = std::numeric_limits<double>::infinity();
  info.maxAspect = 0;
  static const int kFaces[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  for (std::size_t e = 0; e < info.tets; ++e) {
    if (!elementValid(mesh, e)) continue;  // only a hand-built mesh can have these; nothing to measure
    const std::uint32_t* t = &mesh.tets[4 * e];
    for (int k = 0; k < 4; ++k) used[t[k]] = 1;
    const double v = signedVolume(mesh, e);
    info.volume += std::abs(v);
    info.minVolume = std::min(info.minVolume, v);
    info.maxVolume = std::max(info.maxVolume, v);
    if (v < 0) ++info.negativeElements;

    Vec p[4];
    for (int k = 0; k < 4; ++k) p[k] = nodeAt(mesh, t[k]);
    double longest = 0;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) longest = std::max(longest, norm(sub(p[a], p[b])));
    double area = 0;
    for (const auto& f : kFaces) area += 0.5 * norm(cross(sub(p[f[1]], p[f[0]]), sub(p[f[2]], p[f[0]])));
    const double inradius = 3.0 * std::abs(v) / area;
    const double aspect = inradius > 0 ? longest / (2.0 * std::sqrt(6.0) * inradius)
                                       : std::numeric_limits<double>::infinity();
    info.minAspect = std::min(info.minAspect, aspect);
    info.maxAspect = std::max(info.maxAspect, aspect);

    for (const auto& f : kFaces) {
      std::array<std::uint32_t, 3> key = {t[f[0]], t[f[1]], t[f[2]]};
      std::sort(key.begin(), key.end());
      faces.push_back(key);
    }
  }
  if (info.tets == 0 || info.minVolume > info.maxVolume) {
    info.minVolume = info.maxVolume = 0;
    info.minAspect = info.maxAspect = 0;
  }
  // A boundary face belongs to exactly one tet: after sorting, a run of length 1.
  std::sort(faces.begin(), faces.end());
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && faces[j] == faces[i]) ++j;
    if (j - i == 1) ++info.boundaryFaces;
    i = j;
  }
  info.unusedNodes = static_cast<std::size_t>(std::count(used.begin(), used.end(), 0));
  return info;
}

}  // namespace corofem
