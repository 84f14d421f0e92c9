// Element mathematics: Lame parameters, rest set-up, K_e, polar rotation, co-rotational forces,
// masses and energies.
#include "small_meshes.hpp"

#include "model/element.hpp"
#include "util/error.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

using namespace corofem;
using namespace corofem::detail;
using corofem::test::randomElement;
using corofem::test::randomRotation;
using corofem::test::rotation;

namespace {

std::array<Vec3d, 4> transform(const std::array<Vec3d, 4>& X, const Mat3& A, const Vec3d& t) {
  std::array<Vec3d, 4> x;
  for (int i = 0; i < 4; ++i) x[i] = A * X[i] + t;
  return x;
}

Vec12 flatten(const std::array<Vec3d, 4>& x) {
  Vec12 v;
  for (int i = 0; i < 4; ++i) v.segment<3>(3 * i) = x[i];
  return v;
}

std::string messageOf(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::BadInput);
    return e.what();
  }
  ADD_FAILURE() << "no Error thrown";
  return {};
}

}  // namespace

TEST(Lame, ValuesAndValidation) {
  const Lame l = lameFromYoungPoisson(1e5, 0.25);
  // E = mu (3 lambda + 2 mu) / (lambda + mu), nu = lambda / (2 (lambda + mu)); rounding only.
  EXPECT_NEAR(l.mu * (3 * l.lambda + 2 * l.mu) / (l.lambda + l.mu), 1e5, 1e-9);
  EXPECT_NEAR(l.lambda / (2 * (l.lambda + l.mu)), 0.25, 1e-15);
  EXPECT_NEAR(l.mu, 4e4, 1e-9);

  std::string m = messageOf([] { lameFromYoungPoisson(-3, 0.3); });
  EXPECT_NE(m.find("-3"), std::string::npos) << m;
  EXPECT_NE(m.find("> 0"), std::string::npos) << m;
  m = messageOf([] { lameFromYoungPoisson(1e5, 0.5); });
  EXPECT_NE(m.find("0.5"), std::string::npos) << m;
  EXPECT_NE(m.find("(-1, 0.5)"), std::string::npos) << m;
  messageOf([] { lameFromYoungPoisson(1e5, -1.0); });
  messageOf([] { lameFromYoungPoisson(std::nan(""), 0.3); });
  EXPECT_NO_THROW(lameFromYoungPoisson(1e5, -0.99));
  EXPECT_NO_THROW(lameFromYoungPoisson(2e11, 0.4999));
}

TEST(ElementRest, GradientsVolumeAndBadElements) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    const auto X = randomElement(rng);
    const ElementRest r = computeElementRest(X);
    // Rows sum to zero (partition of unity) and sum_i X_i g_i^T = I (F = I at rest); both are exact
    // identities up to rounding of O(1) numbers.
    EXPECT_LT(r.grad.colwise().sum().norm(), 1e-12);
    Mat3 F = Mat3::Zero();
    for (int i = 0; i < 4; ++i) F += X[i] * r.grad.row(i);
    EXPECT_LT((F - Mat3::Identity()).norm(), 1e-12);
    EXPECT_NEAR(r.volume, signedVolume(X), 1e-14);
    EXPECT_GT(r.volume, 0);
    EXPECT_LT((deformationGradient(r, X) - Mat3::Identity()).norm(), 1e-12);
  }
  const std::array<Vec3d, 4> unit = {Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(0, 1, 0), Vec3d(0, 0, 1)};
  EXPECT_NEAR(computeElementRest(unit).volume, 1.0 / 6.0, 1e-16);
  std::array<Vec3d, 4> flat = unit;
  flat[3] = Vec3d(0.3, 0.3, 0);
  EXPECT_NE(messageOf([&] { computeElementRest(flat); }).find("zero volume"), std::string::npos);
  std::array<Vec3d, 4> inverted = unit;
  std::swap(inverted[2], inverted[3]);
  EXPECT_NE(messageOf([&] { computeElementRest(inverted); }).find("inverted"), std::string::npos);
}

TEST(LinearStiffness, SymmetricPsdWithSixRigidModes) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 20; ++trial) {
    const auto X = randomElement(rng);
    const ElementRest r = computeElementRest(X);
    const Lame lame = lameFromYoungPoisson(1e5, 0.3);
    const Mat12 K = linearStiffness(r, lame);
    const double scale = K.norm();
    EXPECT_LT((K - K.transpose()).norm(), 1e-14 * scale);  // symmetrised: exact
    Eigen::SelfAdjointEigenSolver<Mat12> eig(K);
    const auto& ev = eig.eigenvalues();  // ascending
    // Six rigid modes: eigenvalues at rounding level (1e-10 of the largest, double precision with
    // condition of the random shapes); the seventh is a true deformation mode, far above it.
    for (int i = 0; i < 6; ++i) EXPECT_LT(std::abs(ev[i]), 1e-10 * ev[11]) << "eigenvalue " << i;
    EXPECT_GT(ev[6], 1e-4 * ev[11]);

    // Rigid translation and infinitesimal rotation (u = w x X) give zero force.
    Vec12 ut, ur;
    const Vec3d t(0.3, -1.2, 0.7), w(0.2, 0.5, -0.4);
    for (int i = 0; i < 4; ++i) {
      ut.segment<3>(3 * i) = t;
      ur.segment<3>(3 * i) = w.cross(X[i]);
    }
    EXPECT_LT((K * ut).norm(), 1e-10 * scale * t.norm());
    EXPECT_LT((K * ur).norm(), 1e-10 * scale * (flatten(X).norm() * w.norm()));

    // Closed form of the 3x3 blocks: K_ij = V (lambda g_i g_j^T + mu g_j g_i^T + mu (g_i.g_j) I).
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) {
        const Vec3d gi = r.grad.row(i).transpose(), gj = r.grad.row(j).transpose();
        const Mat3 Kij = r.volume * (lame.lambda * gi * gj.transpose() + lame.mu * gj * gi.transpose() +
                                     lame.mu * gi.dot(gj) * Mat3::Identity());
        EXPECT_LT((K.block<3, 3>(3 * i, 3 * j) - Kij).norm(), 1e-12 * scale);
      }
  }
}

TEST(LinearStiffness, ForceIsHookeStressOnFaces) {
  // For a homogeneous deformation u = G X, K u at node i equals V sigma g_i with sigma Hooke's
  // stress of the small strain sym(G): the element reproduces constant stress exactly.
  std::mt19937 rng(3);
  const Lame lame = lameFromYoungPoisson(2e6, 0.35);
  for (int trial = 0; trial < 10; ++trial) {
    const auto X = randomElement(rng);
    const ElementRest r = computeElementRest(X);
    const Mat3 G = Mat3::Random() * 1e-3;
    Vec12 u;
    for (int i = 0; i < 4; ++i) u.segment<3>(3 * i) = G * X[i];
    const Vec12 f = linearStiffness(r, lame) * u;
    const Mat3 sigma = hookeStress(smallStrain(Mat3::Identity() + G), lame);
    for (int i = 0; i < 4; ++i)
      EXPECT_LT((f.segment<3>(3 * i) - r.volume * sigma * r.grad.row(i).transpose()).norm(),
                1e-12 * r.volume * sigma.norm() * r.grad.norm());
  }
}

TEST(PolarRotation, ProperRotationAndSymmetricStretch) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> s(0.3, 3.0);
  for (int trial = 0; trial < 50; ++trial) {
    const Mat3 Q = randomRotation(rng);
    const Mat3 S0 = randomRotation(rng) * Vec3d(s(rng), s(rng), s(rng)).asDiagonal();
    const Mat3 F = Q * S0 * S0.transpose();  // det F > 0, polar factor exactly Q
    const Mat3 R = polarRotation(F);
    // Orthonormality and det at 1e-12: Jacobi SVD on O(1) matrices is accurate to a few ulps.
    EXPECT_LT((R.transpose() * R - Mat3::Identity()).norm(), 1e-12);
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
    EXPECT_LT((R - Q).norm(), 1e-10);  // stretch condition number <= 100: 1e-10 relative
    const Mat3 S = R.transpose() * F;
    EXPECT_LT((S - S.transpose()).norm(), 1e-10 * S.norm());
    EXPECT_GT(Eigen::SelfAdjointEigenSolver<Mat3>(0.5 * (S + S.transpose())).eigenvalues().minCoeff(), 0.0);
  }
}

TEST(PolarRotation, IsTheSvdsRotationToRoundingWhereNewtonRuns) {
  // polarRotation takes Higham's Newton iteration for proper F not nearly flat, the SVD otherwise:
  // the two give the same polar factor U V^T, here to 5e-14 (the factor's own sensitivity to
  // rounding reaches about 2e-14 at a stretch ratio of 100) for stretch ratios up to 100 (det F
  // at least 1e-4 |F|^3: every one of them takes Newton), near-identity F, and F of any scale
  // (1e-6 to 1e6).
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 400; ++trial) {
    const double ratio = std::pow(10.0, 2.0 * u(rng));  // largest over smallest stretch
    const double scale = std::pow(10.0, 12.0 * u(rng) - 6.0);
    const Vec3d s(scale, scale * std::pow(ratio, u(rng)), scale * ratio);
    Mat3 jitter;
    for (int k = 0; k < 9; ++k) jitter(k / 3, k % 3) = 2.0 * u(rng) - 1.0;
    const Mat3 F = trial % 10 == 0 ? Mat3(randomRotation(rng) * (Mat3::Identity() + 1e-9 * jitter))
                                   : Mat3(randomRotation(rng) * s.asDiagonal() * randomRotation(rng));
    Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Mat3 expected = svd.matrixU() * svd.matrixV().transpose();
    ASSERT_GT(expected.determinant(), 0.0);
    const Mat3 R = polarRotation(F);
    EXPECT_LT((R - expected).norm(), 5e-14) << "trial " << trial << ", ratio " << ratio;
    EXPECT_LT((R.transpose() * R - Mat3::Identity()).norm(), 1e-14);
  }
}

TEST(PolarRotation, InvertedAndFlatElementsStayProper) {
  std::mt19937 rng(9);
  for (int trial = 0; trial < 20; ++trial) {
    const Mat3 Q = randomRotation(rng);
    const Mat3 P = randomRotation(rng);
    // Inverted: one negative principal stretch.
    const Mat3 Finv = Q * Vec3d(1.2, 0.8, -0.5).asDiagonal() * P;
    ASSERT_LT(Finv.determinant(), 0);
    Mat3 R = polarRotation(Finv);
    EXPECT_LT((R.transpose() * R - Mat3::Identity()).norm(), 1e-12);
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
    // R^T F is symmetric with one negative eigenvalue (the flipped smallest direction).
    Mat3 S = R.transpose() * Finv;
    EXPECT_LT((S - S.transpose()).norm(), 1e-10);
    // Nearly flat: one singular value 1e-8, with either sign of det.
    for (double sign : {1.0, -1.0}) {
      const Mat3 Fflat = Q * Vec3d(1.5, 0.7, sign * 1e-8).asDiagonal() * P;
      R = polarRotation(Fflat);
      ASSERT_TRUE(R.allFinite());
      EXPECT_LT((R.transpose() * R - Mat3::Identity()).norm(), 1e-12);
      EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
      // The rotation is well defined on the two large stretch directions.
      S = R.transpose() * Fflat;
      EXPECT_LT((S - S.transpose()).norm(), 1e-7);
    }
  }
  // Completely collapsed (F = 0) still returns a finite proper rotation.
  const Mat3 R0 = polarRotation(Mat3::Zero());
  EXPECT_TRUE(R0.allFinite());
  EXPECT_NEAR(R0.determinant(), 1.0, 1e-12);
}

TEST(CorotationalForce, RigidMotionGivesZeroForce) {
  std::mt19937 rng(13);
  const Lame lame = lameFromYoungPoisson(1e6, 0.3);
  std::vector<Mat3> rotations = {rotation(Vec3d::UnitX(), M_PI), rotation(Vec3d::UnitY(), M_PI),
                                 rotation(Vec3d::UnitZ(), M_PI), rotation(Vec3d(1, 1, 0), 2.0)};
  for (int i = 0; i < 6; ++i) rotations.push_back(randomRotation(rng));
  for (int trial = 0; trial < 5; ++trial) {
    const auto X = randomElement(rng);
    const ElementRest r = computeElementRest(X);
    const Mat12 K = linearStiffness(r, lame);
    // Force scale: E * (characteristic area) = E V^(2/3).
    const double forceScale = 1e6 * std::cbrt(r.volume * r.volume);
    for (const Mat3& Q : rotations) {
      const auto x = transform(X, Q, Vec3d(5.0, -2.0, 10.0));
      const Mat3 R = polarRotation(deformationGradient(r, x));
      EXPECT_LT((R - Q).norm(), 1e-12);
      // Co-rotational: zero to rounding (1e-12 relative: positions O(10), double precision).
      EXPECT_LT(corotationalForce(K, R, x, X).norm(), 1e-11 * forceScale);
      // u = R^T x - X is the rigid translation R^T t (|u| ~ 11 m): the energy is |u| times the
      // rounding-level force.
      EXPECT_LT(corotationalEnergy(K, R, x, X), 1e-11 * forceScale * flatten(x).norm());
      // Linear (R = I): large spurious forces for any finite rotation (here >= 2 rad).
      EXPECT_GT(corotationalForce(K, Mat3::Identity(), x, X).norm(), 0.1 * forceScale);
    }
  }
}

TEST(CorotationalForce, IsGradientOfEnergyAndMatchesRotatedStiffness) {
  // With the polar rotation, f = R K (R^T x - X) is the exact gradient of 1/2 u^T K u
  // (the dR term vanishes because R^T F is symmetric). Central differences, h = 1e-6 of the element
  // size: truncation O(h^2) ~ 1e-12 relative, rounding ~ 1e-16 / 1e-6 = 1e-10 relative.
  std::mt19937 rng(17);
  const Lame lame = lameFromYoungPoisson(1e5, 0.3);
  for (int trial = 0; trial < 5; ++trial) {
    const auto X = randomElement(rng);
    const ElementRest r = computeElementRest(X);
    const Mat12 K = linearStiffness(r, lame);
    const Mat3 A = randomRotation(rng) * (Mat3::Identity() + 0.1 * Mat3::Random());
    const auto x = transform(X, A, Vec3d(1, 2, 3));
    const Mat3 R = polarRotation(deformationGradient(r, x));
    const Vec12 f = corotationalForce(K, R, x, X);
    const double h = 1e-6;
    Vec12 fd;
    for (int d = 0; d < 12; ++d) {
      auto xp = x, xm = x;
      xp[d / 3][d % 3] += h;
      xm[d / 3][d % 3] -= h;
      const double ep = corotationalEnergy(K, polarRotation(deformationGradient(r, xp)), xp, X);
      const double em = corotationalEnergy(K, polarRotation(deformationGradient(r, xm)), xm, X);
      fd[d] = (ep - em) / (2 * h);
    }
    EXPECT_LT((fd - f).norm(), 1e-7 * f.norm());
    // Eq. 10/11: f = K^R x - R K X with K^R = R K R^T.
    const Mat12 KR = rotateStiffness(K, R);
    Vec12 RKX;
    const Vec12 KX = K * flatten(X);
    for (int i = 0; i < 4; ++i) RKX.segment<3>(3 * i) = R * KX.segment<3>(3 * i);
    EXPECT_LT((KR * flatten(x) - RKX - f).norm(), 1e-10 * (KR * flatten(x)).norm());
    EXPECT_LT((KR - KR.transpose()).norm(), 1e-12 * KR.norm());
  }
}

TEST(Mass, LumpedAndConsistent) {
  std::mt19937 rng(19);
  const auto X = randomElement(rng);
  const ElementRest r = computeElementRest(X);
  const double rho = 1200.0, total = rho * r.volume;
  EXPECT_DOUBLE_EQ(4 * lumpedNodeMass(r, rho), total);
  const Mat12 M = consistentMass(r, rho);
  EXPECT_LT((M - M.transpose()).norm(), 1e-15 * total);
  // Row sums equal the lumped mass; total mass per component; positive definite.
  for (int a = 0; a < 12; ++a) EXPECT_NEAR(M.row(a).sum(), total / 4, 1e-12 * total);
  Vec12 ones = Vec12::Zero();
  for (int i = 0; i < 4; ++i) ones[3 * i] = 1.0;
  EXPECT_NEAR(ones.dot(M * ones), total, 1e-12 * total);
  EXPECT_NEAR(M(0, 0), total / 10, 1e-12 * total);
  EXPECT_NEAR(M(0, 3), total / 20, 1e-12 * total);
  EXPECT_EQ(M(0, 1), 0.0);
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Mat12>(M).eigenvalues().minCoeff(), 0.0);
}

TEST(Energy, LinearEnergyIsStrainEnergyDensityTimesVolume) {
  // 1/2 u^T K u = V (mu eps:eps + lambda/2 tr(eps)^2) for a homogeneous small strain.
  std::mt19937 rng(23);
  const Lame lame = lameFromYoungPoisson(3e5, 0.2);
  const auto X = randomElement(rng);
  const ElementRest r = computeElementRest(X);
  const Mat3 G = 1e-2 * Mat3::Random();
  const auto x = transform(X, Mat3::Identity() + G, Vec3d::Zero());
  const Mat3 eps = smallStrain(deformationGradient(r, x));
  const double expected = r.volume * (lame.mu * eps.squaredNorm() + 0.5 * lame.lambda * eps.trace() * eps.trace());
  EXPECT_NEAR(corotationalEnergy(linearStiffness(r, lame), Mat3::Identity(), x, X), expected, 1e-10 * expected);
}
