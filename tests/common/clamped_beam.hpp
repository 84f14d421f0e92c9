// The clamped cantilever the preconditioner tests share (tests/solve/test_amg.cpp,
// tests/solve/test_warped_cholesky.cpp): 1 x 0.1 x 0.1 m, E = 1e6 Pa, and its free dofs.
#pragma once

#include "model/problem.hpp"
#include "reference/small_meshes.hpp"

#include <Eigen/Core>

#include <vector>

namespace corofem::test {

/// The mass coefficient of backward Euler's system at 60 Hz: 1 / h^2 (1/s^2).
inline constexpr double kBackwardEulerMass = 3600.0;

/// A cantilever 1 x 0.1 x 0.1 m in `cells` x 3 x 3 cells of 6 tets (E = 1e6 Pa, nu = 0.3,
/// rho = 1000), every node on x = 0 clamped.
inline detail::Problem clampedBeam(int cells, Formulation f = Formulation::Corotational) {
  detail::Problem p = makeProblem(boxMesh(cells, 3, 3, 1.0, 0.1, 0.1, 0.0, 6), 1e6, 0.3, 1000.0, f);
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
    if (p.mesh.nodes[3 * n] < 1e-12)
      for (int c = 0; c < 3; ++c) p.constrained[3 * n + c] = 1;
  return p;
}

/// The dofs of `p` not constrained, ascending.
inline std::vector<Eigen::Index> freeDofsOf(const detail::Problem& p) {
  std::vector<Eigen::Index> dofs;
  for (std::size_t d = 0; d < p.dofCount(); ++d)
    if (!p.constrained[d]) dofs.push_back(static_cast<Eigen::Index>(d));
  return dofs;
}

}  // namespace corofem::test
