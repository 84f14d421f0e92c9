// Helpers of the physics tests: cantilever scenes (clamped at x = xmin, loaded at x = xmax), runs
// through the public Simulation API, and tip and volume measurements.
#pragma once

#include <corofem/mesh.hpp>
#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <string>
#include <vector>

namespace corofem::test {

/// Plane x = value (node sets of the clamp and the tip face).
inline NodeSetDesc planeX(double x) {
  NodeSetDesc set;
  set.kind = NodeSetDesc::Kind::Plane;
  set.planePoint = {x, 0, 0};
  set.planeNormal = {1, 0, 0};
  set.planeTolerance = 1e-6;
  return set;
}

/// A cantilever body along x from `x0` to `x1`, clamped at x0, on the given mesh source.
inline BodyDesc cantileverBody(const MeshSourceDesc& mesh, double x0, double youngs, double poisson,
                               double density, Formulation formulation) {
  BodyDesc body;
  body.name = "beam";
  body.mesh = mesh;
  body.material.youngsModulus = youngs;
  body.material.poissonRatio = poisson;
  body.material.density = density;
  body.formulation = formulation;
  body.fixed.push_back(planeX(x0));
  return body;
}

inline LoadDesc tipForce(double x1, const Vec3& force) {
  LoadDesc load;
  load.kind = LoadDesc::Kind::Force;
  load.vector = force;
  load.nodes = planeX(x1);
  return load;
}

inline LoadDesc gravity(const Vec3& g) {
  LoadDesc load;
  load.kind = LoadDesc::Kind::Gravity;
  load.vector = g;
  return load;
}

inline MeshSourceDesc fileMesh(const std::string& path) {
  MeshSourceDesc m;
  m.file = path;
  return m;
}

inline MeshSourceDesc boxMesh(const std::array<double, 3>& lo, const std::array<double, 3>& hi,
                              const std::array<int, 3>& cells, int tetsPerCell = 5) {
  MeshSourceDesc m;
  BoxSpec box;
  box.min = lo;
  box.max = hi;
  box.cells = cells;
  box.tetsPerCell = tetsPerCell;
  m.box = box;
  return m;
}

inline Scene staticScene(const BodyDesc& body, int increments, LinearSolverKind solver = LinearSolverKind::Cholesky) {
  Scene scene;
  scene.name = "test";
  scene.bodies.push_back(body);
  scene.analysis.kind = AnalysisDesc::Kind::Static;
  scene.analysis.statics.increments = increments;
  scene.solver.linearSolver = solver;
  scene.solver.tolerance = 1e-10;
  scene.backend.kind = BackendKind::Reference;
  return scene;
}

/// Mean displacement of the nodes in `set` (3 components).
inline Vec3 meanDisplacement(const Simulation& sim, const NodeSetDesc& set) {
  std::vector<double> x;
  Status st = sim.readPositions(0, x);
  EXPECT_TRUE(st) << st.message();
  auto nodes = resolveNodeSet(set, sim.restMesh(0));
  EXPECT_TRUE(nodes) << nodes.message();
  Vec3 u{0, 0, 0};
  if (!nodes || nodes->empty()) return u;
  const std::vector<double>& x0 = sim.restMesh(0).nodes;
  for (std::uint32_t n : nodes.value())
    for (int c = 0; c < 3; ++c) u[c] += x[3 * n + c] - x0[3 * n + c];
  for (double& c : u) c /= static_cast<double>(nodes->size());
  return u;
}

/// Deformed volume over rest volume of body 0 (sum of signed element volumes).
inline double volumeRatio(const Simulation& sim) {
  TetMesh deformed = sim.restMesh(0);
  std::vector<double> x;
  EXPECT_TRUE(sim.readPositions(0, x));
  double rest = 0, now = 0;
  for (std::size_t e = 0; e < deformed.tetCount(); ++e) rest += signedVolume(deformed, e);
  deformed.nodes = x;
  for (std::size_t e = 0; e < deformed.tetCount(); ++e) now += signedVolume(deformed, e);
  return now / rest;
}

/// Runs every step; fails the test on the first failing step. Returns false on failure.
inline bool runToEnd(Simulation& sim) {
  while (!sim.finished()) {
    StepReport report;
    Status st = sim.step(&report);
    if (!st) {
      ADD_FAILURE() << "step " << sim.stepsTaken() + 1 << ": " << st.message();
      return false;
    }
  }
  return true;
}

}  // namespace corofem::test
