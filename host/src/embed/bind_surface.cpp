// bindSurface: binds every vertex of a fine surface to an element of a tet mesh (paper Section 5).
#include <corofem/embed.hpp>

#include "embed/element_locator.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <thread>

namespace corofem {
namespace {

using detail::ElementLocator;
using detail::fail;
using detail::Point3;

constexpr std::size_t kVerticesPerBindThread = 20000;  // below this a thread costs more than it saves
constexpr std::size_t kReportedVertices = 5;       // failures located by index and coordinates

void validateTetMesh(const TetMesh& mesh) {
  if (mesh.tets.empty() || mesh.nodes.empty())
    fail(ErrorCode::BadInput, "bindSurface: the tet mesh is empty (", mesh.nodeCount(), " nodes, ",
         mesh.tetCount(), " elements); load or generate the volume mesh before binding a surface to it");
  if (mesh.nodes.size() % 3 != 0 || mesh.tets.size() % 4 != 0)
    fail(ErrorCode::BadInput, "bindSurface: TetMesh::nodes has ", mesh.nodes.size(),
         " values (must be 3 per node) and TetMesh::tets ", mesh.tets.size(), " (must be 4 per element)");
  for (std::size_t i = 0; i < mesh.nodes.size(); ++i)
    if (!std::isfinite(mesh.nodes[i]))
      fail(ErrorCode::BadInput, "bindSurface: tet mesh node ", i / 3, " has a non-finite coordinate ",
           "xyz"[i % 3], " = ", mesh.nodes[i], "; fix the mesh");
  const std::size_t nodeCount = mesh.nodeCount();
  if (nodeCount > std::numeric_limits<std::uint32_t>::max())
    fail(ErrorCode::BadInput, "bindSurface: the tet mesh has ", nodeCount, " nodes, more than 32-bit indices hold");
  for (std::size_t i = 0; i < mesh.tets.size(); ++i)
    if (mesh.tets[i] >= nodeCount)
      fail(ErrorCode::BadInput, "bindSurface: element ", i / 4, " refers to node ", mesh.tets[i],
           " but the tet mesh has only ", nodeCount, " nodes (indices are 0-based)");
}

void validateSurface(const SurfaceMesh& surface) {
  if (surface.vertices.empty())
    fail(ErrorCode::BadInput, "bindSurface: the surface mesh has no vertices; there is nothing to bind");
  if (surface.vertices.size() % 3 != 0 || surface.triangles.size() % 3 != 0)
    fail(ErrorCode::BadInput, "bindSurface: SurfaceMesh::vertices has ", surface.vertices.size(),
         " values and SurfaceMesh::triangles ", surface.triangles.size(), " (both must be 3 per entry)");
  const std::size_t vertexCount = surface.vertexCount();
  if (vertexCount >= std::numeric_limits<std::uint32_t>::max() ||
      surface.triangleCount() >= std::numeric_limits<std::uint32_t>::max())
    fail(ErrorCode::BadInput, "bindSurface: the surface has ", vertexCount, " vertices and ",
         surface.triangleCount(), " triangles, more than 32-bit indices hold");
  for (std::size_t v = 0; v < vertexCount; ++v) {
    const double* x = &surface.vertices[3 * v];
    if (!std::isfinite(x[0]) || !std::isfinite(x[1]) || !std::isfinite(x[2]))
      fail(ErrorCode::BadInput, "bindSurface: surface vertex ", v, " has a non-finite coordinate (", x[0], ", ",
           x[1], ", ", x[2], "); fix or remove it");
  }
  for (std::size_t i = 0; i < surface.triangles.size(); ++i)
    if (surface.triangles[i] >= vertexCount)
      fail(ErrorCode::BadInput, "bindSurface: surface triangle ", i / 3, " refers to vertex ", surface.triangles[i],
           " but the surface has only ", vertexCount, " vertices (indices are 0-based)");
}

/// Per-thread result of the search over a range of vertices.
struct RangeResult {
  std::vector<std::uint32_t> tooFar;  // vertices farther than maxDistance, ascending
};

/// Vertex -> incident triangles, ascending triangle index (counting sort over the triangle list).
void buildVertexTriangles(SurfaceBinding& b, std::size_t vertexCount) {
  const std::size_t triangleCount = b.triangles.size() / 3;
  b.vertexTriangleOffsets.assign(vertexCount + 1, 0);
  for (std::uint32_t v : b.triangles) ++b.vertexTriangleOffsets[v + 1];
  for (std::size_t v = 0; v < vertexCount; ++v) b.vertexTriangleOffsets[v + 1] += b.vertexTriangleOffsets[v];
  b.vertexTriangles.resize(b.triangles.size());
  std::vector<std::uint32_t> cursor(b.vertexTriangleOffsets.begin(), b.vertexTriangleOffsets.end() - 1);
  for (std::size_t t = 0; t < triangleCount; ++t)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = b.triangles[3 * t + k];
      // A degenerate triangle listing a vertex twice is counted once per corner; harmless (its
      // normal is zero).
      b.vertexTriangles[cursor[v]++] = static_cast<std::uint32_t>(t);
    }
}

SurfaceBinding bind(const TetMesh& tets, const SurfaceMesh& surface, const BindingOptions& options) {
  validateTetMesh(tets);
  validateSurface(surface);
  if (!(options.insideTolerance >= 0.0) || !std::isfinite(options.insideTolerance))
    fail(ErrorCode::BadInput, "BindingOptions::insideTolerance is ", options.insideTolerance,
         "; it must be finite and >= 0 (typically 1e-10)");
  if (std::isnan(options.maxDistance))
    fail(ErrorCode::BadInput, "BindingOptions::maxDistance is NaN; give a distance in metres, or a negative "
         "value for the default (5% of the tet mesh's bounding-box diagonal)");

  const ElementLocator locator(tets, options.insideTolerance);
  const std::size_t vertexCount = surface.vertexCount();

  SurfaceBinding b;
  b.tetNodeCount = tets.nodeCount();
  b.element.assign(vertexCount, ElementLocator::kNone);
  b.nodes.resize(4 * vertexCount);
  b.weights.resize(4 * vertexCount);
  b.triangles = surface.triangles;
  BindingStatistics& s = b.statistics;
  s.boundingBoxDiagonal = locator.diagonal();
  s.maxDistanceUsed = options.maxDistance < 0.0 ? 0.05 * locator.diagonal() : options.maxDistance;
  std::vector<double> distance(vertexCount, 0.0);
  std::vector<char> outside(vertexCount, 0);

  auto bindRange = [&](std::size_t first, std::size_t last, RangeResult& out) {
    std::vector<std::uint32_t> stamp;
    std::uint32_t stampId = 0;
    for (std::size_t v = first; v < last; ++v) {
      const Point3 p{surface.vertices[3 * v], surface.vertices[3 * v + 1], surface.vertices[3 * v + 2]};
      double* w = &b.weights[4 * v];
      std::uint32_t e = locator.findContaining(p, w);
      if (e == ElementLocator::kNone) {
        if (stamp.empty()) stamp.assign(locator.elementCount(), 0u);
        const ElementLocator::Nearest nearest = locator.findNearest(p, s.maxDistanceUsed, stamp, stampId);
        if (nearest.element == ElementLocator::kNone) {
          out.tooFar.push_back(static_cast<std::uint32_t>(v));
          continue;
        }
        e = nearest.element;
        // Extrapolated barycentric coordinates: the element's affine map still reproduces p.
        locator.barycentric(e, p, w);
        distance[v] = nearest.distance;
        outside[v] = 1;
      }
      b.element[v] = e;
      for (int k = 0; k < 4; ++k) b.nodes[4 * v + k] = tets.tets[4 * e + k];
    }
  };

  std::size_t threadCount = 1;
  if (options.threads > 0)
    threadCount = std::min<std::size_t>(static_cast<std::size_t>(options.threads), vertexCount);
  else
    threadCount = std::clamp<std::size_t>((vertexCount + kVerticesPerBindThread - 1) / kVerticesPerBindThread, 1,
                                          std::max(1u, std::thread::hardware_concurrency()));
  std::vector<RangeResult> results(threadCount);
  if (threadCount == 1) {
    bindRange(0, vertexCount, results[0]);
  } else {
    // Ranges are contiguous and each vertex is bound on its own: the result does not depend on the
    // thread count. Exceptions stay inside the workers (bad_alloc is reported below).
    std::vector<std::thread> workers;
    std::vector<char> failed(threadCount, 0);
    for (std::size_t t = 0; t < threadCount; ++t) {
      const std::size_t first = vertexCount * t / threadCount, last = vertexCount * (t + 1) / threadCount;
      workers.emplace_back([&, t, first, last] {
        try {
          bindRange(first, last, results[t]);
        } catch (...) {
          failed[t] = 1;
        }
      });
    }
    for (auto& w : workers) w.join();
    for (char f : failed)
      if (f) fail(ErrorCode::Internal, "bindSurface: a worker thread failed (out of memory?)");
  }

  std::vector<std::uint32_t> tooFar;
  for (const RangeResult& r : results) tooFar.insert(tooFar.end(), r.tooFar.begin(), r.tooFar.end());
  if (!tooFar.empty()) {
    std::ostringstream os;
    os << "bindSurface: " << tooFar.size() << " of " << vertexCount
       << " surface vertices lie farther than BindingOptions::maxDistance = " << s.maxDistanceUsed
       << (options.maxDistance < 0.0 ? " (the default, 5% of the tet mesh's bounding-box diagonal "
                                     : " (tet mesh bounding-box diagonal ")
       << locator.diagonal() << ") from every element: ";
    std::vector<std::uint32_t> stamp(locator.elementCount(), 0u);
    std::uint32_t stampId = 0;
    double farthestShown = 0.0;
    for (std::size_t i = 0; i < std::min(tooFar.size(), kReportedVertices); ++i) {
      const std::uint32_t v = tooFar[i];
      const Point3 p{surface.vertices[3 * v], surface.vertices[3 * v + 1], surface.vertices[3 * v + 2]};
      const double d = locator.findNearest(p, std::numeric_limits<double>::infinity(), stamp, stampId).distance;
      farthestShown = std::max(farthestShown, d);
      os << (i ? "; " : "") << "vertex " << v << " at (" << p[0] << ", " << p[1] << ", " << p[2] << ") is " << d
         << " away";
    }
    if (tooFar.size() > kReportedVertices) os << "; and " << tooFar.size() - kReportedVertices << " more";
    os << ". Move the surface into the tet mesh (same units and placement?), or raise "
          "BindingOptions::maxDistance (to at least "
       << farthestShown << " for the vertices shown)";
    fail(ErrorCode::BadInput, os.str());
  }

  for (std::size_t v = 0; v < vertexCount; ++v) {
    if (outside[v]) {
      s.outsideVertices.push_back(static_cast<std::uint32_t>(v));
      s.outsideDistances.push_back(distance[v]);
      s.largestDistance = std::max(s.largestDistance, distance[v]);
    }
  }
  s.outsideCount = s.outsideVertices.size();
  s.insideCount = vertexCount - s.outsideCount;
  buildVertexTriangles(b, vertexCount);
  return b;
}

}  // namespace

Result<SurfaceBinding> bindSurface(const TetMesh& tets, const SurfaceMesh& surface, const BindingOptions& options) {
  return detail::guardResult<SurfaceBinding>([&] { return bind(tets, surface, options); });
}

}  // namespace corofem
