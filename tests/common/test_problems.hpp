// Hand-built problems for the device tests and benchmarks (no scene, no OpenCL): a problem from a
// mesh with the elements set up by model/element.hpp, random element soups, Kuhn-split boxes, random
// vectors and rotations, and a bitwise comparison of vectors.
#pragma once

#include "common/random_vector.hpp"
#include "model/element.hpp"
#include "model/problem.hpp"

#include <Eigen/Geometry>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <utility>

namespace corofem::test {

/// A problem from a mesh with the elements set up by detail::computeElementRest (no scene needed).
inline detail::Problem makeProblem(const TetMesh& mesh, double E = 1e5, double nu = 0.3,
                                   double density = 1000.0,
                                   Formulation formulation = Formulation::Corotational) {
  detail::Problem p;
  p.name = "test-body";
  p.mesh = mesh;
  const std::size_t n = mesh.nodeCount();
  p.restPositions = Eigen::Map<const Eigen::VectorXd>(mesh.nodes.data(), static_cast<Eigen::Index>(3 * n));
  p.lame = detail::lameFromYoungPoisson(E, nu);
  p.density = density;
  p.formulation = formulation;
  p.lumpedMass = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(3 * n));
  for (std::size_t e = 0; e < mesh.tetCount(); ++e) {
    std::array<detail::Vec3d, 4> X;
    for (int k = 0; k < 4; ++k) X[k] = p.restPositions.segment<3>(3 * mesh.tets[4 * e + k]);
    p.elements.push_back(detail::computeElementRest(X));
    for (int k = 0; k < 4; ++k)
      p.lumpedMass.segment<3>(3 * mesh.tets[4 * e + k]).array() += density * p.elements.back().volume / 4.0;
  }
  p.constrained.assign(3 * n, 0);
  p.initialVelocity = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(3 * n));
  return p;
}

/// Whether two vectors hold the same bits (same size, memcmp-equal).
inline bool sameBits(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
}

inline detail::Mat3 randomRotation(std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
  q.normalize();
  return q.toRotationMatrix();
}

/// A soup of `count` disconnected, well-shaped random tetrahedra (4 nodes each, edges ~0.5-2 m,
/// centred within 3 m of the origin), so that each node's force is one element's force.
inline TetMesh randomSoup(std::size_t count, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0), scale(0.5, 2.0);
  TetMesh mesh;
  const detail::Vec3d regular[4] = {{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}};
  for (std::size_t e = 0; e < count; ++e) {
    const double s = scale(rng) * 0.5;
    const detail::Mat3 R = randomRotation(rng);
    const detail::Vec3d c(3 * u(rng), 3 * u(rng), 3 * u(rng));
    std::array<detail::Vec3d, 4> X;
    for (int k = 0; k < 4; ++k) {
      detail::Vec3d jitter(u(rng), u(rng), u(rng));
      X[k] = c + s * R * (regular[k] + 0.25 * jitter);
    }
    // keep positive orientation
    if ((X[1] - X[0]).dot((X[2] - X[0]).cross(X[3] - X[0])) < 0) std::swap(X[2], X[3]);
    for (int k = 0; k < 4; ++k) {
      for (int j = 0; j < 3; ++j) mesh.nodes.push_back(X[k][j]);
      mesh.tets.push_back(static_cast<std::uint32_t>(4 * e + k));
    }
  }
  return mesh;
}

/// A box of nx*ny*nz cells of hx x hy x hz, each split into 6 tetrahedra (Kuhn: conforming);
/// reference/small_meshes.hpp's boxMesh takes the box's sides instead, and can perturb it.
inline TetMesh cellBox(int nx, int ny, int nz, double hx = 1.0, double hy = 1.0, double hz = 1.0) {
  TetMesh mesh;
  auto id = [&](int i, int j, int k) { return static_cast<std::uint32_t>((k * (ny + 1) + j) * (nx + 1) + i); };
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        mesh.nodes.push_back(i * hx);
        mesh.nodes.push_back(j * hy);
        mesh.nodes.push_back(k * hz);
      }
  // Kuhn split of the cube along the main diagonal 0-7: 6 tets through the paths of axis steps.
  static const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        for (const auto& perm : perms) {
          int c[3] = {i, j, k};
          std::uint32_t v[4];
          v[0] = id(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[perm[s]];
            v[s + 1] = id(c[0], c[1], c[2]);
          }
          const double* p[4];
          for (int s = 0; s < 4; ++s) p[s] = &mesh.nodes[3 * v[s]];
          const double a[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
          const double b[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
          const double d[3] = {p[3][0] - p[0][0], p[3][1] - p[0][1], p[3][2] - p[0][2]};
          const double vol = a[0] * (b[1] * d[2] - b[2] * d[1]) - a[1] * (b[0] * d[2] - b[2] * d[0]) +
                             a[2] * (b[0] * d[1] - b[1] * d[0]);
          if (vol < 0) std::swap(v[2], v[3]);
          for (auto x : v) mesh.tets.push_back(x);
        }
  return mesh;
}

}  // namespace corofem::test
