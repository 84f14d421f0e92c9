// Hyperelastic linear tetrahedra (total Lagrangian): St. Venant-Kirchhoff and compressible
// Neo-Hookean. Reference backend only: the geometrically exact yardstick the co-rotational
// formulation is measured against (the role ABAQUS plays in the paper's Fig. 5).
//
// Conventions: F = D_s D_m^-1 (constant per element), P = dW/dF the first Piola-Kirchhoff stress,
// the element internal force f_i = V P g_i (g_i = grad N_i, the rows of ElementRest::grad), i.e.
// f = d(V W)/dx, the same sign as K u for the linear element. Tangent K_t = df/dx (12x12, node-major).
#pragma once

#include "model/element.hpp"

namespace corofem::detail {

enum class HyperelasticModel {
  StVenantKirchhoff,  ///< W = mu E:E + lambda/2 tr(E)^2, E = (F^T F - I)/2
  NeoHookean,         ///< W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2, I1 = tr(F^T F), J = det F
};

/// The hyperelastic model of a formulation. Throws Error(Internal) for Linear / Corotational.
HyperelasticModel hyperelasticModelOf(Formulation formulation);

/// Strain energy density W(F) (J/m^3). Neo-Hookean: +infinity when det F <= 0 (undefined there).
double strainEnergyDensity(HyperelasticModel model, const Mat3& F, const Lame& lame);

/// First Piola-Kirchhoff stress P = dW/dF (Pa). Neo-Hookean with det F <= 0: all NaN.
///   SVK: P = F S, S = lambda tr(E) I + 2 mu E.
///   NH:  P = mu (F - F^-T) + lambda ln J F^-T.
Mat3 firstPiolaStress(HyperelasticModel model, const Mat3& F, const Lame& lame);

/// Directional derivative dP = (dP/dF) : dF at F (the consistent linearisation).
///   SVK: dP = dF S + F dS, dS = lambda tr(dE) I + 2 mu dE, dE = (dF^T F + F^T dF)/2.
///   NH:  dP = mu dF + (mu - lambda ln J) F^-T dF^T F^-T + lambda tr(F^-1 dF) F^-T.
Mat3 firstPiolaDifferential(HyperelasticModel model, const Mat3& F, const Mat3& dF, const Lame& lame);

/// Element strain energy V W(F) (J).
double hyperelasticEnergy(HyperelasticModel model, const ElementRest& rest, const Lame& lame, const Mat3& F);

/// Element internal forces f_i = V P g_i (N), 12 entries node-major.
Vec12 hyperelasticForce(HyperelasticModel model, const ElementRest& rest, const Lame& lame, const Mat3& F);

/// Consistent element tangent K_t(3i+a, 3j+b) = V sum_cd dP_ac/dF_bd g_ic g_jd (symmetric; may be
/// indefinite under compression, e.g. near buckling).
Mat12 hyperelasticTangent(HyperelasticModel model, const ElementRest& rest, const Lame& lame, const Mat3& F);

}  // namespace corofem::detail
