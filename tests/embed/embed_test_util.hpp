// Helpers for the coupled-mesh tests: a Vega .interp reader, smooth test deformations, small meshes.
#pragma once

#include <corofem/embed.hpp>
#include <corofem/mesh.hpp>

#include <Eigen/Dense>

#include <array>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace corofem::test {

/// One row of a Vega interpolation file: `i v0 w0 v1 w1 v2 w2 v3 w3` (0-based vertex and node ids).
struct VegaInterpRow {
  std::array<std::uint32_t, 4> nodes{};
  std::array<double, 4> weights{};
};

/// Reads a Vega .interp file; one row per OBJ vertex, in order. Throws std::runtime_error on a
/// malformed line (tests only).
inline std::vector<VegaInterpRow> readVegaInterp(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open " + path);
  std::vector<VegaInterpRow> rows;
  std::string line;
  std::size_t lineNumber = 0;
  while (std::getline(in, line)) {
    ++lineNumber;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    std::istringstream is(line);
    std::size_t index = 0;
    VegaInterpRow row;
    is >> index;
    for (int k = 0; k < 4; ++k) is >> row.nodes[k] >> row.weights[k];
    if (!is || index != rows.size())
      throw std::runtime_error(path + ":" + std::to_string(lineNumber) + ": malformed interp row");
    rows.push_back(row);
  }
  return rows;
}

/// A smooth map of R^3: x -> Q (A x + a .* sin(K x + phase)) + t with Q a rotation. With amplitude 0
/// it is affine; otherwise nonlinear on the scale 1/|K|.
struct SmoothDeformation {
  Eigen::Matrix3d Q = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d K = Eigen::Matrix3d::Zero();
  Eigen::Vector3d amplitude = Eigen::Vector3d::Zero();
  Eigen::Vector3d phase = Eigen::Vector3d::Zero();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();

  Eigen::Vector3d operator()(const Eigen::Vector3d& x) const {
    const Eigen::Vector3d arg = K * x + phase;
    Eigen::Vector3d wave(std::sin(arg[0]), std::sin(arg[1]), std::sin(arg[2]));
    return Q * (A * x + amplitude.cwiseProduct(wave)) + t;
  }

  /// Random rotation, random affine A near the identity (stretch up to +-30%), a translation of the
  /// order of `size`; when nonlinear, waves of wavelength about `size`/2 and amplitude 5% of `size`.
  static SmoothDeformation random(std::mt19937& rng, double size, bool nonlinear) {
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    SmoothDeformation d;
    Eigen::Quaterniond q(u(rng), u(rng), u(rng), u(rng));
    d.Q = q.normalized().toRotationMatrix();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) d.A(i, j) = (i == j ? 1.0 : 0.0) + 0.3 * u(rng);
    for (int i = 0; i < 3; ++i) d.t[i] = size * u(rng);
    if (nonlinear) {
      const double k = 4.0 * M_PI / size;
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) d.K(i, j) = k * u(rng);
        d.amplitude[i] = 0.05 * size * (0.5 + 0.5 * std::abs(u(rng)));
        d.phase[i] = M_PI * u(rng);
      }
    }
    return d;
  }

  /// Applies the map to 3-per-node positions.
  std::vector<double> apply(const std::vector<double>& x) const {
    std::vector<double> y(x.size());
    for (std::size_t i = 0; i + 2 < x.size(); i += 3) {
      const Eigen::Vector3d p = (*this)(Eigen::Vector3d(x[i], x[i + 1], x[i + 2]));
      for (int a = 0; a < 3; ++a) y[i + a] = p[a];
    }
    return y;
  }
};

inline Eigen::Vector3d point(const std::vector<double>& xyz, std::size_t i) {
  return {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]};
}

/// Exact barycentric coordinates of p in the tetrahedron of the 4 given nodes (solved with a
/// column-pivoted QR of the 3x3 edge matrix).
inline std::array<double, 4> exactBarycentric(const std::vector<double>& nodes,
                                              const std::array<std::uint32_t, 4>& tet, const Eigen::Vector3d& p) {
  const Eigen::Vector3d x0 = point(nodes, tet[0]);
  Eigen::Matrix3d Dm;
  for (int k = 0; k < 3; ++k) Dm.col(k) = point(nodes, tet[k + 1]) - x0;
  const Eigen::Vector3d w = Dm.colPivHouseholderQr().solve(p - x0);
  return {1.0 - w.sum(), w[0], w[1], w[2]};
}

/// sum_k w_k x_{n_k} for 4 nodes and weights.
template <class Nodes, class Weights>
Eigen::Vector3d interpolate(const std::vector<double>& x, const Nodes& nodes, const Weights& w) {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) p += w[k] * point(x, nodes[k]);
  return p;
}

/// Bounding-box diagonal of 3-per-point coordinates.
inline double diagonalOf(const std::vector<double>& xyz) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  for (std::size_t i = 0; i < xyz.size() / 3; ++i) {
    lo = lo.cwiseMin(point(xyz, i));
    hi = hi.cwiseMax(point(xyz, i));
  }
  return (hi - lo).norm();
}

/// One tetrahedron: nodes (0,0,0), (1,0,0), (0,1,0), (0,0,1).
inline TetMesh unitTet() {
  TetMesh m;
  m.nodes = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  m.tets = {0, 1, 2, 3};
  return m;
}

/// A surface made of the given points and no triangles.
inline SurfaceMesh pointCloud(const std::vector<double>& xyz) {
  SurfaceMesh s;
  s.vertices = xyz;
  return s;
}

/// Latitude-longitude sphere: `stacks` rings of `slices` vertices plus the two poles, triangles
/// counter-clockwise seen from outside (so (b-a) x (c-a) points outwards).
/// (stacks - 1) * slices + 2 vertices, 2 * slices * (stacks - 1) triangles.
inline SurfaceMesh uvSphere(const std::array<double, 3>& center, double radius, int stacks, int slices) {
  SurfaceMesh s;
  auto add = [&](double theta, double phi) {
    s.vertices.push_back(center[0] + radius * std::sin(theta) * std::cos(phi));
    s.vertices.push_back(center[1] + radius * std::sin(theta) * std::sin(phi));
    s.vertices.push_back(center[2] + radius * std::cos(theta));
  };
  add(0.0, 0.0);  // north pole, vertex 0
  for (int i = 1; i < stacks; ++i)
    for (int j = 0; j < slices; ++j) add(M_PI * i / stacks, 2.0 * M_PI * j / slices);
  add(M_PI, 0.0);  // south pole
  const std::uint32_t south = static_cast<std::uint32_t>(s.vertexCount() - 1);
  auto ring = [&](int i, int j) { return static_cast<std::uint32_t>(1 + (i - 1) * slices + (j % slices)); };
  for (int j = 0; j < slices; ++j) s.triangles.insert(s.triangles.end(), {0u, ring(1, j), ring(1, j + 1)});
  for (int i = 1; i + 1 < stacks; ++i)
    for (int j = 0; j < slices; ++j) {
      s.triangles.insert(s.triangles.end(), {ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      s.triangles.insert(s.triangles.end(), {ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  for (int j = 0; j < slices; ++j)
    s.triangles.insert(s.triangles.end(), {south, ring(stacks - 1, j + 1), ring(stacks - 1, j)});
  return s;
}

}  // namespace corofem::test
