// Problem: one body discretised for simulation, independent of any backend. Built once from a
// scene body and its mesh; the backends upload from it and the solve/ drivers read it.
#pragma once

#include "model/element.hpp"

#include <corofem/mesh.hpp>
#include <corofem/scene.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace corofem::detail {

/// Whether a formulation is one of the hyperelastic laws (St. Venant-Kirchhoff, Neo-Hookean), which
/// only the reference backend runs.
inline bool isHyperelastic(Formulation f) { return f == Formulation::StVenantKirchhoff || f == Formulation::NeoHookean; }

/// A prescribed displacement: dofs and their full values (scaled by the load factor / ramp).
struct PrescribedDisplacement {
  std::vector<std::uint32_t> dofs;   ///< 3 * node + component
  std::vector<double> values;        ///< full displacement of each dof (m)
  double rampTime = 0.0;             ///< dynamics: linear ramp from 0 over this time (s)
};

/// A constant external force (gravity, spread nodal forces) with its ramp.
struct ExternalForce {
  Eigen::VectorXd f;                 ///< 3N nodal forces at full load (N)
  double rampTime = 0.0;
  bool gravity = false;              ///< a gravity load (Simulation::setGravity replaces these)
};

struct Problem {
  std::string name;
  TetMesh mesh;                      ///< rest mesh (positively oriented)
  Eigen::VectorXd restPositions;     ///< 3N, node-major (x0 y0 z0 x1 ...)
  std::vector<ElementRest> elements; ///< one per tet
  Lame lame;                         ///< same material in every element of a body
  double density = 0;
  double rayleighMass = 0, rayleighStiffness = 0;
  Formulation formulation = Formulation::Corotational;
  RotationMethod rotation = RotationMethod::Polar;
  Eigen::VectorXd lumpedMass;        ///< 3N: rho V / 4 to each node of each element, per component
  std::vector<std::uint8_t> constrained;  ///< 3N: 1 where the dof is fixed or prescribed
  std::vector<PrescribedDisplacement> prescribed;
  std::vector<ExternalForce> forces;
  Eigen::VectorXd initialVelocity;   ///< 3N
  /// 3N, N/m, or empty: zero-length springs an application attaches (spring handles), k_d on dof
  /// d pulling it towards a target the driver holds. They add k_d to the diagonal of the
  /// stiffness: A = m M + c C + s (K_t + diag k) (Device::apply; not damped by Rayleigh's beta).
  Eigen::VectorXd springStiffness;

  std::size_t dofCount() const { return static_cast<std::size_t>(restPositions.size()); }

  /// f_ext at load factor (statics) or time (dynamics: each force scaled by min(1, t / ramp)).
  Eigen::VectorXd externalForce(double loadFactorOrTime, bool dynamic) const;
  /// The same into f (resized to 3N; no allocation when it has that size already).
  void externalForce(double loadFactorOrTime, bool dynamic, Eigen::VectorXd& f) const;
  /// The scale of each of `forces` at that load factor or time: externalForce is the sum over the
  /// loads of scale * f, added in the loads' order from 0.
  std::vector<double> loadScales(double loadFactorOrTime, bool dynamic) const;
  /// The scale of each prescribed displacement (Problem::prescribed, in order) at the load factor
  /// (statics) or the time (dynamics, its ramp): applyPrescribed's x = X + scale * u.
  std::vector<double> prescribedScales(double loadFactorOrTime, bool dynamic) const;
  /// Dof d of externalForce with the loads' `scales` (loadScales): their sum from 0 in load order.
  double externalForceAt(const std::vector<double>& scales, Eigen::Index d) const {
    double sum = 0.0;
    for (std::size_t l = 0; l < forces.size(); ++l) sum += scales[l] * forces[l].f[d];
    return sum;
  }
  /// Writes the prescribed displacements (scaled likewise) into the positions x (3N): x = X + s u
  /// on prescribed dofs, and x = X on the other constrained (fixed) dofs; free dofs are untouched.
  void applyPrescribed(Eigen::VectorXd& x, double loadFactorOrTime, bool dynamic) const;
};

/// The consistent nodal forces of the body force rho g on the problem's elements: rho g V / 4 to
/// each node of each element (N), 3N.
Eigen::VectorXd gravityForce(const Problem& p, const double g[3]);

/// Builds a body's problem (node sets resolved, loads assembled, elements set up). Throws
/// Error(BadInput) with the body name and the element for a zero-volume element, bad material...
/// .bou files of node sets are read under `limits`.
Problem buildProblem(const BodyDesc& body, const TetMesh& mesh, const SolverDesc& solver,
                     const std::string& baseDir, const InputLimits& limits = {});

}  // namespace corofem::detail
