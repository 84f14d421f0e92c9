// The warped precomputed Cholesky of precond/warped_cholesky.hpp.
#include "precond/warped_cholesky.hpp"

#include "precond/nested_dissection.hpp"
#include "util/error.hpp"
#include "util/parallel.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <functional>
#include <utility>

namespace corofem::detail {

namespace {

/// Where a rigid motion costs less than this, relative to its diagonal weight, the rest operator is
/// singular. Rounding leaves a free body's rigid motions within 1.5e-16 of 0 in statics (box beams
/// of 4 to 60 cells, E = 1e5 and 2e11). A held body's smallest falls as its length cubed: a
/// cantilever of n x 1 x 1 cells clamped at one end gives 2.3e-7 at n = 100, 6.5e-10 at 700 and
/// 8.3e-12 at 3,000 (its stiffness's condition number, about n^4, nears double precision's
/// reach near n = 10,000). With mass (dynamics) it is at least about the ratio of mass to
/// stiffness on the diagonal: 1.6e-9 for a 1 m steel-stiff (E = 2e11) beam at 1/60 s.
/// (tests/solve/test_warped_cholesky.cpp, StaticsOfABodyNothingHoldsFailsWithTheFix.)
constexpr double kRigidThreshold = 1e-13;

/// The smallest Rayleigh quotient v.A v / v.D v over the rigid motions v of the body (three
/// translations, three rotations about its rest centroid) on its free dofs, D = diag(A) (all
/// positive); +infinity where the free dofs span no rigid motion.
double weakestRigidMotion(const AmgMatrix& A, const std::vector<Eigen::Index>& freeDofs, const Eigen::VectorXd& rest,
                          const Eigen::VectorXd& diagonal) {
  const auto n = static_cast<Eigen::Index>(freeDofs.size());
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (Eigen::Index i = 0; i + 2 < rest.size(); i += 3) centre += rest.segment<3>(i);
  centre /= std::max<double>(1.0, static_cast<double>(rest.size() / 3));
  // S = D^1/2 B, B the six motions on the free dofs; an orthonormal basis Q of its range.
  Eigen::MatrixXd S(n, 6);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index d = freeDofs[static_cast<std::size_t>(i)];
    const int c = static_cast<int>(d % 3);
    const Eigen::Vector3d arm = rest.segment<3>(d - c) - centre;
    const double w = std::sqrt(diagonal[i]);
    for (int k = 0; k < 3; ++k) {
      S(i, k) = w * (k == c ? 1.0 : 0.0);
      S(i, 3 + k) = w * Eigen::Vector3d::Unit(k).cross(arm)[c];  // rotation about axis k
    }
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(S);
  const double largest = std::abs(qr.matrixR()(0, 0));
  Eigen::Index rank = 0;
  for (Eigen::Index k = 0; k < std::min<Eigen::Index>(6, n); ++k)
    if (std::abs(qr.matrixR()(k, k)) > 1e-10 * largest) ++rank;
  if (rank == 0) return INFINITY;
  const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(n, rank);
  // G = Q^T D^-1/2 A D^-1/2 Q: its smallest eigenvalue is the smallest Rayleigh quotient.
  const Eigen::VectorXd s = diagonal.cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd AQ = A * (s.asDiagonal() * Q);
  const Eigen::MatrixXd G = Q.transpose() * (s.asDiagonal() * AQ);
  return Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(0.5 * (G + G.transpose()), Eigen::EigenvaluesOnly)
      .eigenvalues()
      .minCoeff();
}

[[noreturn]] void failSingular(const std::string& body) {
  fail(ErrorCode::SolveFailed, "body '", body, "': the preconditioner \"warped_cholesky\" factors the body's system at "
       "rest, and it is singular: a rigid motion of the body costs it no energy (statics of a body too few "
       "\"fixed\" nodes hold; spring handles are not in the factor), or a free node is in no element (it has no "
       "mass or stiffness). Hold the body with \"fixed\" nodes (at least three not on one line), run a dynamic "
       "analysis, or use the preconditioner \"amg\"");
}

}  // namespace

void WarpedCholesky::build(const AmgMatrix& A0, const std::vector<Eigen::Index>& freeDofs, const Eigen::VectorXd& rest,
                           const std::string& body) {
  clear();
  checkRestSystem("WarpedCholesky", A0, freeDofs, rest);
  const auto n = static_cast<Eigen::Index>(freeDofs.size());
  if (n > 0) {
    const Eigen::VectorXd diagonal = A0.diagonal();
    if (!(diagonal.minCoeff() > 0.0) || !diagonal.allFinite() ||
        !(weakestRigidMotion(A0, freeDofs, rest, diagonal) > kRigidThreshold))
      failSingular(body);
    // P A0 P^T in nested dissection order (precond/nested_dissection.hpp), factored as it stands.
    // LDL^T of a positive definite matrix has a positive D; anything else (a mechanism the rigid
    // motions above do not show) would make PCG break down.
    const std::vector<int> position = nestedDissection(A0, freeDofs, rest);
    const Eigen::Map<const Eigen::VectorXi> perm(position.data(), n);
    if (!factor_.factor(Eigen::SparseMatrix<double>(A0), perm)) failSingular(body);
    factorEntries_ = static_cast<Eigen::Index>(factor_.factorEntries());
  }
  freeDofs_ = freeDofs;
  nodeCount_ = static_cast<std::size_t>(rest.size() / 3);
  for (std::size_t i = 0; i < freeDofs_.size(); ++i) {
    const std::size_t node = static_cast<std::size_t>(freeDofs_[i]) / 3;
    if (warpNodes_.empty() || warpNodes_.back().node != node) warpNodes_.push_back({node, {-1, -1, -1}});
    warpNodes_.back().free[freeDofs_[i] % 3] = static_cast<int>(i);
  }
  built_ = true;
}

void WarpedCholesky::clear() {
  built_ = false;
  freeDofs_.clear();
  warpNodes_.clear();
  blocks_.clear();
  factor_ = SupernodalLdlt();
  factorEntries_ = 0;
}

void WarpedCholesky::setNodeRotations(std::vector<Mat3> rotations) {
  if (!rotations.empty() && rotations.size() != nodeCount_)
    fail(ErrorCode::Internal, "WarpedCholesky: ", rotations.size(), " node rotations for ", nodeCount_, " nodes");
  blocks_.clear();
  if (rotations.empty()) return;
  blocks_.reserve(warpNodes_.size());
  for (const WarpNode& w : warpNodes_) {
    const Mat3& R = rotations[w.node];
    int dofs[3], k = 0;
    for (int c = 0; c < 3; ++c)
      if (w.free[c] >= 0) dofs[k++] = c;
    if (k == 3) {
      blocks_.push_back(R);
      continue;
    }
    // A slip condition: the polar factor U V^T of the free dofs' block (orthogonal even where the
    // block is singular).
    Eigen::MatrixXd F(k, k);
    for (int i = 0; i < k; ++i)
      for (int j = 0; j < k; ++j) F(i, j) = R(dofs[i], dofs[j]);
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::MatrixXd Q = svd.matrixU() * svd.matrixV().transpose();
    Mat3 block = Mat3::Zero();
    for (int i = 0; i < k; ++i)
      for (int j = 0; j < k; ++j) block(dofs[i], dofs[j]) = Q(i, j);
    blocks_.push_back(block);
  }
}

void WarpedCholesky::warp(const Eigen::VectorXd& v, Eigen::VectorXd& out, bool transpose) const {
  out.resize(v.size());
  for (std::size_t n = 0; n < warpNodes_.size(); ++n) {
    const WarpNode& w = warpNodes_[n];
    Vec3d a;
    for (int c = 0; c < 3; ++c) a[c] = w.free[c] >= 0 ? v[w.free[c]] : 0.0;
    const Vec3d b = transpose ? Vec3d(blocks_[n].transpose() * a) : Vec3d(blocks_[n] * a);
    for (int c = 0; c < 3; ++c)
      if (w.free[c] >= 0) out[w.free[c]] = b[c];
  }
}

void WarpedCholesky::apply(const Eigen::VectorXd& r, Eigen::VectorXd& z) const {
  if (!built_ || r.size() != static_cast<Eigen::Index>(freeDofs_.size()))
    fail(ErrorCode::Internal, "WarpedCholesky: applied to ", r.size(), " entries, built for ", freeDofs_.size(),
         built_ ? " free dofs" : " (not built)");
  if (freeDofs_.empty()) {
    z.resize(0);
    return;
  }
  if (blocks_.empty()) {
    factor_.solve(r, z);
    return;
  }
  Eigen::VectorXd t, s;
  warp(r, t, true);
  factor_.solve(t, s);
  warp(s, z, false);
}

Eigen::Index WarpedCholesky::factorEntries() const {
  return factorEntries_;
}

std::vector<Mat3> nodeRotations(const TetMesh& mesh, const std::vector<Mat3>& elementRotations) {
  if (elementRotations.size() != mesh.tetCount())
    fail(ErrorCode::Internal, "nodeRotations: ", elementRotations.size(), " rotations for ", mesh.tetCount(),
         " elements");
  std::vector<Mat3> sum(mesh.nodeCount(), Mat3::Zero());
  for (std::size_t e = 0; e < elementRotations.size(); ++e)
    for (int a = 0; a < 4; ++a) sum[mesh.tets[4 * e + a]] += elementRotations[e];
  parallelChunks(sum.size(), 1024, [&](std::size_t, std::size_t begin, std::size_t end) {
    for (std::size_t n = begin; n < end; ++n) sum[n] = sum[n].isZero() ? Mat3::Identity() : polarRotation(sum[n]);
  });
  return sum;
}

Made BodyCholesky::ensure(const Problem& p, const std::vector<Eigen::Index>& freeDofs, double massScale,
                          double stiffScale) {
  const double ratio = restRatio(massScale, stiffScale);
  const Made found = pair_.find(ratio, freeDofs);
  if (found != Made::Built) return found;
  bool remade = false;
  const AmgMatrix& stiffness = stiffness_.of(p, remade);
  if (remade) pair_.clear();  // the spare is of another stiffness
  pair_.now().build(restOperator(stiffness, p, freeDofs, massScale, stiffScale), freeDofs, p.restPositions, p.name);
  pair_.made(ratio);
  ++builds_;
  return Made::Built;
}

}  // namespace corofem::detail
