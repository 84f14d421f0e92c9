// util/finite.hpp: the drivers' test for NaN and infinite entries agrees with Eigen's allFinite()
// on every kind of entry, at every position and length (the packets of the vectorised sum and
// their tail), in double and float.
#include "util/finite.hpp"

#include <gtest/gtest.h>

#include <limits>
#include <random>
#include <vector>

namespace corofem {
namespace {

template <class Scalar>
void agreesWithEigen() {
  using Vector = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;
  using L = std::numeric_limits<Scalar>;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1e3, 1e3);
  const Scalar specials[] = {L::infinity(), -L::infinity(), L::quiet_NaN(), -L::quiet_NaN(), L::max(), L::lowest(),
                             L::denorm_min(), Scalar(-0.0), L::min()};
  for (int n : {0, 1, 2, 3, 4, 5, 7, 8, 9, 15, 16, 17, 1890}) {
    Vector v(n);
    for (int i = 0; i < n; ++i) v[i] = static_cast<Scalar>(u(rng));
    EXPECT_TRUE(detail::allFiniteEntries(v)) << n;
    for (int pos : {0, n / 2, n - 1}) {
      if (n == 0) break;
      for (Scalar s : specials) {
        Vector w = v;
        w[pos] = s;
        EXPECT_EQ(detail::allFiniteEntries(w), w.allFinite()) << "n " << n << ", entry " << pos << " = " << s;
      }
    }
  }
  // Huge finite entries whose plain sum overflows are still finite.
  const Vector huge = Vector::Constant(33, L::max());
  EXPECT_TRUE(detail::allFiniteEntries(huge));
  // Maps of unaligned storage, as the OpenCL backend passes its staging buffers.
  std::vector<Scalar> storage(48);
  for (Scalar& x : storage) x = static_cast<Scalar>(u(rng));
  for (int offset = 0; offset < 5; ++offset)
    for (int n : {0, 1, 3, 9, 17, 40}) {
      Eigen::Map<Vector> m(storage.data() + offset, n);
      EXPECT_TRUE(detail::allFiniteEntries(m));
      if (n == 0) continue;
      const Scalar keep = m[n - 1];
      m[n - 1] = L::quiet_NaN();
      EXPECT_FALSE(detail::allFiniteEntries(Eigen::Map<const Vector>(storage.data() + offset, n)));
      m[n - 1] = keep;
    }
  // An expression, not only a vector.
  const Vector a = Vector::Ones(9);
  EXPECT_TRUE(detail::allFiniteEntries(a * Scalar(2)));
  EXPECT_FALSE(detail::allFiniteEntries(a / Scalar(0)));
}

TEST(Finite, AgreesWithEigensAllFiniteInDouble) { agreesWithEigen<double>(); }
TEST(Finite, AgreesWithEigensAllFiniteInFloat) { agreesWithEigen<float>(); }

}  // namespace
}  // namespace corofem
