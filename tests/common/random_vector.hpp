// Reproducible random vectors for the tests: n entries uniform in [-1, 1] from a seed (never zeros).
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <random>

namespace corofem::test {

/// n entries uniform in [-1, 1], reproducible from the seed.
inline Eigen::VectorXd randomVector(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd v(static_cast<Eigen::Index>(n));
  for (Eigen::Index i = 0; i < v.size(); ++i) v[i] = u(rng);
  return v;
}

}  // namespace corofem::test
