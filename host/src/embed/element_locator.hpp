// Point location in a tetrahedral mesh: which element contains a point, and which element is nearest
// to a point outside the mesh. A uniform grid of element bounding boxes (cells about the size of an
// element) makes both queries touch only a few elements. Used by bindSurface (coupled mesh).
#pragma once

#include <corofem/mesh.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace corofem::detail {

using Point3 = std::array<double, 3>;

/// Closest point on triangle (a, b, c) to p; returns the squared distance (Ericson, Real-Time
/// Collision Detection, 5.1.5: Voronoi regions of vertices, edges, face).
double pointTriangleDistanceSquared(const Point3& p, const Point3& a, const Point3& b, const Point3& c);

class ElementLocator {
 public:
  static constexpr std::uint32_t kNone = 0xffffffffu;

  /// Precomputes D_m^-1 = [X1-X0, X2-X0, X3-X0]^-1 and the bounding box of every element, and the
  /// grid. The mesh must outlive the locator and be validated (indices in range, finite nodes).
  /// `insideTolerance` (barycentric) widens the boxes so that every element that contains a point
  /// within the tolerance is registered in the point's cell. Throws Error(BadInput) for a flat element.
  ElementLocator(const TetMesh& mesh, double insideTolerance);

  /// Barycentric coordinates of p in element e: (w1 w2 w3) = D_m^-1 (p - X0), w0 = 1 - w1 - w2 - w3.
  /// Affine, so sum_k w_k X_k = p exactly (up to rounding) also for p outside the element.
  void barycentric(std::size_t e, const Point3& p, double w[4]) const;

  /// Lowest-index element whose barycentric coordinates of p are all >= -tolerance; kNone if none.
  /// w receives the coordinates in that element.
  std::uint32_t findContaining(const Point3& p, double w[4]) const;

  /// Element at the smallest point-to-tetrahedron distance from p (ties within 1e-12 of the bounding
  /// box diagonal: lowest index), searched in growing rings of grid cells until no unvisited cell
  /// can be closer. Returns kNone when no element is within `cutoff`. `stamp` (size elementCount(),
  /// owned by the calling thread) marks visited elements.
  struct Nearest {
    std::uint32_t element = kNone;
    double distance = 0.0;
  };
  Nearest findNearest(const Point3& p, double cutoff, std::vector<std::uint32_t>& stamp,
                      std::uint32_t& stampId) const;

  /// True distance from p to element e (0 when p is inside).
  double pointTetDistance(std::size_t e, const Point3& p) const;

  std::size_t elementCount() const { return bboxLo_.size(); }
  double diagonal() const { return diagonal_; }
  std::array<int, 3> gridDims() const { return {dims_[0], dims_[1], dims_[2]}; }

 private:
  Point3 node(std::uint32_t n) const { return {nodes_[3 * n], nodes_[3 * n + 1], nodes_[3 * n + 2]}; }
  std::size_t cellIndex(int i, int j, int k) const {
    return (static_cast<std::size_t>(k) * dims_[1] + j) * dims_[0] + i;
  }

  const double* nodes_;
  const std::uint32_t* tets_;
  double tolerance_;
  double diagonal_ = 0.0;
  std::vector<std::array<double, 9>> dmInv_;  // row-major
  std::vector<Point3> bboxLo_, bboxHi_;
  Point3 lo_{}, h_{};                          // grid origin and cell size per axis
  int dims_[3] = {1, 1, 1};
  std::vector<std::uint32_t> cellStart_;       // CSR: cell -> elements, ascending element index
  std::vector<std::uint32_t> cellElements_;
};

}  // namespace corofem::detail
