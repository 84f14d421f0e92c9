// The warped precomputed Cholesky of precond/warped_cholesky.hpp.
#include "precond/warped_cholesky.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <functional>
#include <utility>

namespace corofem::detail {

void WarpedCholesky::build(const AmgMatrix& A0, const std::vector<Eigen::Index>& freeDofs, std::size_t nodeCount,
                           const std::string& body) {
  clear();
  const auto n = static_cast<Eigen::Index>(freeDofs.size());
  if (A0.rows() != n || A0.cols() != n ||
      std::adjacent_find(freeDofs.begin(), freeDofs.end(), std::greater_equal<Eigen::Index>()) != freeDofs.end() ||
      (!freeDofs.empty() && (freeDofs.front() < 0 || freeDofs.back() >= static_cast<Eigen::Index>(3 * nodeCount))))
    fail(ErrorCode::Internal, "WarpedCholesky: a rest operator of ", A0.rows(), " x ", A0.cols(), " for ", n,
         " free dofs, or free dofs not strictly ascending within 0..", 3 * nodeCount, " - 1");
  if (n > 0) {
    factor_ = std::make_unique<Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower>>(
        Eigen::SparseMatrix<double>(A0));
    // LDL^T of a positive definite matrix has a positive D; anything else (a zero or negative
    // pivot: the body can move rigidly with no mass to resist) would make PCG break down.
    if (factor_->info() != Eigen::Success || !(factor_->vectorD().minCoeff() > 0.0) || !factor_->vectorD().allFinite()) {
      factor_.reset();
      fail(ErrorCode::SolveFailed, "body '", body, "': the preconditioner \"warped_cholesky\" factors the body's "
           "system at rest, and it is singular: nothing holds the body against a rigid motion (statics of a body "
           "without enough constrained nodes). Constrain the body, or use the preconditioner \"diagonal\"");
    }
  }
  freeDofs_ = freeDofs;
  nodeCount_ = nodeCount;
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
  rotations_.clear();
  factor_.reset();
}

void WarpedCholesky::setNodeRotations(std::vector<Mat3> rotations) {
  if (!rotations.empty() && rotations.size() != nodeCount_)
    fail(ErrorCode::Internal, "WarpedCholesky: ", rotations.size(), " node rotations for ", nodeCount_, " nodes");
  rotations_ = std::move(rotations);
}

void WarpedCholesky::warp(const Eigen::VectorXd& v, Eigen::VectorXd& out, bool transpose) const {
  out.resize(v.size());
  for (const WarpNode& w : warpNodes_) {
    Vec3d a;
    for (int c = 0; c < 3; ++c) a[c] = w.free[c] >= 0 ? v[w.free[c]] : 0.0;
    const Mat3& R = rotations_[w.node];
    const Vec3d b = transpose ? Vec3d(R.transpose() * a) : Vec3d(R * a);
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
  if (rotations_.empty()) {
    z = factor_->solve(r);
    return;
  }
  Eigen::VectorXd t;
  warp(r, t, true);
  const Eigen::VectorXd s = factor_->solve(t);
  warp(s, z, false);
}

Eigen::Index WarpedCholesky::factorEntries() const {
  return factor_ ? factor_->matrixL().nestedExpression().nonZeros() : 0;
}

std::vector<Mat3> nodeRotations(const TetMesh& mesh, const std::vector<Mat3>& elementRotations) {
  if (elementRotations.size() != mesh.tetCount())
    fail(ErrorCode::Internal, "nodeRotations: ", elementRotations.size(), " rotations for ", mesh.tetCount(),
         " elements");
  std::vector<Mat3> sum(mesh.nodeCount(), Mat3::Zero());
  for (std::size_t e = 0; e < elementRotations.size(); ++e)
    for (int a = 0; a < 4; ++a) sum[mesh.tets[4 * e + a]] += elementRotations[e];
  for (Mat3& s : sum) s = s.isZero() ? Mat3::Identity() : polarRotation(s);
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
  pair_.now().build(restOperator(stiffness, p, freeDofs, massScale, stiffScale), freeDofs, p.mesh.nodeCount(), p.name);
  pair_.made(ratio);
  ++builds_;
  return Made::Built;
}

}  // namespace corofem::detail
