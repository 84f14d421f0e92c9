// A fast exact test for non-finite entries (NaN or infinity) in Eigen vectors.
#pragma once

#include <Eigen/Core>

#include <cmath>

namespace corofem::detail {

/// True when every entry of v is finite. The sum of v * 0 is then ±0, and NaN as soon as one
/// entry is NaN or infinite (inf * 0 = NaN): exact (a plain sum of v could overflow), and Eigen
/// vectorises the reduction, where its allFinite() tests entry by entry. The drivers test their
/// vectors several times a step, on every body (tests/solve/test_finite.cpp).
template <class Derived>
bool allFiniteEntries(const Eigen::DenseBase<Derived>& v) {
#if defined(__FAST_MATH__) || (defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__)
  return v.derived().allFinite();  // the compiler may assume no NaN or inf: Eigen's test copes, this one not
#else
  using Scalar = typename Derived::Scalar;
  return !std::isnan((v.derived().array() * Scalar(0)).sum());
#endif
}

}  // namespace corofem::detail
