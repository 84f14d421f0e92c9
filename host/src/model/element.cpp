// Linear tetrahedron mathematics (paper Eqs. 4-9, 11), double precision: the reference every
// backend and kernel is checked against.
#include "model/element.hpp"

#include "util/error.hpp"

#include <Eigen/Dense>
#include <Eigen/SVD>

#include <cmath>

namespace corofem::detail {

Lame lameFromYoungPoisson(double youngsModulus, double poissonRatio) {
  if (!(std::isfinite(youngsModulus) && youngsModulus > 0.0))
    fail(ErrorCode::BadInput, "Young's modulus E = ", youngsModulus,
         " Pa is invalid; it must be finite and > 0 (e.g. 1e5 for rubber, 2e11 for steel)");
  if (!(std::isfinite(poissonRatio) && poissonRatio > -1.0 && poissonRatio < 0.5))
    fail(ErrorCode::BadInput, "Poisson's ratio nu = ", poissonRatio,
         " is invalid; it must lie in the open range (-1, 0.5) (e.g. 0.3; use 0.49 for nearly incompressible)");
  // lambda = E nu / ((1 + nu)(1 - 2 nu)), mu = E / (2 (1 + nu)).
  Lame lame;
  lame.lambda = youngsModulus * poissonRatio / ((1.0 + poissonRatio) * (1.0 - 2.0 * poissonRatio));
  lame.mu = youngsModulus / (2.0 * (1.0 + poissonRatio));
  return lame;
}

namespace {

/// Edge matrix [p1-p0, p2-p0, p3-p0] (columns): D_m at rest, D_s when deformed.
Mat3 edgeMatrix(const std::array<Vec3d, 4>& p) {
  Mat3 D;
  D.col(0) = p[1] - p[0];
  D.col(1) = p[2] - p[0];
  D.col(2) = p[3] - p[0];
  return D;
}

}  // namespace

double signedVolume(const std::array<Vec3d, 4>& X) { return edgeMatrix(X).determinant() / 6.0; }

ElementRest computeElementRest(const std::array<Vec3d, 4>& X) {
  const Mat3 Dm = edgeMatrix(X);
  const double volume = Dm.determinant() / 6.0;
  if (!(volume > 0.0)) {
    if (volume < 0.0)
      fail(ErrorCode::BadInput, "tetrahedron is inverted (signed volume ", volume,
           " m^3): its nodes are ordered negatively; swap two of them");
    fail(ErrorCode::BadInput, "tetrahedron has zero volume (signed volume ", volume,
         " m^3): its nodes are coplanar or coincident; remove it or fix the coordinates");
  }
  ElementRest rest;
  rest.volume = volume;
  rest.DmInv = Dm.inverse();
  // Eqs. 4-6: x = X0 + D_m xi, so the natural coordinates are xi = D_m^-1 (x - X0) and the shape
  // functions N_1..N_3 = xi_1..xi_3, N_0 = 1 - xi_1 - xi_2 - xi_3. Their (constant) gradients are
  // the rows of D_m^-1, and grad N_0 = -(sum of the others), so the rows sum to zero.
  rest.grad.row(1) = rest.DmInv.row(0);
  rest.grad.row(2) = rest.DmInv.row(1);
  rest.grad.row(3) = rest.DmInv.row(2);
  rest.grad.row(0) = -(rest.grad.row(1) + rest.grad.row(2) + rest.grad.row(3));
  if (!rest.DmInv.allFinite())
    fail(ErrorCode::BadInput, "tetrahedron is degenerate (volume ", volume,
         " m^3 but its edge matrix cannot be inverted); fix the coordinates");
  return rest;
}

Mat12 linearStiffness(const ElementRest& rest, const Lame& lame) {
  // Eq. 8: B (6x12) maps nodal displacements to the engineering strain
  // (e_xx, e_yy, e_zz, g_xy, g_yz, g_zx); H (6x6) is the isotropic elasticity matrix.
  Eigen::Matrix<double, 6, 12> B = Eigen::Matrix<double, 6, 12>::Zero();
  for (int i = 0; i < 4; ++i) {
    const double gx = rest.grad(i, 0), gy = rest.grad(i, 1), gz = rest.grad(i, 2);
    const int c = 3 * i;
    B(0, c + 0) = gx;
    B(1, c + 1) = gy;
    B(2, c + 2) = gz;
    B(3, c + 0) = gy;  B(3, c + 1) = gx;
    B(4, c + 1) = gz;  B(4, c + 2) = gy;
    B(5, c + 0) = gz;  B(5, c + 2) = gx;
  }
  Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
  H.topLeftCorner<3, 3>().setConstant(lame.lambda);
  H.topLeftCorner<3, 3>().diagonal().array() += 2.0 * lame.mu;
  H.bottomRightCorner<3, 3>().diagonal().setConstant(lame.mu);
  // Eq. 7 with constant integrand: K_e = V B^T H B. Symmetrised to remove rounding asymmetry.
  Mat12 K = rest.volume * (B.transpose() * H * B);
  return 0.5 * (K + K.transpose());
}

Mat3 deformationGradient(const ElementRest& rest, const std::array<Vec3d, 4>& x) {
  return edgeMatrix(x) * rest.DmInv;  // F = D_s D_m^-1
}

namespace {

/// The rotation of F by SVD, for every F: F = U S V^T, R = U V^T. When det(U V^T) < 0 (inverted
/// element, det F < 0) the column of U for the smallest singular value is negated, which gives the
/// closest proper rotation (det R = +1) and a signed stretch diag(s0, s1, -s2): the element is
/// treated as a rotated, inverted one.
Mat3 rotationBySvd(const Mat3& F) {
  Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU();
  const Mat3& V = svd.matrixV();
  if ((U * V.transpose()).determinant() < 0.0) U.col(2) = -U.col(2);  // singular values descend
  return U * V.transpose();
}

/// det F / |F|_F^3 below which (a singular value under about 1e-6 of the others, or an inverted F)
/// the SVD decides; the same threshold as the kernels' Newton polar (kernels/opencl/rotation.cl).
constexpr double kNewtonMinDet = 1e-6;

/// The polar factor of F (det F > 0, well away from 0) by Higham's scaled Newton iteration
/// X <- (zeta X + X^-T / zeta) / 2, zeta = (|X^-1|_F / |X|_F)^(1/2) until the steps are small, then
/// unscaled (quadratic convergence): a step under 1e-9 leaves an error near its square, so the
/// next iterate is the polar factor to rounding. False where 20 steps did not get there.
bool rotationByNewton(const Mat3& F, Mat3& R) {
  Mat3 X = F;
  bool scaled = true;
  for (int k = 0; k < 20; ++k) {
    Mat3 invT;  // X^-T: the columns of X's cofactor matrix over det X
    invT.col(0) = X.col(1).cross(X.col(2));
    invT.col(1) = X.col(2).cross(X.col(0));
    invT.col(2) = X.col(0).cross(X.col(1));
    const double det = X.col(0).dot(invT.col(0));
    if (!(det > 0.0)) return false;
    invT /= det;
    const double zeta = scaled ? std::sqrt(std::sqrt(invT.squaredNorm() / X.squaredNorm())) : 1.0;
    const Mat3 next = 0.5 * (zeta * X + invT / zeta);
    const double step = (next - X).norm();
    X = next;
    if (step < 1e-9) {
      R = X;
      return true;
    }
    if (step < 1e-2) scaled = false;
  }
  return false;
}

}  // namespace

Mat3 polarRotation(const Mat3& F) {
  // Newton where F is a proper, not nearly flat deformation (the common case, and several times
  // cheaper than the SVD: docs/performance.md); the SVD for inverted, flat or non-finite F and
  // where Newton stops short.
  const double norm = F.norm();
  Mat3 R;
  if (F.determinant() > kNewtonMinDet * norm * norm * norm && rotationByNewton(F, R)) return R;
  return rotationBySvd(F);
}

Vec12 corotationalForce(const Mat12& K, const Mat3& R, const std::array<Vec3d, 4>& x,
                        const std::array<Vec3d, 4>& X, double* energy) {
  // Eq. 9: f = R K (R^T x - X), applied node by node with the block-diagonal R.
  Vec12 u;
  for (int i = 0; i < 4; ++i) u.segment<3>(3 * i) = R.transpose() * x[i] - X[i];
  // lazyProduct: Eigen's coefficient loops, unrolled at 12 x 12 (its general matrix-vector
  // kernel, which `K * u` takes at this size, costs more in set-up than in arithmetic here).
  const Vec12 local = K.lazyProduct(u);
  if (energy) *energy = 0.5 * u.dot(local);
  Vec12 f;
  for (int i = 0; i < 4; ++i) f.segment<3>(3 * i) = R * local.segment<3>(3 * i);
  return f;
}

double lumpedNodeMass(const ElementRest& rest, double density) { return density * rest.volume / 4.0; }

Mat12 consistentMass(const ElementRest& rest, double density) {
  // Integral of rho N_i N_j over a linear tetrahedron = rho V (1 + delta_ij) / 20.
  Mat12 M = Mat12::Zero();
  const double m = density * rest.volume / 20.0;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      M.block<3, 3>(3 * i, 3 * j).diagonal().setConstant(i == j ? 2.0 * m : m);
  return M;
}

Mat12 rotateStiffness(const Mat12& K, const Mat3& R) {
  // Eq. 11: K^R = R K R^T with R the block-diagonal of four copies of the 3x3 rotation.
  // K is symmetric (K_ji = K_ij^T), so R K_ji R^T is the transpose of R K_ij R^T: each block pair
  // is formed once. The result is symmetric but for the rounding of the diagonal blocks R K_ii R^T.
  Mat12 out;
  for (int i = 0; i < 4; ++i)
    for (int j = i; j < 4; ++j) {
      const Mat3 block = R * K.block<3, 3>(3 * i, 3 * j) * R.transpose();
      out.block<3, 3>(3 * i, 3 * j) = block;
      if (j != i) out.block<3, 3>(3 * j, 3 * i) = block.transpose();
    }
  return out;
}

double corotationalEnergy(const Mat12& K, const Mat3& R, const std::array<Vec3d, 4>& x,
                          const std::array<Vec3d, 4>& X) {
  // Through the force's code, so that an energy the force pass gave (the reference backend keeps
  // those) has the same bits as one computed alone.
  double energy = 0.0;
  corotationalForce(K, R, x, X, &energy);
  return energy;
}

Mat3 smallStrain(const Mat3& F) { return 0.5 * (F + F.transpose()) - Mat3::Identity(); }

Mat3 hookeStress(const Mat3& strain, const Lame& lame) {
  return lame.lambda * strain.trace() * Mat3::Identity() + 2.0 * lame.mu * strain;
}

}  // namespace corofem::detail
