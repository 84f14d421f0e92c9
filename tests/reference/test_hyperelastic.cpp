// Hyperelastic elements (SVK, Neo-Hookean): forces are the energy gradient, the tangent is the
// force Jacobian (central finite differences), rotation invariance, and the small-strain limit.
#include "small_meshes.hpp"

#include "model/hyperelastic.hpp"

#include <gtest/gtest.h>

#include <limits>

using namespace corofem;
using namespace corofem::detail;
using corofem::test::randomElement;
using corofem::test::randomRotation;

namespace {

const HyperelasticModel kModels[] = {HyperelasticModel::StVenantKirchhoff, HyperelasticModel::NeoHookean};

const char* nameOf(HyperelasticModel m) {
  return m == HyperelasticModel::StVenantKirchhoff ? "SVK" : "NeoHookean";
}

std::array<Vec3d, 4> deform(const std::array<Vec3d, 4>& X, const Mat3& A, const Vec3d& t) {
  std::array<Vec3d, 4> x;
  for (int i = 0; i < 4; ++i) x[i] = A * X[i] + t;
  return x;
}

/// A random large deformation (rotation times up to 30 % stretch/shear), det > 0.
Mat3 randomDeformation(std::mt19937& rng) {
  for (;;) {
    const Mat3 A = randomRotation(rng) * (Mat3::Identity() + 0.3 * Mat3::Random());
    if (A.determinant() > 0.3) return A;
  }
}

}  // namespace

TEST(Hyperelastic, ForceIsEnergyGradientAndTangentIsForceJacobian) {
  std::mt19937 rng(101);
  const Lame lame = lameFromYoungPoisson(1e5, 0.35);
  for (HyperelasticModel model : kModels)
    for (int trial = 0; trial < 10; ++trial) {
      const auto X = randomElement(rng);
      const ElementRest r = computeElementRest(X);
      // Random per-node perturbation on top of a homogeneous deformation: a general F.
      auto x = deform(X, randomDeformation(rng), Vec3d(0.5, -0.2, 1.0));
      for (auto& xi : x) xi += 0.05 * Vec3d::Random();
      const Mat3 F = deformationGradient(r, x);
      ASSERT_GT(F.determinant(), 0);
      const Vec12 f = hyperelasticForce(model, r, lame, F);
      const Mat12 K = hyperelasticTangent(model, r, lame, F);

      // Central differences with h = 1e-6 (element size ~1): truncation O(h^2) ~ 1e-12 relative,
      // rounding ~ eps * E / h ~ 1e-10 relative: a 1e-6 relative tolerance leaves ample margin
      // and still catches any wrong term (those are O(1) relative).
      const double h = 1e-6;
      Vec12 fd;
      Mat12 Kfd;
      for (int d = 0; d < 12; ++d) {
        auto xp = x, xm = x;
        xp[d / 3][d % 3] += h;
        xm[d / 3][d % 3] -= h;
        const Mat3 Fp = deformationGradient(r, xp), Fm = deformationGradient(r, xm);
        fd[d] = (hyperelasticEnergy(model, r, lame, Fp) - hyperelasticEnergy(model, r, lame, Fm)) / (2 * h);
        Kfd.col(d) = (hyperelasticForce(model, r, lame, Fp) - hyperelasticForce(model, r, lame, Fm)) / (2 * h);
      }
      EXPECT_LT((fd - f).norm(), 1e-6 * f.norm()) << nameOf(model) << " trial " << trial;
      EXPECT_LT((Kfd - K).norm(), 1e-6 * K.norm()) << nameOf(model) << " trial " << trial;
      EXPECT_LT((K - K.transpose()).norm(), 1e-14 * K.norm());
      // Forces of an element sum to zero (no net force from internal stress), to rounding.
      Vec3d sum = Vec3d::Zero();
      for (int i = 0; i < 4; ++i) sum += f.segment<3>(3 * i);
      EXPECT_LT(sum.norm(), 1e-12 * f.norm());
    }
}

TEST(Hyperelastic, RestStateAndRotationInvariance) {
  std::mt19937 rng(103);
  const Lame lame = lameFromYoungPoisson(1e5, 0.3);
  for (HyperelasticModel model : kModels) {
    const auto X = randomElement(rng);
    const ElementRest r = computeElementRest(X);
    // At rest: zero energy and force, and the tangent is the linear K_e (both models linearise to
    // Hooke's law with the same lambda, mu). Rounding of O(1e5) entries: 1e-10 relative.
    EXPECT_NEAR(hyperelasticEnergy(model, r, lame, Mat3::Identity()), 0.0, 1e-20);
    EXPECT_LT(hyperelasticForce(model, r, lame, Mat3::Identity()).norm(), 1e-10);
    const Mat12 K0 = linearStiffness(r, lame);
    EXPECT_LT((hyperelasticTangent(model, r, lame, Mat3::Identity()) - K0).norm(), 1e-10 * K0.norm());

    // Objectivity: W(Q F) = W(F), P(Q F) = Q P(F).
    const Mat3 F = randomDeformation(rng);
    const Mat3 Q = randomRotation(rng);
    const double W = strainEnergyDensity(model, F, lame);
    EXPECT_NEAR(strainEnergyDensity(model, Q * F, lame), W, 1e-10 * std::abs(W));
    const Mat3 P = firstPiolaStress(model, F, lame);
    EXPECT_LT((firstPiolaStress(model, Q * F, lame) - Q * P).norm(), 1e-10 * P.norm());
  }
}

TEST(Hyperelastic, NeoHookeanUndefinedWhenInverted) {
  const Lame lame = lameFromYoungPoisson(1e5, 0.3);
  const Mat3 Finv = Vec3d(1.0, 1.0, -0.5).asDiagonal();
  EXPECT_EQ(strainEnergyDensity(HyperelasticModel::NeoHookean, Finv, lame), std::numeric_limits<double>::infinity());
  EXPECT_FALSE(firstPiolaStress(HyperelasticModel::NeoHookean, Finv, lame).allFinite());
  // SVK stays defined (and finite) for inverted elements.
  EXPECT_TRUE(std::isfinite(strainEnergyDensity(HyperelasticModel::StVenantKirchhoff, Finv, lame)));
  EXPECT_TRUE(firstPiolaStress(HyperelasticModel::StVenantKirchhoff, Finv, lame).allFinite());
}

TEST(Hyperelastic, SmallStrainLimitMatchesLinearAndCorotational) {
  // x = Q (X + s U) with a unit random displacement U: the hyperelastic forces agree with the
  // co-rotational ones (and, for Q = I, the linear ones) up to O(s^2); relative to the force
  // (O(s)) the difference is O(s). Checked at two amplitudes: the relative error is below 10 s
  // and shrinks roughly tenfold when s does (a first-order discrepancy would not).
  std::mt19937 rng(107);
  const Lame lame = lameFromYoungPoisson(1e5, 0.3);
  for (HyperelasticModel model : kModels)
    for (int trial = 0; trial < 5; ++trial) {
      const auto X = randomElement(rng);
      const ElementRest r = computeElementRest(X);
      const Mat12 K = linearStiffness(r, lame);
      std::array<Vec3d, 4> U;
      for (auto& u : U) u = Vec3d::Random();
      for (bool rotated : {false, true}) {
        const Mat3 Q = rotated ? randomRotation(rng) : Mat3::Identity();
        double previous = 0;
        for (double s : {1e-4, 1e-5}) {
          std::array<Vec3d, 4> x;
          for (int i = 0; i < 4; ++i) x[i] = Q * (X[i] + s * U[i]);
          const Mat3 F = deformationGradient(r, x);
          const Vec12 fh = hyperelasticForce(model, r, lame, F);
          const Mat3 R = rotated ? polarRotation(F) : Mat3::Identity();
          const Vec12 fc = corotationalForce(K, R, x, X);
          const double rel = (fh - fc).norm() / fc.norm();
          EXPECT_LT(rel, 10 * s) << nameOf(model) << (rotated ? " rotated" : " linear") << " s = " << s;
          if (previous > 0) EXPECT_LT(rel, 0.3 * previous);
          previous = rel;
          EXPECT_NEAR(hyperelasticEnergy(model, r, lame, F), corotationalEnergy(K, R, x, X),
                      10 * s * corotationalEnergy(K, R, x, X));
        }
      }
    }
}
