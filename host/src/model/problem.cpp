// Problem: load and prescribed-displacement scaling (statics: load factor; dynamics: ramp in time).
// buildProblem lives in build_problem.cpp (it needs the scene's node-set resolution).
#include "model/problem.hpp"

#include <algorithm>

namespace corofem::detail {

namespace {

/// Scale of a load: statics -> the load factor itself; dynamics -> min(1, t / rampTime), or 1 when
/// the load has no ramp (rampTime == 0). Negative times give 0 (nothing applied before t = 0).
double loadScale(double loadFactorOrTime, bool dynamic, double rampTime) {
  if (!dynamic) return loadFactorOrTime;
  if (rampTime <= 0.0) return 1.0;
  return std::clamp(loadFactorOrTime / rampTime, 0.0, 1.0);
}

}  // namespace

Eigen::VectorXd gravityForce(const Problem& p, const double g[3]) {
  // Consistent body force of a linear tetrahedron: integral of rho g N_i = rho g V / 4.
  Eigen::VectorXd f = Eigen::VectorXd::Zero(p.restPositions.size());
  const Vec3d gv(g[0], g[1], g[2]);
  for (std::size_t e = 0; e < p.mesh.tetCount(); ++e) {
    const Vec3d fi = p.density * p.elements[e].volume / 4.0 * gv;
    for (int k = 0; k < 4; ++k) f.segment<3>(3 * static_cast<Eigen::Index>(p.mesh.tets[4 * e + k])) += fi;
  }
  return f;
}

Eigen::VectorXd Problem::externalForce(double loadFactorOrTime, bool dynamic) const {
  Eigen::VectorXd f;
  externalForce(loadFactorOrTime, dynamic, f);
  return f;
}

std::vector<double> Problem::loadScales(double loadFactorOrTime, bool dynamic) const {
  std::vector<double> scales;
  for (const ExternalForce& load : forces) scales.push_back(loadScale(loadFactorOrTime, dynamic, load.rampTime));
  return scales;
}

std::vector<double> Problem::prescribedScales(double loadFactorOrTime, bool dynamic) const {
  std::vector<double> scales;
  for (const PrescribedDisplacement& p : prescribed) scales.push_back(loadScale(loadFactorOrTime, dynamic, p.rampTime));
  return scales;
}

void Problem::externalForce(double loadFactorOrTime, bool dynamic, Eigen::VectorXd& f) const {
  const std::vector<double> scales = loadScales(loadFactorOrTime, dynamic);
  f.resize(restPositions.size());
  for (Eigen::Index d = 0; d < f.size(); ++d) f[d] = externalForceAt(scales, d);  // one pass, whatever the loads
}

void Problem::applyPrescribed(Eigen::VectorXd& x, double loadFactorOrTime, bool dynamic) const {
  // Fixed dofs (constrained, value 0) are held at their rest position; prescribed dofs move to
  // X + scale * value. Prescribed entries are written after, so they win on a shared dof.
  for (std::size_t d = 0; d < constrained.size(); ++d)
    if (constrained[d]) x[static_cast<Eigen::Index>(d)] = restPositions[static_cast<Eigen::Index>(d)];
  const std::vector<double> scales = prescribedScales(loadFactorOrTime, dynamic);
  for (std::size_t g = 0; g < prescribed.size(); ++g) {
    const PrescribedDisplacement& p = prescribed[g];
    for (std::size_t k = 0; k < p.dofs.size(); ++k) {
      const auto d = static_cast<Eigen::Index>(p.dofs[k]);
      x[d] = restPositions[d] + scales[g] * p.values[k];
    }
  }
}

}  // namespace corofem::detail
