// The warped Cholesky's factor and solves (precond/supernodal_ldlt.hpp) and order
// (precond/nested_dissection.hpp): the supernodal factor and solves against Eigen's simplicial
// factor on random symmetric positive definite matrices of awkward sizes and on a beam's rest
// operator in its nested dissection order (the same pattern, the same solutions), matrices that are
// not positive definite refused, the same bits whatever runs the tasks and in whatever order, and
// the order's split of the beam into independent subtrees with a fill near minimum degree's.
#include "precond/nested_dissection.hpp"
#include "precond/rest_system.hpp"
#include "precond/supernodal_ldlt.hpp"
#include "common/clamped_beam.hpp"
#include "common/random_vector.hpp"
#include "util/error.hpp"
#include "util/parallel.hpp"

#include <gtest/gtest.h>

#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <limits>
#include <random>
#include <tuple>

using namespace corofem;
using namespace corofem::detail;
using corofem::test::randomVector;

namespace {

using Ldlt = Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower>;

/// A random sparse symmetric positive definite n x n matrix: about `perRow` random off-diagonal
/// entries a row in [-1, 1], the diagonal above the row's absolute sum.
Eigen::SparseMatrix<double> randomSpd(int n, int perRow, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> col(0, std::max(0, n - 1));
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  std::vector<Eigen::Triplet<double>> entries;
  std::vector<double> rowSum(static_cast<std::size_t>(n), 0.0);
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < perRow; ++k) {
      const int j = col(rng);
      if (j == i) continue;
      const double v = value(rng);
      entries.emplace_back(i, j, v);
      entries.emplace_back(j, i, v);
      rowSum[static_cast<std::size_t>(i)] += std::abs(v);
      rowSum[static_cast<std::size_t>(j)] += std::abs(v);
    }
  for (int i = 0; i < n; ++i) entries.emplace_back(i, i, 1.0 + rowSum[static_cast<std::size_t>(i)] + value(rng) * 0.5);
  Eigen::SparseMatrix<double> A(n, n);
  A.setFromTriplets(entries.begin(), entries.end());
  return A;
}

/// The supernodal factor of A in the order Eigen's factor f of A chose.
SupernodalLdlt supernodal(const Eigen::SparseMatrix<double>& A, const Ldlt& f) {
  SupernodalLdlt s;
  EXPECT_TRUE(s.factor(A, f.permutationP().indices()));
  return s;
}

/// Runs a parallelChunks call's chunks on the calling thread, last first.
void backwards(std::size_t count, const std::function<void(std::size_t)>& task) {
  for (std::size_t i = count; i-- > 0;) task(i);
}

TEST(SupernodalLdlt, SolvesAsEigensFactorDoesOnRandomMatricesOfAwkwardSizes) {
  for (const int n : {1, 2, 7, 64, 597})
    for (const int perRow : {1, 4, 12}) {
      const Eigen::SparseMatrix<double> A = randomSpd(n, perRow, static_cast<unsigned>(n * 31 + perRow));
      const Ldlt f(A);
      ASSERT_EQ(f.info(), Eigen::Success);
      const SupernodalLdlt s = supernodal(A, f);
      EXPECT_EQ(s.rows(), n);
      EXPECT_EQ(s.factorEntries(), static_cast<std::size_t>(f.matrixL().nestedExpression().nonZeros()))
          << "the symbolic pattern is Eigen's; " << n << " rows, " << perRow << " a row";
      if (n >= 64 && perRow >= 4)  // the factor's trailing columns fill in: runs of more than one
        EXPECT_LT(s.supernodeCount(), static_cast<std::size_t>(n)) << n << " rows, " << perRow << " a row";
      for (const unsigned seed : {3u, 4u}) {
        const Eigen::VectorXd b = randomVector(static_cast<std::size_t>(n), seed);
        Eigen::VectorXd x;
        s.solve(b, x);
        const Eigen::VectorXd expected = f.solve(b);
        EXPECT_LT((x - expected).norm(), 1e-12 * expected.norm()) << n << " rows, " << perRow << " a row";
        EXPECT_LT((A * x - b).norm(), 1e-10 * b.norm()) << n << " rows, " << perRow << " a row";
      }
    }
}

TEST(SupernodalLdlt, AFactorWithoutAPermutationSolvesToo) {
  const Eigen::SparseMatrix<double> A = randomSpd(301, 5, 9);
  const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower, Eigen::NaturalOrdering<int>> f(A);
  ASSERT_EQ(f.info(), Eigen::Success);
  SupernodalLdlt s;
  ASSERT_TRUE(s.factor(A, Eigen::VectorXi()));
  EXPECT_EQ(s.factorEntries(), static_cast<std::size_t>(f.matrixL().nestedExpression().nonZeros()));
  const Eigen::VectorXd b = randomVector(301, 2);
  Eigen::VectorXd x;
  s.solve(b, x);
  EXPECT_LT((A * x - b).norm(), 1e-10 * b.norm());
}

/// The clamped beam's rest operator (backward Euler at 1/60 s) and its free dofs.
struct BeamSystem {
  Problem p = test::clampedBeam(40);
  std::vector<Eigen::Index> free = test::freeDofsOf(p);
  AmgMatrix A0 = restOperator(restStiffness(p), p, free, 3600.0, 1.0);
};

/// The factor of A0 in nested dissection order, as WarpedCholesky makes it.
struct OrderedFactor {
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> P;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower, Eigen::NaturalOrdering<int>> ldlt;
  SupernodalLdlt solves;
  explicit OrderedFactor(const BeamSystem& b) {
    const std::vector<int> position = nestedDissection(b.A0, b.free, b.p.restPositions);
    const auto n = static_cast<Eigen::Index>(b.free.size());
    P.resize(n);
    for (Eigen::Index i = 0; i < n; ++i) P.indices()[i] = position[static_cast<std::size_t>(i)];
    Eigen::SparseMatrix<double> ordered(n, n);
    ordered = Eigen::SparseMatrix<double>(b.A0).twistedBy(P);
    ldlt.compute(ordered);
    EXPECT_TRUE(solves.factor(Eigen::SparseMatrix<double>(b.A0), P.indices()));
  }
};

TEST(NestedDissection, SplitsABeamIntoIndependentSubtreesWithAFillNearMinimumDegrees) {
  const BeamSystem b;
  const std::vector<int> position = nestedDissection(b.A0, b.free, b.p.restPositions);
  ASSERT_EQ(position.size(), b.free.size());
  std::vector<int> sorted = position;
  std::sort(sorted.begin(), sorted.end());
  for (std::size_t i = 0; i < sorted.size(); ++i) ASSERT_EQ(sorted[i], static_cast<int>(i)) << "not a permutation";
  // A node's dofs stay together, in their order.
  for (std::size_t i = 1; i < b.free.size(); ++i)
    if (b.free[i] / 3 == b.free[i - 1] / 3) EXPECT_EQ(position[i], position[i - 1] + 1) << "free dof " << i;

  const OrderedFactor f(b);
  ASSERT_EQ(f.ldlt.info(), Eigen::Success);
  const Ldlt amd{Eigen::SparseMatrix<double>(b.A0)};
  const double fill = static_cast<double>(f.ldlt.matrixL().nestedExpression().nonZeros());
  const double amdFill = static_cast<double>(amd.matrixL().nestedExpression().nonZeros());
  EXPECT_LT(fill, 1.5 * amdFill) << "nested dissection's fill against minimum degree's";
  EXPECT_EQ(f.solves.factorEntries(), static_cast<std::size_t>(fill)) << "the symbolic pattern is Eigen's";
  // The beam's cross-sections are the separators: the top of the tree, which one thread solves,
  // is a few of them (41 x 4 x 4 nodes, 48 dofs a cross-section; 40 x 4 x 4 free).
  EXPECT_GT(f.solves.topColumns(), 0u);
  EXPECT_LT(f.solves.topColumns(), b.free.size() / 8) << "the top of the tree";

  const Eigen::VectorXd r = randomVector(b.free.size(), 7);
  Eigen::VectorXd z;
  f.solves.solve(r, z);
  const Eigen::VectorXd expected = amd.solve(r);
  EXPECT_LT((z - expected).norm(), 1e-10 * expected.norm());

  EXPECT_THROW(nestedDissection(b.A0, {b.free.begin(), b.free.end() - 1}, b.p.restPositions), Error)
      << "an operator of more rows than free dofs";
  Eigen::VectorXd nan = b.p.restPositions;
  nan[b.free[5]] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(nestedDissection(b.A0, b.free, nan), Error) << "a rest position not finite";
}

TEST(SupernodalLdlt, FactorsADenseMatrixABlockDiagonalOneAndTheEmptyOne) {
  // Dense: one run of every column, no rows below, no subtree to split.
  Eigen::MatrixXd dense = Eigen::MatrixXd::Random(40, 40);
  dense = dense * dense.transpose() + 40.0 * Eigen::MatrixXd::Identity(40, 40);
  // A forest: seven independent blocks, its rows shuffled.
  std::vector<Eigen::Triplet<double>> entries;
  int forestRows = 0;
  for (int b = 0; b < 7; ++b) {  // 9, 14, 19, ... rows
    const Eigen::SparseMatrix<double> block = randomSpd(9 + 5 * b, 4, static_cast<unsigned>(40 + b));
    for (int j = 0; j < block.outerSize(); ++j)
      for (Eigen::SparseMatrix<double>::InnerIterator it(block, j); it; ++it)
        entries.emplace_back(forestRows + static_cast<int>(it.row()), forestRows + j, it.value());
    forestRows += static_cast<int>(block.rows());
  }
  Eigen::SparseMatrix<double> forest(forestRows, forestRows);
  forest.setFromTriplets(entries.begin(), entries.end());
  Eigen::VectorXi shuffled = Eigen::VectorXi::LinSpaced(forestRows, 0, forestRows - 1);
  std::shuffle(shuffled.data(), shuffled.data() + forestRows, std::mt19937(3));
  for (const auto& [A, perm, what] :
       {std::tuple{Eigen::SparseMatrix<double>(dense.sparseView()), Eigen::VectorXi(), "dense"},
        std::tuple{forest, Eigen::VectorXi(), "a forest"}, std::tuple{forest, shuffled, "a forest, shuffled"}}) {
    SupernodalLdlt s;
    ASSERT_TRUE(s.factor(A, perm)) << what;
    const Eigen::VectorXd b = randomVector(static_cast<std::size_t>(A.rows()), 8);
    Eigen::VectorXd x;
    s.solve(b, x);
    EXPECT_LT((A * x - b).norm(), 1e-12 * b.norm()) << what;
  }
  SupernodalLdlt empty;
  ASSERT_TRUE(empty.factor(Eigen::SparseMatrix<double>(0, 0), Eigen::VectorXi()));
  EXPECT_EQ(empty.rows(), 0);
  Eigen::VectorXd x = Eigen::VectorXd::Ones(2);
  empty.solve(Eigen::VectorXd(), x);
  EXPECT_EQ(x.size(), 0);
}

TEST(SupernodalLdlt, ANeverBuiltOneSolvesTheEmptySystem) {
  const SupernodalLdlt s;
  Eigen::VectorXd x = Eigen::VectorXd::Ones(3);
  s.solve(Eigen::VectorXd(), x);
  EXPECT_EQ(x.size(), 0);
  EXPECT_EQ(s.supernodeCount(), 0u);
  EXPECT_THROW(s.solve(Eigen::VectorXd::Ones(1), x), Error);
}

TEST(SupernodalLdlt, GivesTheSameBitsWhateverRunsItsTasksAndInWhateverOrder) {
  const BeamSystem b;
  const OrderedFactor f(b);
  const Eigen::VectorXd r = randomVector(b.free.size(), 11);
  Eigen::VectorXd pooled, serial;
  f.solves.solve(r, pooled);  // the library's pool (or the caller alone on one CPU)
  std::atomic<int> calls{0};
  const TaskRunnerFn runner = [&](std::size_t count, const std::function<void(std::size_t)>& task) {
    ++calls;
    backwards(count, task);
  };
  {
    const TaskScope scope(runner);
    f.solves.solve(r, serial);
  }
  EXPECT_EQ(calls.load(), 2) << "the two sweeps' tasks on the application's runner";
  ASSERT_EQ(pooled.size(), serial.size());
  EXPECT_EQ(std::memcmp(pooled.data(), serial.data(), sizeof(double) * static_cast<std::size_t>(pooled.size())), 0);
  // The factorisation's tasks too: made on the runner, last task first, it solves to the same bits.
  SupernodalLdlt backwardsMade;
  {
    const TaskScope scope(runner);
    ASSERT_TRUE(backwardsMade.factor(Eigen::SparseMatrix<double>(b.A0), f.P.indices()));
  }
  EXPECT_EQ(calls.load(), 3) << "the factorisation's tasks on the application's runner";
  backwardsMade.solve(r, serial);
  EXPECT_EQ(std::memcmp(pooled.data(), serial.data(), sizeof(double) * static_cast<std::size_t>(pooled.size())), 0)
      << "a factor made with its tasks run backwards";
}

TEST(SupernodalLdlt, InconsistentInputsAreInternalErrorsAndARefusedFactorKeepsTheOneBefore) {
  const Eigen::SparseMatrix<double> A = randomSpd(20, 3, 1);
  const Ldlt f(A);
  SupernodalLdlt s;
  const auto expectInternal = [](const std::function<void()>& call, const char* what) {
    try {
      call();
      ADD_FAILURE() << what << ": no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::Internal) << what;
      EXPECT_NE(std::string(e.what()).find("SupernodalLdlt"), std::string::npos) << e.what();
    }
  };
  expectInternal([&] { s.factor(Eigen::SparseMatrix<double>(20, 19), Eigen::VectorXi()); }, "a matrix not square");
  expectInternal([&] { s.factor(A, Eigen::VectorXi::LinSpaced(19, 0, 18)); }, "a permutation too short");
  Eigen::VectorXi twice = f.permutationP().indices();
  twice[1] = twice[0];
  expectInternal([&] { s.factor(A, twice); }, "a permutation with a repeat");
  Eigen::VectorXi outside = f.permutationP().indices();
  outside[3] = 20;
  expectInternal([&] { s.factor(A, outside); }, "a permutation out of range");

  ASSERT_TRUE(s.factor(A, f.permutationP().indices()));
  Eigen::VectorXd x;
  expectInternal([&] { s.solve(Eigen::VectorXd::Ones(21), x); }, "a right-hand side of another size");
  const Eigen::VectorXd b = randomVector(20, 3);
  const auto keepsTheOneBefore = [&](const char* what) {
    EXPECT_EQ(s.rows(), 20) << what;
    s.solve(b, x);
    EXPECT_LT((x - f.solve(b)).norm(), 1e-12 * x.norm()) << what;
  };
  expectInternal([&] { s.factor(A, twice); }, "a permutation with a repeat, after a factor");
  keepsTheOneBefore("a factor refused for its permutation");

  // Not positive definite: a negative pivot (the last, after every update), a zero one, one
  // that is not finite, and an indefinite matrix of positive diagonal.
  const auto refused = [&](Eigen::SparseMatrix<double> M, const char* what) {
    EXPECT_FALSE(s.factor(M, Eigen::VectorXi())) << what;
    keepsTheOneBefore(what);
  };
  Eigen::SparseMatrix<double> negative = randomSpd(30, 4, 2);
  negative.coeffRef(29, 29) = -negative.coeff(29, 29);
  refused(negative, "a negative pivot");
  Eigen::SparseMatrix<double> zero(3, 3);
  zero.coeffRef(0, 0) = 1.0;
  zero.coeffRef(2, 2) = 1.0;
  refused(zero, "a zero pivot");
  Eigen::SparseMatrix<double> nan = randomSpd(30, 4, 3);
  nan.coeffRef(7, 7) = std::numeric_limits<double>::quiet_NaN();
  refused(nan, "a pivot not a number");
  Eigen::SparseMatrix<double> offNan = randomSpd(30, 4, 4);
  offNan.coeffRef(12, 3) = offNan.coeffRef(3, 12) = std::numeric_limits<double>::quiet_NaN();
  refused(offNan, "an entry below the diagonal not a number");
  Eigen::SparseMatrix<double> offInf = randomSpd(30, 4, 5);
  offInf.coeffRef(20, 2) = offInf.coeffRef(2, 20) = std::numeric_limits<double>::infinity();
  refused(offInf, "an entry below the diagonal infinite");
  Eigen::SparseMatrix<double> indefinite(2, 2);
  indefinite.coeffRef(0, 0) = 1.0;
  indefinite.coeffRef(1, 1) = 1.0;
  indefinite.coeffRef(0, 1) = 2.0;
  indefinite.coeffRef(1, 0) = 2.0;
  refused(indefinite, "an indefinite matrix");
}

}  // namespace
