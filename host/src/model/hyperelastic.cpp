// Hyperelastic element mathematics (total Lagrangian SVK and compressible Neo-Hookean).
#include "model/hyperelastic.hpp"

#include "util/error.hpp"

#include <Eigen/Dense>

#include <cmath>
#include <limits>

namespace corofem::detail {

HyperelasticModel hyperelasticModelOf(Formulation formulation) {
  switch (formulation) {
    case Formulation::StVenantKirchhoff: return HyperelasticModel::StVenantKirchhoff;
    case Formulation::NeoHookean: return HyperelasticModel::NeoHookean;
    default: break;
  }
  fail(ErrorCode::Internal, "hyperelasticModelOf: formulation ", static_cast<int>(formulation),
       " is linear or co-rotational, not hyperelastic");
}

double strainEnergyDensity(HyperelasticModel model, const Mat3& F, const Lame& lame) {
  if (model == HyperelasticModel::StVenantKirchhoff) {
    const Mat3 E = 0.5 * (F.transpose() * F - Mat3::Identity());
    const double trE = E.trace();
    return lame.mu * E.squaredNorm() + 0.5 * lame.lambda * trE * trE;
  }
  const double J = F.determinant();
  if (!(J > 0.0)) return std::numeric_limits<double>::infinity();
  const double logJ = std::log(J);
  return 0.5 * lame.mu * (F.squaredNorm() - 3.0) - lame.mu * logJ + 0.5 * lame.lambda * logJ * logJ;
}

Mat3 firstPiolaStress(HyperelasticModel model, const Mat3& F, const Lame& lame) {
  if (model == HyperelasticModel::StVenantKirchhoff) {
    const Mat3 E = 0.5 * (F.transpose() * F - Mat3::Identity());
    const Mat3 S = lame.lambda * E.trace() * Mat3::Identity() + 2.0 * lame.mu * E;
    return F * S;
  }
  const double J = F.determinant();
  if (!(J > 0.0)) return Mat3::Constant(std::numeric_limits<double>::quiet_NaN());
  const Mat3 FinvT = F.inverse().transpose();
  return lame.mu * (F - FinvT) + lame.lambda * std::log(J) * FinvT;
}

Mat3 firstPiolaDifferential(HyperelasticModel model, const Mat3& F, const Mat3& dF, const Lame& lame) {
  if (model == HyperelasticModel::StVenantKirchhoff) {
    const Mat3 E = 0.5 * (F.transpose() * F - Mat3::Identity());
    const Mat3 S = lame.lambda * E.trace() * Mat3::Identity() + 2.0 * lame.mu * E;
    const Mat3 dE = 0.5 * (dF.transpose() * F + F.transpose() * dF);
    const Mat3 dS = lame.lambda * dE.trace() * Mat3::Identity() + 2.0 * lame.mu * dE;
    return dF * S + F * dS;
  }
  const double J = F.determinant();
  if (!(J > 0.0)) return Mat3::Constant(std::numeric_limits<double>::quiet_NaN());
  const Mat3 Finv = F.inverse();
  const Mat3 FinvT = Finv.transpose();
  // d(F^-T) = -F^-T dF^T F^-T and d(ln J) = tr(F^-1 dF).
  return lame.mu * dF + (lame.mu - lame.lambda * std::log(J)) * FinvT * dF.transpose() * FinvT +
         lame.lambda * (Finv * dF).trace() * FinvT;
}

double hyperelasticEnergy(HyperelasticModel model, const ElementRest& rest, const Lame& lame, const Mat3& F) {
  return rest.volume * strainEnergyDensity(model, F, lame);
}

Vec12 hyperelasticForce(HyperelasticModel model, const ElementRest& rest, const Lame& lame, const Mat3& F) {
  // F = sum_i x_i g_i^T, so dF/dx_i = e_a g_i^T and d(V W)/dx_i = V P g_i.
  const Mat3 P = firstPiolaStress(model, F, lame);
  Vec12 f;
  for (int i = 0; i < 4; ++i) f.segment<3>(3 * i) = rest.volume * P * rest.grad.row(i).transpose();
  return f;
}

Mat12 hyperelasticTangent(HyperelasticModel model, const ElementRest& rest, const Lame& lame, const Mat3& F) {
  // Column (3j+b): perturb node j along axis b, dF = e_b g_j^T; the force change at node i is
  // V dP g_i.
  Mat12 K;
  for (int j = 0; j < 4; ++j)
    for (int b = 0; b < 3; ++b) {
      Mat3 dF = Mat3::Zero();
      dF.row(b) = rest.grad.row(j);
      const Mat3 dP = firstPiolaDifferential(model, F, dF, lame);
      for (int i = 0; i < 4; ++i)
        K.block<3, 1>(3 * i, 3 * j + b) = rest.volume * dP * rest.grad.row(i).transpose();
    }
  return 0.5 * (K + K.transpose());  // exact symmetry (hyperelastic); removes rounding asymmetry
}

}  // namespace corofem::detail
