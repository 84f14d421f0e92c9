// Tiny meshes and hand-built problems for the element / reference-backend tests (independent of the
// mesh generator and the scene code, so these tests only exercise model/ and backends/reference/).
#pragma once

#include "common/test_problems.hpp"  // makeProblem, randomRotation
#include "model/element.hpp"
#include "model/problem.hpp"

#include <corofem/mesh.hpp>

#include <Eigen/Dense>
#include <Eigen/Geometry>

#include <array>
#include <cmath>
#include <random>
#include <vector>

namespace corofem::test {

using detail::Mat3;
using detail::Vec3d;

/// Rodrigues rotation about a (not necessarily unit) axis by angle (rad).
inline Mat3 rotation(const Vec3d& axis, double angle) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}

/// A random, reasonably shaped tetrahedron: the regular one (edge ~1) under a random rotation, a
/// moderate random stretch (0.5-2 per axis), scale and offset. Positively oriented.
inline std::array<Vec3d, 4> randomElement(std::mt19937& rng, double scale = 1.0) {
  std::uniform_real_distribution<double> u(0.5, 2.0), off(-3.0, 3.0);
  const std::array<Vec3d, 4> regular = {Vec3d(1, 1, 1), Vec3d(1, -1, -1), Vec3d(-1, 1, -1), Vec3d(-1, -1, 1)};
  const Mat3 A = randomRotation(rng) * Vec3d(u(rng), u(rng), u(rng)).asDiagonal() * randomRotation(rng);
  const Vec3d t(off(rng), off(rng), off(rng));
  std::array<Vec3d, 4> X;
  for (int i = 0; i < 4; ++i) X[i] = scale * (0.5 * A * regular[i] + t);
  if (detail::signedVolume(X) < 0) std::swap(X[2], X[3]);
  return X;
}

/// Box [0, lx] x [0, ly] x [0, lz] with nx x ny x nz cells, each split into 6 tetrahedra around the
/// cell's main diagonal (Kuhn split: conforming), every element positively oriented. Interior nodes
/// are moved by up to `perturb` times the cell size on each axis (seeded), boundary nodes stay.
inline TetMesh boxMesh(int nx, int ny, int nz, double lx = 1.0, double ly = 1.0, double lz = 1.0,
                       double perturb = 0.0, unsigned seed = 1) {
  TetMesh mesh;
  const auto id = [&](int i, int j, int k) { return static_cast<std::uint32_t>(i + (nx + 1) * (j + (ny + 1) * k)); };
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-perturb, perturb);
  const double hx = lx / nx, hy = ly / ny, hz = lz / nz;
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        double x = i * hx, y = j * hy, z = k * hz;
        const bool interior = i > 0 && i < nx && j > 0 && j < ny && k > 0 && k < nz;
        if (interior && perturb > 0) {
          x += u(rng) * hx;
          y += u(rng) * hy;
          z += u(rng) * hz;
        }
        mesh.nodes.insert(mesh.nodes.end(), {x, y, z});
      }
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        for (const auto& p : perms) {
          int c[3] = {0, 0, 0};
          std::array<std::uint32_t, 4> t;
          t[0] = id(i, j, k);
          for (int s = 0; s < 3; ++s) {
            c[p[s]] = 1;
            t[s + 1] = id(i + c[0], j + c[1], k + c[2]);
          }
          std::array<Vec3d, 4> X;
          for (int a = 0; a < 4; ++a) X[a] = Vec3d(&mesh.nodes[3 * t[a]]);
          if (detail::signedVolume(X) < 0) std::swap(t[2], t[3]);
          mesh.tets.insert(mesh.tets.end(), t.begin(), t.end());
        }
  return mesh;
}

/// Element node positions of element e in a 3N vector.
inline std::array<Vec3d, 4> elementNodes(const detail::Problem& p, const Eigen::VectorXd& x, std::size_t e) {
  std::array<Vec3d, 4> out;
  for (int k = 0; k < 4; ++k) out[k] = x.segment<3>(3 * p.mesh.tets[4 * e + k]);
  return out;
}

}  // namespace corofem::test
