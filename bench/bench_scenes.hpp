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

/// The timed step of the step benchmarks, set on `s`: dynamics at 60 Hz, one Newton iteration of
/// dissipative Newmark, exactly 20 PCG iterations (tolerance 1e-30, cap 20, read once) with the
/// diagonal preconditioner, so that every backend does the same work. `steps` 0: open-ended.
/// Dissipative Newmark (gamma 0.6, beta (gamma + 1/2)^2 / 4): the average-acceleration default
/// with one linearised iteration gains energy on a swinging co-rotational beam within ~80 steps
/// (the energy guard stops it), and a benchmark must time thousands of steps.
inline void twentyIterationSteps(Scene& s, int steps, Precision precision) {
  s.analysis.kind = AnalysisDesc::Kind::Dynamic;
  s.analysis.dynamics.timeStep = 1.0 / 60.0;
  s.analysis.dynamics.steps = steps;
  s.analysis.dynamics.newtonIterations = 1;
  s.analysis.dynamics.newmarkGamma = 0.6;
  s.analysis.dynamics.newmarkBeta = 0.3025;
  s.solver.tolerance = 1e-30;
  s.solver.maxIterations = 20;
  s.solver.checkEvery = 20;
  s.solver.preconditioner = PreconditionerKind::Diagonal;
  s.solver.precision = precision;
}

}  // namespace corofem::bench
