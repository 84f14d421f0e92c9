// 3x3 block-Jacobi preconditioner usable as the Preconditioner of Eigen's ConjugateGradient:
// M^-1 = blockdiag(A_nn)^-1 with one block per node (its 1-3 free dofs).
#pragma once

#include <Eigen/Core>
#include <Eigen/Dense>
#include <Eigen/SparseCore>

#include <cmath>
#include <vector>

namespace corofem::detail {

class BlockJacobiPreconditioner {
 public:
  using Scalar = double;
  using StorageIndex = int;
  enum { ColsAtCompileTime = Eigen::Dynamic, MaxColsAtCompileTime = Eigen::Dynamic };

  BlockJacobiPreconditioner() = default;

  /// Block k covers rows [starts[k], starts[k+1]); the last entry is the matrix size. Without
  /// blocks the preconditioner is the plain diagonal (blocks of size 1).
  void setBlocks(std::vector<int> starts) { starts_ = std::move(starts); }

  template <class MatType>
  BlockJacobiPreconditioner& analyzePattern(const MatType&) { return *this; }

  template <class MatType>
  BlockJacobiPreconditioner& factorize(const MatType& A) {
    const int n = static_cast<int>(A.rows());
    if (starts_.empty() || starts_.back() != n) {
      starts_.resize(static_cast<std::size_t>(n) + 1);
      for (int i = 0; i <= n; ++i) starts_[static_cast<std::size_t>(i)] = i;
    }
    inv_.assign(starts_.size() - 1, Eigen::Matrix3d::Zero());
    std::vector<int> blockOf(static_cast<std::size_t>(n));
    for (std::size_t k = 0; k + 1 < starts_.size(); ++k)
      for (int r = starts_[k]; r < starts_[k + 1]; ++r) blockOf[static_cast<std::size_t>(r)] = static_cast<int>(k);
    std::vector<Eigen::Matrix3d> blocks(inv_.size(), Eigen::Matrix3d::Zero());
    for (int col = 0; col < A.outerSize(); ++col)
      for (typename MatType::InnerIterator it(A, col); it; ++it) {
        const int row = static_cast<int>(it.index());
        const int k = blockOf[static_cast<std::size_t>(col)];
        if (blockOf[static_cast<std::size_t>(row)] != k) continue;
        blocks[static_cast<std::size_t>(k)](row - starts_[static_cast<std::size_t>(k)],
                                            col - starts_[static_cast<std::size_t>(k)]) = it.value();
      }
    for (std::size_t k = 0; k < blocks.size(); ++k) {
      const int size = starts_[k + 1] - starts_[k];
      const Eigen::Matrix3d& B = blocks[k];
      Eigen::Matrix3d inv = Eigen::Matrix3d::Zero();
      bool ok = false;
      if (size == 3) {
        inv = B.inverse();
        ok = inv.allFinite() && std::abs(B.determinant()) > 1e-14 * std::pow(B.norm(), 3);
      } else if (size == 2) {
        const Eigen::Matrix2d b2 = B.topLeftCorner<2, 2>();
        inv.topLeftCorner<2, 2>() = b2.inverse();
        ok = inv.allFinite() && std::abs(b2.determinant()) > 1e-14 * b2.squaredNorm();
      }
      if (!ok) {
        // Singular or 1x1 block (possible for indefinite tangents): fall back to the diagonal, and
        // to 1 where the diagonal is zero (as Eigen's DiagonalPreconditioner does).
        inv.setZero();
        for (int i = 0; i < size; ++i) inv(i, i) = B(i, i) != 0.0 ? 1.0 / B(i, i) : 1.0;
      }
      inv_[k] = inv;
    }
    return *this;
  }

  template <class MatType>
  BlockJacobiPreconditioner& compute(const MatType& A) { return factorize(A); }

  template <class Rhs>
  Eigen::VectorXd solve(const Rhs& b) const {
    Eigen::VectorXd z(b.size());
    for (std::size_t k = 0; k < inv_.size(); ++k) {
      const int s = starts_[k], size = starts_[k + 1] - s;
      for (int i = 0; i < size; ++i) {
        double v = 0.0;
        for (int j = 0; j < size; ++j) v += inv_[k](i, j) * b[s + j];
        z[s + i] = v;
      }
    }
    return z;
  }

  Eigen::ComputationInfo info() const { return Eigen::Success; }

 private:
  std::vector<int> starts_;
  std::vector<Eigen::Matrix3d> inv_;
};

}  // namespace corofem::detail
