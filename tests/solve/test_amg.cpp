// The warped smoothed-aggregation multigrid (precond/amg.hpp): a symmetric positive definite
// operator, a PCG iteration count that does not grow like Jacobi's on a slender beam, the warp that
// keeps it under a rigid rotation of the body, partially constrained nodes, and the reference
// backend's "amg" preconditioner against its diagonal one.
#include "common/body_backend.hpp"
#include "common/textbook_pcg.hpp"
#include "device/body_layout.hpp"
#include "device/device_amg.hpp"
#include "model/element.hpp"
#include "precond/amg.hpp"
#include "common/clamped_beam.hpp"
#include "common/random_vector.hpp"
#include "reference/small_meshes.hpp"
#include "util/parallel.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <string>

using namespace corofem;
using namespace corofem::detail;
using corofem::test::clampedBeam;
using corofem::test::kBackwardEulerMass;
using corofem::test::freeDofsOf;
using corofem::test::randomVector;

namespace {

/// m M + W K_0 W^T on the free dofs, W = blockdiag(R) (a rigid rotation of the whole body: the
/// co-rotational tangent there), assembled here from the element functions.
AmgMatrix assembled(const Problem& p, double m, const Mat3& R) {
  const std::vector<Eigen::Index> dofs = freeDofsOf(p);
  std::vector<int> index(p.dofCount(), -1);
  for (std::size_t i = 0; i < dofs.size(); ++i) index[static_cast<std::size_t>(dofs[i])] = static_cast<int>(i);
  std::vector<Eigen::Triplet<double, int>> t;
  for (std::size_t e = 0; e < p.elements.size(); ++e) {
    const Mat12 K = rotateStiffness(linearStiffness(p.elements[e], p.lame), R);
    for (int a = 0; a < 12; ++a)
      for (int b = 0; b < 12; ++b) {
        const int r = index[3 * p.mesh.tets[4 * e + a / 3] + a % 3], c = index[3 * p.mesh.tets[4 * e + b / 3] + b % 3];
        if (r >= 0 && c >= 0) t.emplace_back(r, c, K(a, b));
      }
  }
  for (std::size_t i = 0; i < dofs.size(); ++i)
    t.emplace_back(static_cast<int>(i), static_cast<int>(i), m * p.lumpedMass[dofs[i]]);
  AmgMatrix A(static_cast<Eigen::Index>(dofs.size()), static_cast<Eigen::Index>(dofs.size()));
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

/// Textbook PCG on A x = b to a relative residual of 1e-8; returns the iterations.
int pcgIterations(const AmgMatrix& A, const Eigen::VectorXd& b, const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& M) {
  return test::textbookPcgIterations(A, b, M, 1e-8);
}

struct Fixture {
  Problem p;
  AmgMatrix A;
  Eigen::VectorXd diagInv;
  AmgMatrix blocksInverse;
  WarpedAmg amg;
  AmgFineOperator fine;
  Fixture(int cells, double m, const Mat3& R) : p(clampedBeam(cells)), A(assembled(p, m, R)) {
    diagInv = A.diagonal().cwiseInverse();
    amg.build(assembled(p, m, Mat3::Identity()), freeDofsOf(p), p.restPositions, p.mesh.nodeCount());
    fine.apply = [this](const Eigen::VectorXd& v, Eigen::VectorXd& y) { y = A * v; };
    blocksInverse = nodeBlocks(A, freeDofsOf(p)).second;
    fine.blockInverse = [this](const Eigen::VectorXd& v, Eigen::VectorXd& y) { y = blocksInverse * v; };
  }
  Eigen::VectorXd apply(const Eigen::VectorXd& r) const {
    Eigen::VectorXd z;
    amg.apply(fine, r, z);
    return z;
  }
};

TEST(WarpedAmg, IsSymmetricPositiveDefiniteWithSeveralLevels) {
  Fixture f(30, kBackwardEulerMass, Mat3::Identity());
  ASSERT_GE(f.amg.levelSizes().size(), 2u) << "a beam of " << f.A.rows() << " dofs must get a coarse level";
  EXPECT_EQ(f.amg.levelSizes().front(), f.A.rows());
  const auto n = static_cast<std::size_t>(f.A.rows());
  for (unsigned seed = 1; seed <= 3; ++seed) {
    const Eigen::VectorXd a = randomVector(n, seed), b = randomVector(n, seed + 10);
    const Eigen::VectorXd Ma = f.apply(a), Mb = f.apply(b);
    EXPECT_NEAR(a.dot(Mb), b.dot(Ma), 1e-10 * a.norm() * Mb.norm());
    EXPECT_GT(a.dot(Ma), 0.0);
    EXPECT_TRUE(Ma.allFinite());
  }
}

TEST(WarpedAmg, IterationsStayFewWhereJacobiNeedsHundredsAndDoNotGrowWithTheMesh) {
  for (double m : {kBackwardEulerMass, 0.0}) {  // dynamics and statics
    int amgIterations[2] = {0, 0};
    int k = 0;
    for (int cells : {20, 40}) {
      Fixture f(cells, m, Mat3::Identity());
      const Eigen::VectorXd b = randomVector(static_cast<std::size_t>(f.A.rows()), 7);
      const int jacobi = pcgIterations(f.A, b, [&](const Eigen::VectorXd& r) { return Eigen::VectorXd(f.diagInv.cwiseProduct(r)); });
      const int amg = pcgIterations(f.A, b, [&](const Eigen::VectorXd& r) { return f.apply(r); });
      EXPECT_LE(amg, 30) << cells << " cells, m = " << m;
      EXPECT_LT(5 * amg, jacobi) << cells << " cells, m = " << m;
      amgIterations[k++] = amg;
    }
    EXPECT_LE(amgIterations[1], amgIterations[0] + 6) << "m = " << m << ": twice the length, iterations "
                                                       << amgIterations[0] << " -> " << amgIterations[1];
  }
}

TEST(WarpedAmg, TheWarpKeepsARotatedBodyAsEasyAsAtRest) {
  std::mt19937 rng(3);
  const Mat3 R = test::randomRotation(rng);
  Fixture rest(30, 0.0, Mat3::Identity()), turned(30, 0.0, R);
  const Eigen::VectorXd b = randomVector(static_cast<std::size_t>(rest.A.rows()), 5);
  const int atRest = pcgIterations(rest.A, b, [&](const Eigen::VectorXd& r) { return rest.apply(r); });
  const int unwarped = pcgIterations(turned.A, b, [&](const Eigen::VectorXd& r) { return turned.apply(r); });
  Eigen::VectorXd x = turned.p.restPositions;
  for (std::size_t n = 0; n < turned.p.mesh.nodeCount(); ++n) x.segment<3>(3 * n) = R * x.segment<3>(3 * n);
  turned.amg.setPositions(x);
  const int warped = pcgIterations(turned.A, b, [&](const Eigen::VectorXd& r) { return turned.apply(r); });
  EXPECT_LE(warped, atRest + 3) << "at rest " << atRest << ", turned and warped " << warped;
  EXPECT_GT(unwarped, warped + 5) << "turned without the warp " << unwarped << ", with it " << warped;
}

TEST(WarpedAmg, PartlyConstrainedNodesAndTinyBodies) {
  // A node with one or two of its dofs constrained keeps its other ones in the hierarchy.
  Problem p = clampedBeam(24);
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
    if (std::abs(p.mesh.nodes[3 * n] - 1.0) < 1e-12) p.constrained[3 * n + 2] = 1;  // the tip slides in x, y
  Fixture f(24, 0.0, Mat3::Identity());
  f.p = p;
  f.A = assembled(p, 0.0, Mat3::Identity());
  f.diagInv = f.A.diagonal().cwiseInverse();
  f.blocksInverse = nodeBlocks(f.A, freeDofsOf(p)).second;
  f.amg.build(f.A, freeDofsOf(p), p.restPositions, p.mesh.nodeCount());
  const Eigen::VectorXd b = randomVector(static_cast<std::size_t>(f.A.rows()), 9);
  EXPECT_LE(pcgIterations(f.A, b, [&](const Eigen::VectorXd& r) { return f.apply(r); }), 30);

  // A body below the coarsest size: smoothing above the direct solve of its rest operator.
  Fixture tiny(2, kBackwardEulerMass, Mat3::Identity());
  EXPECT_EQ(tiny.amg.levelSizes().size(), 2u);
  EXPECT_EQ(tiny.amg.levelSizes()[0], tiny.amg.levelSizes()[1]);
  const Eigen::VectorXd bt = randomVector(static_cast<std::size_t>(tiny.A.rows()), 4);
  EXPECT_LE(pcgIterations(tiny.A, bt, [&](const Eigen::VectorXd& r) { return tiny.apply(r); }), 1);
}

TEST(WarpedAmg, TheReferenceBackendSolvesADeformedBeamInFewIterationsToTheSameAnswer) {
  Problem p = clampedBeam(40);
  // A large bend: the beam curled about y (radius 1 m, so its end turns by 1 rad), plus noise.
  Eigen::VectorXd x = p.restPositions;
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) {
    const double s = p.mesh.nodes[3 * n], radius = 1.0 - p.mesh.nodes[3 * n + 2];
    x[3 * n] = radius * std::sin(s);
    x[3 * n + 2] = 1.0 - radius * std::cos(s);
  }
  x += 1e-3 * randomVector(p.dofCount(), 11);
  const Eigen::VectorXd b = randomVector(p.dofCount(), 12);
  const SystemCoeffs c{kBackwardEulerMass, 0.0, 1.0};
  SolverDesc s;
  s.tolerance = 1e-10;
  s.maxIterations = 5000;
  Eigen::VectorXd answer[2];
  int iterations[2];
  int k = 0;
  for (PreconditionerKind pre : {PreconditionerKind::Diagonal, PreconditionerKind::Amg}) {
    s.preconditioner = pre;
    auto backend = test::createReferenceBackend(p, s);
    backend->setPositions(x);
    answer[k] = Eigen::VectorXd::Zero(b.size());
    const LinearSolveStats st = backend->solve(c, b, answer[k]);
    EXPECT_TRUE(st.converged);
    iterations[k++] = st.iterations;
  }
  EXPECT_LE(iterations[1], 40) << "diagonal " << iterations[0];
  EXPECT_LT(4 * iterations[1], iterations[0]);
  EXPECT_LT((answer[1] - answer[0]).norm(), 1e-8 * answer[0].norm());
}

TEST(WarpedAmg, ABodyKeepsItsHierarchyWithinAFactorOfTwoAndTakesBackTheOneItReplaced) {
  const Problem p = clampedBeam(20);
  const std::vector<Eigen::Index> free = freeDofsOf(p);
  BodyAmg body;
  using Made = BodyAmg::Made;
  EXPECT_EQ(body.ensure(p, free, kBackwardEulerMass, 1.0), Made::Built);
  EXPECT_EQ(body.ensure(p, free, 1.5 * kBackwardEulerMass, 1.0), Made::Kept);  // h a little shorter
  EXPECT_EQ(body.ensure(p, free, 4.0 * kBackwardEulerMass, 1.0), Made::Built);  // a substep: h / 2
  EXPECT_EQ(body.ensure(p, free, kBackwardEulerMass, 1.0), Made::Switched);     // the next full step
  EXPECT_EQ(body.ensure(p, free, 4.0 * kBackwardEulerMass, 1.0), Made::Switched);
  EXPECT_EQ(body.ensure(p, free, 0.0, 1.0), Made::Built);  // statics
  body.clear();
  EXPECT_EQ(body.ensure(p, free, 0.0, 1.0), Made::Built);
  EXPECT_FALSE(body.amg().levelSizes().empty());
}

TEST(WarpedAmg, AGrabMakesAHierarchyAndTheReleaseTakesBackTheOneBefore) {
  // The beam's hierarchy made for its clamp; an application grabs the tip (its nodes constrained):
  // one is made for the new free dofs (keeping the clamp's restricted to them was tried: twice the
  // PCG iterations, bench_precond's precondGrab at 0db57de), and the clamp's stays as the spare, so
  // that the release takes it back with no set-up, and grabbing again takes back the grab's.
  const Problem p = clampedBeam(30);
  const std::vector<Eigen::Index> before = freeDofsOf(p);
  Problem grabbed = p;
  for (std::size_t n = 0; n < grabbed.mesh.nodeCount(); ++n)
    if (grabbed.mesh.nodes[3 * n] > 1.0 - 1e-12)
      for (int c = 0; c < 3; ++c) grabbed.constrained[3 * n + c] = 1;
  const std::vector<Eigen::Index> after = freeDofsOf(grabbed);
  ASSERT_LT(after.size(), before.size());
  BodyAmg body;
  using Made = BodyAmg::Made;
  ASSERT_EQ(body.ensure(p, before, kBackwardEulerMass, 1.0), Made::Built);
  EXPECT_EQ(body.ensure(grabbed, after, kBackwardEulerMass, 1.0), Made::Built);
  EXPECT_EQ(body.amg().builtFreeDofs(), after);
  EXPECT_EQ(body.ensure(p, before, kBackwardEulerMass, 1.0), Made::Switched);  // released
  EXPECT_EQ(body.amg().builtFreeDofs(), before);
  EXPECT_EQ(body.ensure(grabbed, after, kBackwardEulerMass, 1.0), Made::Switched);  // grabbed again
  EXPECT_EQ(body.builds(), 2);
  // The clamp released as well: free dofs neither hierarchy has.
  Problem loose = grabbed;
  for (std::size_t n = 0; n < loose.mesh.nodeCount(); ++n)
    if (loose.mesh.nodes[3 * n] < 1e-12)
      for (int c = 0; c < 3; ++c) loose.constrained[3 * n + c] = 0;
  EXPECT_EQ(body.ensure(loose, freeDofsOf(loose), kBackwardEulerMass, 1.0), Made::Built);
  EXPECT_EQ(body.amg().builtFreeDofs(), freeDofsOf(loose));
  EXPECT_EQ(body.builds(), 3);
}

/// The largest eigenvalue of B^-1 A (dense; B symmetric positive definite).
double largestEigenvalue(const AmgMatrix& A, const AmgMatrix& B) {
  const Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> es(Eigen::MatrixXd(A), Eigen::MatrixXd(B),
                                                                     Eigen::EigenvaluesOnly);
  return es.eigenvalues().maxCoeff();
}

TEST(WarpedAmg, AGrabsHierarchyTakesTheBoundsOfTheOneForMoreDofsAndTheyHoldThere) {
  // A grab's hierarchy (fewer free dofs, the same time step) takes level 0's two spectral bounds
  // from the clamp's instead of 40 power steps (BodyAmg::ensure). They must bound the grabbed
  // operator's spectra (interlacing: its Rayleigh quotients are some of the clamp's), stay near what
  // a fresh estimate gives, and leave PCG's iterations where a fresh hierarchy has them. A ratio
  // below the one the bounds were made at (the bounds may not hold) and free dofs the clamp's
  // hierarchy lacks (a release of the clamp) estimate afresh: the bits of a body that never had
  // the clamp's.
  const Problem p = clampedBeam(12);
  Problem grabbed = p;
  for (std::size_t n = 0; n < grabbed.mesh.nodeCount(); ++n)
    if (grabbed.mesh.nodes[3 * n] > 1.0 - 1e-12)
      for (int c = 0; c < 3; ++c) grabbed.constrained[3 * n + c] = 1;
  const std::vector<Eigen::Index> before = freeDofsOf(p), after = freeDofsOf(grabbed);
  ASSERT_LT(after.size(), before.size());
  const double m = kBackwardEulerMass;
  using Made = BodyAmg::Made;

  BodyAmg body;
  ASSERT_EQ(body.ensure(p, before, m, 1.0), Made::Built);
  const WarpedAmg::Bounds clamp = body.amg().bounds();
  // The same ratio with its last bits changed, as a step's h comes back.
  ASSERT_EQ(body.ensure(grabbed, after, m * (1.0 + 4e-16), 1.0), Made::Built);
  const WarpedAmg::Bounds taken = body.amg().bounds();
  EXPECT_EQ(taken.fine, clamp.fine);
  EXPECT_EQ(taken.level0, clamp.level0);
  EXPECT_EQ(body.amg().levels().at(0).lambdaMax, clamp.level0);

  // They hold for the grabbed operators: level 0's Chebyshev bound against the node blocks of the
  // operator with half the mass (the window of ratios served), the prolongator's against the diagonal.
  const AmgMatrix K0 = restStiffness(grabbed);
  const AmgMatrix half = restOperator(K0, grabbed, after, 0.5 * m, 1.0), A0 = restOperator(K0, grabbed, after, m, 1.0);
  const double fineTrue = largestEigenvalue(half, nodeBlocks(half, after).first);
  AmgMatrix D(A0.rows(), A0.cols());
  D.setIdentity();
  D.diagonal() = A0.diagonal();
  const double level0True = largestEigenvalue(A0, D);
  EXPECT_LE(fineTrue, taken.fine);
  EXPECT_LE(level0True, taken.level0);

  // Near a fresh estimate, and PCG's iterations with either hierarchy alike.
  BodyAmg fresh;
  ASSERT_EQ(fresh.ensure(grabbed, after, m, 1.0), Made::Built);
  const WarpedAmg::Bounds own = fresh.amg().bounds();
  EXPECT_NEAR(taken.fine, own.fine, 0.05 * own.fine);
  EXPECT_NEAR(taken.level0, own.level0, 0.05 * own.level0);
  AmgFineOperator fine;
  fine.apply = [&](const Eigen::VectorXd& v, Eigen::VectorXd& y) { y = A0 * v; };
  const AmgMatrix blocksInverse = nodeBlocks(A0, after).second;
  fine.blockInverse = [&](const Eigen::VectorXd& v, Eigen::VectorXd& y) { y = blocksInverse * v; };
  auto iterations = [&](const WarpedAmg& amg) {
    return pcgIterations(A0, randomVector(after.size(), 5), [&](const Eigen::VectorXd& r) {
      Eigen::VectorXd z;
      amg.apply(fine, r, z);
      return z;
    });
  };
  const int withTaken = iterations(body.amg()), withOwn = iterations(fresh.amg());
  EXPECT_LE(withTaken, withOwn + 1);
  EXPECT_LE(withTaken, 30);

  // The same ratio with its last bits changed downwards: taken too.
  BodyAmg below;
  ASSERT_EQ(below.ensure(p, before, m, 1.0), Made::Built);
  ASSERT_EQ(below.ensure(grabbed, after, m * (1.0 - 4e-16), 1.0), Made::Built);
  EXPECT_EQ(below.amg().bounds().fine, clamp.fine);

  // A smaller ratio (h longer) than the clamp's, where the bounds may not hold, and one 2.5 times
  // it (beyond the hierarchy's window, where they would be loose): estimated afresh, the bits of a
  // fresh body.
  for (double ratio : {0.9 * m, 2.5 * m}) {
    BodyAmg other, otherFresh;
    ASSERT_EQ(other.ensure(p, before, m, 1.0), Made::Built);
    ASSERT_EQ(other.ensure(grabbed, after, ratio, 1.0), Made::Built);
    ASSERT_EQ(otherFresh.ensure(grabbed, after, ratio, 1.0), Made::Built);
    EXPECT_EQ(other.amg().bounds().fine, otherFresh.amg().bounds().fine) << ratio;
    EXPECT_EQ(other.amg().bounds().level0, otherFresh.amg().bounds().level0) << ratio;
    EXPECT_NE(other.amg().bounds().fine, clamp.fine) << ratio;
  }

  // One dof of a node pinned (a node block shrinks to 2 x 2: still a principal submatrix): taken,
  // and it holds.
  Problem pinned = p;
  std::size_t tip = 0;
  for (std::size_t n = 0; n < pinned.mesh.nodeCount(); ++n)
    if (pinned.mesh.nodes[3 * n] > pinned.mesh.nodes[3 * tip]) tip = n;
  pinned.constrained[3 * tip + 1] = 1;
  const std::vector<Eigen::Index> one = freeDofsOf(pinned);
  ASSERT_EQ(one.size() + 1, before.size());
  BodyAmg pin;
  ASSERT_EQ(pin.ensure(p, before, m, 1.0), Made::Built);
  ASSERT_EQ(pin.ensure(pinned, one, m, 1.0), Made::Built);
  EXPECT_EQ(pin.amg().bounds().fine, clamp.fine);
  const AmgMatrix halfPinned = restOperator(K0, pinned, one, 0.5 * m, 1.0);
  EXPECT_LE(largestEigenvalue(halfPinned, nodeBlocks(halfPinned, one).first), clamp.fine);

  // The clamp released too: dofs the clamp's hierarchy does not have.
  Problem loose = grabbed;
  for (std::size_t n = 0; n < loose.mesh.nodeCount(); ++n)
    if (loose.mesh.nodes[3 * n] < 1e-12)
      for (int c = 0; c < 3; ++c) loose.constrained[3 * n + c] = 0;
  BodyAmg looseFresh;
  ASSERT_EQ(body.ensure(loose, freeDofsOf(loose), m, 1.0), Made::Built);
  ASSERT_EQ(looseFresh.ensure(loose, freeDofsOf(loose), m, 1.0), Made::Built);
  EXPECT_EQ(body.amg().bounds().fine, looseFresh.amg().bounds().fine);
  EXPECT_EQ(body.amg().bounds().level0, looseFresh.amg().bounds().level0);
}

/// m M + s K_0 assembled element by element, as the set-up once did: the yardstick of the operator
/// restricted from the kept K_0.
AmgMatrix assembledRestOperator(const Problem& p, const std::vector<Eigen::Index>& free, double m, double s) {
  std::vector<int> index(p.dofCount(), -1);
  for (std::size_t i = 0; i < free.size(); ++i) index[static_cast<std::size_t>(free[i])] = static_cast<int>(i);
  std::vector<Eigen::Triplet<double, int>> t;
  for (std::size_t e = 0; e < p.elements.size(); ++e) {
    const Mat12 K = linearStiffness(p.elements[e], p.lame);
    for (int a = 0; a < 12; ++a)
      for (int b = 0; b < 12; ++b) {
        const int r = index[3 * p.mesh.tets[4 * e + a / 3] + a % 3], c = index[3 * p.mesh.tets[4 * e + b / 3] + b % 3];
        if (r >= 0 && c >= 0) t.emplace_back(r, c, s * K(a, b));
      }
  }
  for (std::size_t i = 0; i < free.size(); ++i)
    t.emplace_back(static_cast<int>(i), static_cast<int>(i), m * p.lumpedMass[static_cast<std::size_t>(free[i])]);
  AmgMatrix A(static_cast<Eigen::Index>(free.size()), static_cast<Eigen::Index>(free.size()));
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

double relativeDifference(const AmgMatrix& a, const AmgMatrix& b) {
  return AmgMatrix(a - b).norm() / b.norm();
}

TEST(WarpedAmg, TheStiffnessAssembledInPlaceIsTheOneTripletsGive) {
  // The same pattern (every pair of nodes sharing an element, every diagonal) and the same sums in
  // the same order: equal entries, on a mesh whose node numbering is scrambled.
  TetMesh mesh = test::boxMesh(5, 3, 2, 0.5, 0.3, 0.2);
  std::vector<std::uint32_t> to(mesh.nodeCount());
  for (std::size_t n = 0; n < to.size(); ++n) to[n] = static_cast<std::uint32_t>(n);
  std::mt19937 rng(17);
  std::shuffle(to.begin(), to.end(), rng);
  std::vector<double> nodes(mesh.nodes.size());
  for (std::size_t n = 0; n < to.size(); ++n)
    for (int c = 0; c < 3; ++c) nodes[3 * to[n] + static_cast<std::size_t>(c)] = mesh.nodes[3 * n + static_cast<std::size_t>(c)];
  mesh.nodes = nodes;
  for (std::uint32_t& v : mesh.tets) v = to[v];
  for (double c : {0.9, 0.8, 0.7}) mesh.nodes.push_back(c);  // a node in no element: its diagonal alone
  Problem p = test::makeProblem(mesh, 2e5, 0.3, 900.0);
  std::vector<Eigen::Triplet<double, int>> t;
  for (std::size_t e = 0; e < p.elements.size(); ++e) {
    const Mat12 K = linearStiffness(p.elements[e], p.lame);
    for (int a = 0; a < 12; ++a)
      for (int b = 0; b < 12; ++b)
        t.emplace_back(static_cast<int>(3 * p.mesh.tets[4 * e + a / 3] + a % 3),
                       static_cast<int>(3 * p.mesh.tets[4 * e + b / 3] + b % 3), K(a, b));
  }
  for (std::size_t d = 0; d < p.dofCount(); ++d) t.emplace_back(static_cast<int>(d), static_cast<int>(d), 0.0);
  AmgMatrix expected(static_cast<Eigen::Index>(p.dofCount()), static_cast<Eigen::Index>(p.dofCount()));
  expected.setFromTriplets(t.begin(), t.end());
  const AmgMatrix K = restStiffness(p);
  ASSERT_EQ(K.nonZeros(), expected.nonZeros());
  for (Eigen::Index r = 0; r < K.rows(); ++r) {
    ASSERT_EQ(K.outerIndexPtr()[r + 1], expected.outerIndexPtr()[r + 1]) << "row " << r;
    for (int k = K.outerIndexPtr()[r]; k < K.outerIndexPtr()[r + 1]; ++k) {
      ASSERT_EQ(K.innerIndexPtr()[k], expected.innerIndexPtr()[k]) << "row " << r;
      ASSERT_EQ(K.valuePtr()[k], expected.valuePtr()[k]) << "row " << r << ", column " << K.innerIndexPtr()[k];
      ASSERT_EQ(std::signbit(K.valuePtr()[k]) || K.valuePtr()[k] != 0.0,
                std::signbit(expected.valuePtr()[k]) || expected.valuePtr()[k] != 0.0)
          << "row " << r << ": a zero of another sign";
    }
  }
}

TEST(WarpedAmg, TheRestOperatorRestrictedFromTheKeptStiffnessIsTheAssembledOne) {
  Problem p = clampedBeam(12);
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)  // a few more constrained dofs, single components too
    if (n % 7 == 3) p.constrained[3 * n + n % 3] = 1;
  const std::vector<Eigen::Index> free = freeDofsOf(p);
  const AmgMatrix K = restStiffness(p);
  for (const double m : {0.0, kBackwardEulerMass, 3.7e4}) {
    const AmgMatrix restricted = restOperator(K, p, free, m, 0.8), assembled = assembledRestOperator(p, free, m, 0.8);
    ASSERT_EQ(restricted.rows(), assembled.rows());
    EXPECT_LT(relativeDifference(restricted, assembled), 1e-14) << "m = " << m;
    EXPECT_TRUE(restricted.isCompressed());
  }
}

TEST(WarpedAmg, AChangedMaterialOrMeshGivesTheHierarchyTheNewStiffness) {
  // BodyAmg keeps K_0 across set-ups (a grab restricts it); a material change (setMaterial clears
  // the hierarchy) or another body's problem must not find the old one.
  Problem p = clampedBeam(12);
  const std::vector<Eigen::Index> free = freeDofsOf(p);
  BodyAmg body;
  ASSERT_EQ(body.ensure(p, free, kBackwardEulerMass, 1.0), BodyAmg::Made::Built);
  EXPECT_LT(relativeDifference(body.amg().levels()[0].A, assembledRestOperator(p, free, kBackwardEulerMass, 1.0)), 1e-14);
  p.lame = lameFromYoungPoisson(3e6, 0.35);
  body.clear();
  ASSERT_EQ(body.ensure(p, free, kBackwardEulerMass, 1.0), BodyAmg::Made::Built);
  EXPECT_LT(relativeDifference(body.amg().levels()[0].A, assembledRestOperator(p, free, kBackwardEulerMass, 1.0)), 1e-14)
      << "the set-up used the stiffness of the old material";
  const Problem other = clampedBeam(12);  // the same mesh, the first material, another object
  body.clear();
  ASSERT_EQ(body.ensure(other, free, kBackwardEulerMass, 1.0), BodyAmg::Made::Built);
  EXPECT_LT(relativeDifference(body.amg().levels()[0].A, assembledRestOperator(other, free, kBackwardEulerMass, 1.0)),
            1e-14);
  // Another mesh of as many nodes, the same material: twice as long, so other element gradients.
  Problem longer = test::makeProblem(test::boxMesh(12, 3, 3, 2.0, 0.1, 0.1, 0.0, 6), 1e6, 0.3, 1000.0);
  longer.constrained = other.constrained;
  body.clear();
  ASSERT_EQ(body.ensure(longer, free, kBackwardEulerMass, 1.0), BodyAmg::Made::Built);
  EXPECT_LT(relativeDifference(body.amg().levels()[0].A, assembledRestOperator(longer, free, kBackwardEulerMass, 1.0)),
            1e-14)
      << "the set-up used the stiffness of the shorter mesh";
}

TEST(WarpedAmg, TheRestOperatorRefusesFreeDofsOutOfOrder) {
  const Problem p = clampedBeam(4);
  std::vector<Eigen::Index> free = freeDofsOf(p);
  std::swap(free[3], free[4]);
  EXPECT_THROW(restOperator(restStiffness(p), p, free, 1.0, 1.0), Error);
}

}  // namespace

namespace {

/// Whether `pt` holds exactly the entries of `p` transposed (any size, empty included).
bool isTransposeOf(const AmgMatrix& pt, const AmgMatrix& p) {
  const AmgMatrix t = p.transpose();
  if (pt.rows() != t.rows() || pt.cols() != t.cols() || pt.nonZeros() != t.nonZeros()) return false;
  for (Eigen::Index r = 0; r < t.rows(); ++r)
    for (AmgMatrix::InnerIterator a(pt, r), b(t, r);; ++a, ++b) {
      if (!a || !b) {
        if (a || b) return false;
        break;
      }
      if (a.col() != b.col() || a.value() != b.value()) return false;
    }
  return true;
}

/// What every entry of a device matrix should be: body s's matrix m at rows row(s, i), columns
/// col(s, j), and nothing else.
template <class Row, class Col>
void expectJoined(const AmgMatrix& device, const std::vector<const AmgMatrix*>& parts, const Row& row, const Col& col,
                  const char* what) {
  SCOPED_TRACE(what);
  ASSERT_TRUE(device.isCompressed());
  Eigen::Index entries = 0;
  for (std::size_t s = 0; s < parts.size(); ++s) {
    if (!parts[s]) continue;
    entries += parts[s]->nonZeros();
    for (Eigen::Index i = 0; i < parts[s]->rows(); ++i)
      for (AmgMatrix::InnerIterator it(*parts[s], i); it; ++it)
        ASSERT_EQ(device.coeff(static_cast<Eigen::Index>(row(s, i)), static_cast<Eigen::Index>(col(s, it.col()))),
                  it.value())
            << "body " << s << " entry (" << i << ", " << it.col() << ")";
  }
  EXPECT_EQ(device.nonZeros(), entries);
  for (Eigen::Index r = 0; r < device.outerSize(); ++r)  // each row's columns ascend
    for (int k = device.outerIndexPtr()[r] + 1; k < device.outerIndexPtr()[r + 1]; ++k)
      ASSERT_LT(device.innerIndexPtr()[k - 1], device.innerIndexPtr()[k]) << "row " << r;
}

}  // namespace

TEST(DeviceAmg, TheLevelsLaidEndToEndHoldEveryBodysEntriesInTheDevicesNumbering) {
  // Two bodies of different depths, both in a Morton numbering (level 0's rows permuted), one with
  // extra constrained dofs: every body's P_0, P_0^T, coarse operators, prolongators and coarsest
  // inverse where the device finds them, nothing more; in the plain layout (a body's coarse rows
  // end to end) and the blocked one (each coarse vertex in 6 rows, its own first).
  Problem a = clampedBeam(160), b = clampedBeam(8);
  for (std::size_t n = 0; n < b.mesh.nodeCount(); ++n)
    if (n % 5 == 2) b.constrained[3 * n + 1] = 1;
  const BodyLayout layout({&a, &b}, 1, 64, 64, 12);
  DeviceAmg amg(layout.segments);
  ASSERT_TRUE(amg.prepare({0, 1}, {{kBackwardEulerMass, 1.0}, {kBackwardEulerMass, 1.0}}));
  const WarpedAmg* hierarchy[2] = {&amg.body(0).amg(), &amg.body(1).amg()};
  ASSERT_GE(hierarchy[0]->levels().size(), 3u);
  bool partialVertex = false;  // the blocked layout pads some vertex (an aggregate with fewer than 6 modes)
  for (std::size_t s = 0; s < 2; ++s)
    for (std::size_t k = 1; k < hierarchy[s]->levels().size(); ++k) {
      const std::vector<int>& vs = hierarchy[s]->levels()[k].vertexStart;
      ASSERT_EQ(vs.back(), hierarchy[s]->levels()[k].A.rows()) << "body " << s << ", level " << k;
      for (std::size_t v = 0; v + 1 < vs.size(); ++v) partialVertex |= vs[v + 1] - vs[v] < 6;
    }
  EXPECT_TRUE(partialVertex) << "no padded vertex: the blocked layout's padding goes untested";
  // Level 0 rows: the free dof i of body s at its device dof.
  std::vector<std::vector<std::size_t>> fine(2);
  for (std::size_t s = 0; s < 2; ++s) {
    const BodySegment& sg = layout.segments[s];
    std::vector<std::size_t> deviceDof(sg.dofs());
    for (std::size_t d = 0; d < sg.dofs(); ++d) deviceDof[sg.hostDof(d)] = d;
    for (Eigen::Index dof : hierarchy[s]->builtFreeDofs())
      fine[s].push_back(sg.dofBegin() + deviceDof[static_cast<std::size_t>(dof)]);
  }
  for (const std::size_t block : {std::size_t{0}, std::size_t{6}}) {
    SCOPED_TRACE("block " + std::to_string(block));
    const DeviceAmgLayout L = amg.layout(layout.nodeTotal, block);
    EXPECT_EQ(L.block, block);
    ASSERT_EQ(L.levels.size() + 1, std::max(hierarchy[0]->levels().size(), hierarchy[1]->levels().size()));
    // The rows body s takes on level k, and where its row i lies there: body 0's rows first.
    auto taken = [&](std::size_t s, std::size_t k) -> std::size_t {
      if (hierarchy[s]->levels().size() <= k) return 0;
      const AmgLevel& level = hierarchy[s]->levels()[k];
      return block == 0 ? static_cast<std::size_t>(level.A.rows()) : block * (level.vertexStart.size() - 1);
    };
    auto coarseRow = [&](std::size_t k) {
      return [&, k](std::size_t s, Eigen::Index i) {
        const std::size_t first = s == 0 ? 0 : taken(0, k);
        if (block == 0) return first + static_cast<std::size_t>(i);
        const std::vector<int>& vs = hierarchy[s]->levels()[k].vertexStart;
        const std::size_t v = static_cast<std::size_t>(std::upper_bound(vs.begin(), vs.end(), int(i)) - vs.begin() - 1);
        return first + block * v + static_cast<std::size_t>(i - vs[v]);
      };
    };
    auto atFine = [&](std::size_t s, Eigen::Index i) { return fine[s][static_cast<std::size_t>(i)]; };
    expectJoined(L.P0, {&hierarchy[0]->levels()[0].P, &hierarchy[1]->levels()[0].P}, atFine, coarseRow(1), "P0");
    EXPECT_TRUE(isTransposeOf(L.Pt0, L.P0)) << "Pt0 is not P0^T";
    for (std::size_t k = 1; k <= L.levels.size(); ++k) {
      const auto here = coarseRow(k), below = coarseRow(k + 1);
      std::vector<const AmgMatrix*> A(2, nullptr), P(2, nullptr);
      std::vector<Eigen::MatrixXd> inverse(2);
      for (std::size_t s = 0; s < 2; ++s) {
        const auto& levels = hierarchy[s]->levels();
        if (k + 1 < levels.size()) {
          A[s] = &levels[k].A;
          P[s] = &levels[k].P;
        } else if (k + 1 == levels.size()) {
          inverse[s] = hierarchy[s]->coarsestInverse();
        }
      }
      const DeviceAmgLevel& level = L.levels[k - 1];
      ASSERT_EQ(level.rows, taken(0, k) + taken(1, k)) << "level " << k;
      ASSERT_EQ(level.dinv.size(), level.rows);
      // The smoother's 1 / (A_ii lambda_max); 0 on a coarsest body's rows and on padding rows.
      std::vector<double> dinv(level.rows, 0.0);
      for (std::size_t s = 0; s < 2; ++s)
        for (Eigen::Index i = 0; A[s] && i < A[s]->rows(); ++i)
          dinv[here(s, i)] = hierarchy[s]->levels()[k].diagInv[i] / hierarchy[s]->levels()[k].lambdaMax;
      for (std::size_t r = 0; r < level.rows; ++r) ASSERT_EQ(level.dinv[r], dinv[r]) << "level " << k << ", row " << r;
      EXPECT_EQ(level.smooths, A[0] != nullptr || A[1] != nullptr) << "level " << k;
      expectJoined(level.A, A, here, here, "A_k");
      expectJoined(level.P, P, here, below, "P_k");
      EXPECT_TRUE(isTransposeOf(level.Pt, level.P)) << "level " << k;
      std::size_t dense = 0;
      for (std::size_t s = 0; s < 2; ++s) {
        if (inverse[s].size() == 0) continue;
        dense += static_cast<std::size_t>(inverse[s].size());
        for (Eigen::Index i = 0; i < inverse[s].rows(); ++i)
          for (Eigen::Index j = 0; j < inverse[s].cols(); ++j)
            ASSERT_EQ(level.inverse.coeff(static_cast<Eigen::Index>(here(s, i)), static_cast<Eigen::Index>(here(s, j))),
                      inverse[s](i, j));
      }
      EXPECT_EQ(level.inverseEntries, dense) << "level " << k;
    }
  }
}

TEST(DeviceAmg, BlockRowsHoldEveryEntryInItsBlockAndTheProductIsTheMatrixs) {
  // A random matrix of 3 x 6 blocks (some empty, some partly filled) as BlockRows: each entry at
  // its block and place, zeros elsewhere, the padding after the last block, and the product by
  // blocks equal to the matrix's; sizes that are not whole blocks refused.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Index rows = 3 * 40, cols = 6 * 25;
  std::vector<Eigen::Triplet<double, int>> t;
  for (Eigen::Index i = 0; i < rows; ++i)
    for (Eigen::Index j = 0; j < cols; ++j)
      if (rng() % 9 == 0) t.emplace_back(int(i), int(j), u(rng));
  AmgMatrix m(rows, cols);
  m.setFromTriplets(t.begin(), t.end());
  const BlockRows b = blockRows(m, 3, 6, 8);
  ASSERT_EQ(b.blockRows, 40u);
  ASSERT_EQ(b.start.size(), 41u);
  ASSERT_EQ(b.values.size(), 18 * b.cols.size() + 8);
  for (std::size_t k = 18 * b.cols.size(); k < b.values.size(); ++k) EXPECT_EQ(b.values[k], 0.0);
  const Eigen::MatrixXd dense = Eigen::MatrixXd(m);
  const Eigen::VectorXd x = randomVector(static_cast<std::size_t>(cols), 8);
  Eigen::VectorXd y = Eigen::VectorXd::Zero(rows);
  std::size_t blocksHeld = 0;
  for (std::size_t i = 0; i < b.blockRows; ++i) {
    for (std::uint32_t j = b.start[i]; j < b.start[i + 1]; ++j) {
      if (j > b.start[i]) {
        ASSERT_LT(b.cols[j - 1], b.cols[j]) << "block row " << i;
      }
      const Eigen::MatrixXd part = dense.block(3 * Eigen::Index(i), 6 * Eigen::Index(b.cols[j]), 3, 6);
      EXPECT_NE(part.cwiseAbs().maxCoeff(), 0.0) << "an empty block kept in block row " << i;
      for (int c = 0; c < 6; ++c)
        for (int r = 0; r < 3; ++r) {
          ASSERT_EQ(b.values[18 * j + 3 * std::size_t(c) + std::size_t(r)], part(r, c)) << "block row " << i;
          y[3 * Eigen::Index(i) + r] += part(r, c) * x[6 * Eigen::Index(b.cols[j]) + c];
        }
    }
    blocksHeld += b.start[i + 1] - b.start[i];
  }
  std::size_t blocksThere = 0;  // every non-empty block is held
  for (Eigen::Index i = 0; i < rows / 3; ++i)
    for (Eigen::Index j = 0; j < cols / 6; ++j) blocksThere += dense.block(3 * i, 6 * j, 3, 6).cwiseAbs().maxCoeff() > 0.0;
  EXPECT_EQ(blocksHeld, blocksThere);
  EXPECT_LT((y - m * x).norm(), 1e-13 * (m * x).norm());
  EXPECT_THROW(blockRows(m, 7, 6, 0), Error);  // 120 rows are not whole blocks of 7,
  EXPECT_THROW(blockRows(m, 3, 4, 0), Error);  // nor 150 columns of 4
  EXPECT_THROW(blockRows(m, 0, 6, 0), Error);
}

TEST(WarpedAmg, TheMatrixVectorProductInSlicesIsEigensBitForBit) {
  // K_0 of four slices of rows times a random vector, the slices run last first: Eigen's bits.
  const Problem p = clampedBeam(150);
  const AmgMatrix K = restStiffness(p);
  ASSERT_GT(static_cast<std::size_t>(K.rows()), 2 * kProductRows);
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd x(K.cols());
  for (Eigen::Index i = 0; i < x.size(); ++i) x[i] = u(rng) * std::pow(10.0, static_cast<int>(rng() % 9) - 4);
  const Eigen::VectorXd whole = K * x;
  const TaskRunnerFn backwards = [](std::size_t count, const std::function<void(std::size_t)>& task) {
    for (std::size_t i = count; i-- > 0;) task(i);
  };
  const TaskScope scope(backwards);
  const Eigen::VectorXd sliced = amgProduct(K, x);
  ASSERT_EQ(sliced.size(), whole.size());
  for (Eigen::Index i = 0; i < whole.size(); ++i) ASSERT_EQ(sliced[i], whole[i]) << "row " << i;
}

TEST(WarpedAmg, TheProductInSlicesOfRowsIsEigensProductBitForBit) {
  // A K_0 of more rows than a slice times a random sparse matrix: the same pattern and the same
  // bits as the whole product, whatever the host's threads did with the slices.
  const Problem p = clampedBeam(150);
  const AmgMatrix K = restStiffness(p);
  ASSERT_GT(static_cast<std::size_t>(K.rows()), 2 * kProductRows);  // 7,248 rows: four slices, the last short
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Eigen::Triplet<double, int>> t;
  for (int r = 0; r < K.cols(); ++r)
    for (int k = 0; k < 5; ++k) t.emplace_back(r, static_cast<int>(rng() % 700), u(rng));
  AmgMatrix B(K.cols(), 700);
  B.setFromTriplets(t.begin(), t.end());
  const AmgMatrix whole = K * B, sliced = sparseProduct(K, B);
  ASSERT_EQ(sliced.rows(), whole.rows());
  ASSERT_EQ(sliced.cols(), whole.cols());
  ASSERT_EQ(sliced.nonZeros(), whole.nonZeros());
  for (Eigen::Index r = 0; r <= whole.rows(); ++r) ASSERT_EQ(sliced.outerIndexPtr()[r], whole.outerIndexPtr()[r]);
  for (Eigen::Index k = 0; k < whole.nonZeros(); ++k) {
    ASSERT_EQ(sliced.innerIndexPtr()[k], whole.innerIndexPtr()[k]) << "entry " << k;
    ASSERT_EQ(sliced.valuePtr()[k], whole.valuePtr()[k]) << "entry " << k;
  }
}
