// Textbook PCG on an assembled sparse matrix (tests and bench/bench_warped_cholesky.cpp): a
// yardstick for preconditioners written outside the library's solver.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <functional>

namespace corofem::test {

/// PCG on A x = b from x = 0 to |r| <= tolerance |b|, with z = M(r); returns the iterations taken,
/// or `cap` where it stopped short.
template <class Matrix>
int textbookPcgIterations(const Matrix& A, const Eigen::VectorXd& b,
                          const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& M, double tolerance,
                          int cap = 5000) {
  Eigen::VectorXd x = Eigen::VectorXd::Zero(b.size()), r = b, z = M(r), p = z;
  double rz = r.dot(z);
  for (int it = 0; it < cap; ++it) {
    if (r.norm() <= tolerance * b.norm()) return it;
    const Eigen::VectorXd Ap = A * p;
    const double alpha = rz / p.dot(Ap);
    x += alpha * p;
    r -= alpha * Ap;
    z = M(r);
    const double rzNew = r.dot(z);
    p = z + (rzNew / rz) * p;
    rz = rzNew;
  }
  return cap;
}

}  // namespace corofem::test
