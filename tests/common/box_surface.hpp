// A render surface for tests: the closed, finely divided surface of a box.
#pragma once

#include <corofem/mesh.hpp>

#include <array>
#include <cstdint>

namespace corofem::test {

/// The closed surface of the box [lo, hi], each face an m x m grid of quads split in two triangles,
/// outward (counter-clockwise seen from outside). Vertices are not shared between faces.
inline SurfaceMesh boxSurface(const std::array<double, 3>& lo, const std::array<double, 3>& hi, int m) {
  SurfaceMesh s;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const int u = (axis + 1) % 3, w = (axis + 2) % 3;  // (u, w, axis) right-handed
      const auto base = static_cast<std::uint32_t>(s.vertexCount());
      for (int j = 0; j <= m; ++j)
        for (int i = 0; i <= m; ++i) {
          double p[3];
          p[axis] = side ? hi[axis] : lo[axis];
          p[u] = lo[u] + (hi[u] - lo[u]) * i / m;
          p[w] = lo[w] + (hi[w] - lo[w]) * j / m;
          s.vertices.insert(s.vertices.end(), {p[0], p[1], p[2]});
        }
      for (int j = 0; j < m; ++j)
        for (int i = 0; i < m; ++i) {
          const std::uint32_t a = base + j * (m + 1) + i, b = a + 1, c = a + (m + 1), d = c + 1;
          if (side) s.triangles.insert(s.triangles.end(), {a, b, d, a, d, c});
          else s.triangles.insert(s.triangles.end(), {a, d, b, a, c, d});
        }
    }
  return s;
}

}  // namespace corofem::test
