// Uniform grid of element bounding boxes: containing-element and nearest-element queries.
#include "embed/element_locator.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace corofem::detail {
namespace {

double dot(const Point3& a, const Point3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Point3 sub(const Point3& a, const Point3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Point3 cross(const Point3& a, const Point3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

/// Distance from p to the axis-aligned box [lo, hi].
double pointBoxDistance(const Point3& p, const Point3& lo, const Point3& hi) {
  double s = 0.0;
  for (int a = 0; a < 3; ++a) {
    const double d = std::max({lo[a] - p[a], 0.0, p[a] - hi[a]});
    s += d * d;
  }
  return std::sqrt(s);
}

}  // namespace

double pointTriangleDistanceSquared(const Point3& p, const Point3& a, const Point3& b, const Point3& c) {
  // Ericson, Real-Time Collision Detection, ClosestPtPointTriangle: classify p against the Voronoi
  // regions of the vertices, then the edges, else project onto the face.
  const Point3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  auto dist2 = [&](const Point3& q) {
    const Point3 d = sub(p, q);
    return dot(d, d);
  };
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return dist2(a);
  const Point3 bp = sub(p, b);
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return dist2(b);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double v = d1 / (d1 - d3);
    return dist2({a[0] + v * ab[0], a[1] + v * ab[1], a[2] + v * ab[2]});
  }
  const Point3 cp = sub(p, c);
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return dist2(c);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double w = d2 / (d2 - d6);
    return dist2({a[0] + w * ac[0], a[1] + w * ac[1], a[2] + w * ac[2]});
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return dist2({b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2])});
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return dist2({a[0] + ab[0] * v + ac[0] * w, a[1] + ab[1] * v + ac[1] * w, a[2] + ab[2] * v + ac[2] * w});
}

ElementLocator::ElementLocator(const TetMesh& mesh, double insideTolerance)
    : nodes_(mesh.nodes.data()), tets_(mesh.tets.data()), tolerance_(insideTolerance) {
  const std::size_t elementCount = mesh.tetCount();
  dmInv_.resize(elementCount);
  bboxLo_.resize(elementCount);
  bboxHi_.resize(elementCount);

  Point3 meshLo{}, meshHi{}, nodeLo{}, nodeHi{};  // padded element boxes; the nodes alone
  for (int a = 0; a < 3; ++a) {
    meshLo[a] = nodeLo[a] = std::numeric_limits<double>::infinity();
    meshHi[a] = nodeHi[a] = -std::numeric_limits<double>::infinity();
  }
  for (std::size_t e = 0; e < elementCount; ++e) {
    const std::uint32_t* t = tets_ + 4 * e;
    const Point3 x0 = node(t[0]);
    const Point3 e1 = sub(node(t[1]), x0), e2 = sub(node(t[2]), x0), e3 = sub(node(t[3]), x0);
    // D_m = [e1 e2 e3] (columns); its inverse has rows (e2 x e3, e3 x e1, e1 x e2) / det(D_m).
    const Point3 r1 = cross(e2, e3), r2 = cross(e3, e1), r3 = cross(e1, e2);
    const double det = dot(e1, r1);
    const double inv = 1.0 / det;
    std::array<double, 9>& m = dmInv_[e];
    for (int a = 0; a < 3; ++a) {
      m[a] = r1[a] * inv;
      m[3 + a] = r2[a] * inv;
      m[6 + a] = r3[a] * inv;
    }
    bool finite = det != 0.0;
    for (double v : m) finite = finite && std::isfinite(v);
    if (!finite)
      fail(ErrorCode::BadInput, "bindSurface: element ", e, " is flat (zero volume; nodes ", t[0], ", ", t[1],
           ", ", t[2], ", ", t[3], "), so no point has barycentric coordinates in it; remove it or fix the "
           "coordinates of its nodes");
    Point3 lo = x0, hi = x0;
    double extent = 0.0;
    for (int k = 1; k < 4; ++k) {
      const Point3 x = node(t[k]);
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], x[a]);
        hi[a] = std::max(hi[a], x[a]);
      }
    }
    for (int a = 0; a < 3; ++a) {
      extent = std::max(extent, hi[a] - lo[a]);
      nodeLo[a] = std::min(nodeLo[a], lo[a]);
      nodeHi[a] = std::max(nodeHi[a], hi[a]);
    }
    // A point with all w_k >= -tol lies within about 3 tol * extent of the element (each negative w_k
    // moves it at most |w_k| times an edge length outside): pad the box by 4 tol * extent.
    const double pad = 4.0 * tolerance_ * extent;
    for (int a = 0; a < 3; ++a) {
      lo[a] -= pad;
      hi[a] += pad;
      meshLo[a] = std::min(meshLo[a], lo[a]);
      meshHi[a] = std::max(meshHi[a], hi[a]);
    }
    bboxLo_[e] = lo;
    bboxHi_[e] = hi;
  }
  if (elementCount == 0) return;
  diagonal_ = std::sqrt(dot(sub(nodeHi, nodeLo), sub(nodeHi, nodeLo)));

  // Grid: about one cell per element, cubic cells as far as the box allows.
  const double tiny = 1e-12 * diagonal_;
  double boxVolume = 1.0;
  for (int a = 0; a < 3; ++a) boxVolume *= std::max(meshHi[a] - meshLo[a], tiny);
  const double cell = std::cbrt(boxVolume / static_cast<double>(elementCount));
  lo_ = meshLo;
  for (int a = 0; a < 3; ++a) {
    const double extent = std::max(meshHi[a] - meshLo[a], tiny);
    dims_[a] = static_cast<int>(std::clamp(std::ceil(extent / cell), 1.0, 2048.0));
    h_[a] = extent / dims_[a];
  }
  auto cellRange = [&](std::size_t e, int a, int& first, int& last) {
    first = std::clamp(static_cast<int>(std::floor((bboxLo_[e][a] - lo_[a]) / h_[a])), 0, dims_[a] - 1);
    last = std::clamp(static_cast<int>(std::floor((bboxHi_[e][a] - lo_[a]) / h_[a])), 0, dims_[a] - 1);
  };
  const std::size_t cellCount = static_cast<std::size_t>(dims_[0]) * dims_[1] * dims_[2];
  cellStart_.assign(cellCount + 1, 0);
  // Two passes (count, fill) in element order: each cell's list is ascending in element index.
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<std::uint32_t> cursor;
    if (pass == 1) {
      for (std::size_t c = 0; c < cellCount; ++c) cellStart_[c + 1] += cellStart_[c];
      cellElements_.resize(cellStart_[cellCount]);
      cursor.assign(cellStart_.begin(), cellStart_.end() - 1);
    }
    for (std::size_t e = 0; e < elementCount; ++e) {
      int i0, i1, j0, j1, k0, k1;
      cellRange(e, 0, i0, i1);
      cellRange(e, 1, j0, j1);
      cellRange(e, 2, k0, k1);
      for (int k = k0; k <= k1; ++k)
        for (int j = j0; j <= j1; ++j)
          for (int i = i0; i <= i1; ++i) {
            const std::size_t c = cellIndex(i, j, k);
            if (pass == 0)
              ++cellStart_[c + 1];
            else
              cellElements_[cursor[c]++] = static_cast<std::uint32_t>(e);
          }
    }
  }
}

void ElementLocator::barycentric(std::size_t e, const Point3& p, double w[4]) const {
  const std::uint32_t n0 = tets_[4 * e];
  const double d[3] = {p[0] - nodes_[3 * n0], p[1] - nodes_[3 * n0 + 1], p[2] - nodes_[3 * n0 + 2]};
  const std::array<double, 9>& m = dmInv_[e];
  w[1] = m[0] * d[0] + m[1] * d[1] + m[2] * d[2];
  w[2] = m[3] * d[0] + m[4] * d[1] + m[5] * d[2];
  w[3] = m[6] * d[0] + m[7] * d[1] + m[8] * d[2];
  w[0] = 1.0 - w[1] - w[2] - w[3];
}

std::uint32_t ElementLocator::findContaining(const Point3& p, double w[4]) const {
  int cell[3];
  for (int a = 0; a < 3; ++a) {
    const double t = (p[a] - lo_[a]) / h_[a];
    if (!(t >= 0.0 && t <= dims_[a])) return kNone;  // outside every padded element box (or NaN)
    cell[a] = std::min(static_cast<int>(t), dims_[a] - 1);
  }
  const std::size_t c = cellIndex(cell[0], cell[1], cell[2]);
  // The cell's list is ascending, so the first element that contains p is the lowest-index one.
  for (std::uint32_t q = cellStart_[c]; q < cellStart_[c + 1]; ++q) {
    const std::uint32_t e = cellElements_[q];
    const Point3& lo = bboxLo_[e];
    const Point3& hi = bboxHi_[e];
    if (p[0] < lo[0] || p[0] > hi[0] || p[1] < lo[1] || p[1] > hi[1] || p[2] < lo[2] || p[2] > hi[2]) continue;
    barycentric(e, p, w);
    if (w[0] >= -tolerance_ && w[1] >= -tolerance_ && w[2] >= -tolerance_ && w[3] >= -tolerance_) return e;
  }
  return kNone;
}

double ElementLocator::pointTetDistance(std::size_t e, const Point3& p) const {
  double w[4];
  barycentric(e, p, w);
  // The nearest point of a tetrahedron to an outside point lies on a face whose plane separates them,
  // i.e. a face opposite a vertex with w_k < 0. Every face distance is >= the true distance, so the
  // minimum over those faces is the distance.
  const std::uint32_t* t = tets_ + 4 * e;
  double best = std::numeric_limits<double>::infinity();
  bool outside = false;
  for (int k = 0; k < 4; ++k) {
    if (w[k] >= 0.0) continue;
    outside = true;
    const Point3 a = node(t[(k + 1) & 3]), b = node(t[(k + 2) & 3]), c = node(t[(k + 3) & 3]);
    best = std::min(best, pointTriangleDistanceSquared(p, a, b, c));
  }
  return outside ? std::sqrt(best) : 0.0;
}

ElementLocator::Nearest ElementLocator::findNearest(const Point3& p, double cutoff,
                                                    std::vector<std::uint32_t>& stamp,
                                                    std::uint32_t& stampId) const {
  if (++stampId == 0) {  // wrapped: clear the marks
    std::fill(stamp.begin(), stamp.end(), 0u);
    stampId = 1;
  }
  const double tie = 1e-12 * diagonal_;
  int c[3];
  for (int a = 0; a < 3; ++a) {
    const double t = std::floor((p[a] - lo_[a]) / h_[a]);
    c[a] = static_cast<int>(std::clamp(t, 0.0, static_cast<double>(dims_[a] - 1)));
  }
  Nearest best{kNone, std::numeric_limits<double>::infinity()};
  auto visitCell = [&](int i, int j, int k) {
    const std::size_t cell = cellIndex(i, j, k);
    for (std::uint32_t q = cellStart_[cell]; q < cellStart_[cell + 1]; ++q) {
      const std::uint32_t e = cellElements_[q];
      if (stamp[e] == stampId) continue;
      stamp[e] = stampId;
      const double bound = std::min(best.distance, cutoff) + tie;
      if (pointBoxDistance(p, bboxLo_[e], bboxHi_[e]) > bound) continue;
      const double d = pointTetDistance(e, p);
      if (d > bound) continue;
      if (d < best.distance - tie || e < best.element) best.element = e;
      best.distance = std::min(best.distance, d);
    }
  };
  const int maxRing = std::max({dims_[0], dims_[1], dims_[2]});
  for (int r = 0; r <= maxRing; ++r) {
    int b0[3], b1[3];
    for (int a = 0; a < 3; ++a) {
      b0[a] = std::max(c[a] - r, 0);
      b1[a] = std::min(c[a] + r, dims_[a] - 1);
    }
    // Visit the shell of cells at Chebyshev distance exactly r from c (clipped to the grid).
    for (int k = b0[2]; k <= b1[2]; ++k)
      for (int j = b0[1]; j <= b1[1]; ++j) {
        const bool onShell = std::abs(k - c[2]) == r || std::abs(j - c[1]) == r;
        if (onShell) {
          for (int i = b0[0]; i <= b1[0]; ++i) visitCell(i, j, k);
        } else {
          if (c[0] - r >= 0) visitCell(c[0] - r, j, k);
          if (r > 0 && c[0] + r < dims_[0]) visitCell(c[0] + r, j, k);
        }
      }
    // Every unvisited element lies in the grid outside the box of visited cells, i.e. in one of the
    // slabs beyond a side of that box that is not the grid's own side: the distance from p to the
    // nearest such slab bounds the distance to every unvisited element from below.
    double lowerBound = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
      for (int side = 0; side < 2; ++side) {
        if (side == 0 ? b0[a] == 0 : b1[a] == dims_[a] - 1) continue;
        Point3 slabLo = lo_, slabHi{};
        for (int x = 0; x < 3; ++x) slabHi[x] = lo_[x] + dims_[x] * h_[x];
        if (side == 0)
          slabHi[a] = lo_[a] + b0[a] * h_[a];
        else
          slabLo[a] = lo_[a] + (b1[a] + 1) * h_[a];
        lowerBound = std::min(lowerBound, pointBoxDistance(p, slabLo, slabHi));
      }
    }
    if (lowerBound > std::min(best.distance, cutoff) + tie) break;  // also: every cell visited
  }
  if (best.element != kNone && best.distance > cutoff) best.element = kNone;
  return best;
}

}  // namespace corofem::detail
