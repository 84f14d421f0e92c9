// What the benchmarks' scenes share: a generated box body clamped at its x = 0 face, under gravity.
#pragma once

#include <corofem/scene.hpp>

#include <array>
#include <string>

namespace corofem::bench {

/// A box [0, size] of cells (tetsPerCell tets each), clamped at x = 0, under gravity (0, -9.81, 0),
/// of Young's modulus E (Pa), Poisson ratio nu and density rho (kg/m^3).
inline BodyDesc clampedBox(const std::string& name, const std::array<double, 3>& size, const std::array<int, 3>& cells,
                           int tetsPerCell, double E, double nu, double rho) {
  BodyDesc b;
  b.name = name;
  BoxSpec box;
  box.max = size;
  box.cells = cells;
  box.tetsPerCell = tetsPerCell;
  b.mesh.box = box;
  b.material.youngsModulus = E;
  b.material.poissonRatio = nu;
  b.material.density = rho;
  NodeSetDesc clamp;
  clamp.kind = NodeSetDesc::Kind::Plane;
  clamp.planePoint = {0, 0, 0};
  clamp.planeNormal = {1, 0, 0};
  clamp.planeTolerance = 1e-9;
  b.fixed.push_back(clamp);
  LoadDesc g;
  g.kind = LoadDesc::Kind::Gravity;
  g.vector = {0, -9.81, 0};
  b.loads.push_back(g);
  return b;
}

}  // namespace corofem::bench
