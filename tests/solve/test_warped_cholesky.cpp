// The warped precomputed Cholesky (precond/warped_cholesky.hpp): the exact inverse of a body turned
// rigidly (so that the warp is seen to work), few iterations where Jacobi needs hundreds on a
// curled beam and the same answer, partly constrained nodes, a factor kept within a factor of two
// of its time step and taken back after a grab, and a clear error for a body nothing holds.
#include "common/body_backend.hpp"
#include "model/element.hpp"
#include "precond/warped_cholesky.hpp"
#include "common/clamped_beam.hpp"
#include "common/random_vector.hpp"
#include "reference/small_meshes.hpp"
#include "util/error.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>

using namespace corofem;
using namespace corofem::detail;
using corofem::test::clampedBeam;
using corofem::test::kBackwardEulerMass;
using corofem::test::freeDofsOf;
using corofem::test::randomVector;

namespace {

/// The beam curled about y so that its end (x = 1) turns by `turn` rad, plus noise.
Eigen::VectorXd curled(const Problem& p, double turn, unsigned seed) {
  Eigen::VectorXd x = p.restPositions;
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) {
    const double s = p.mesh.nodes[3 * n] * turn, radius = 1.0 / turn - p.mesh.nodes[3 * n + 2];
    x[3 * n] = radius * std::sin(s);
    x[3 * n + 2] = 1.0 / turn - radius * std::cos(s);
  }
  return x + 1e-4 * randomVector(p.dofCount(), seed);
}

/// One linear solve of A x = b from zero on the reference backend with the preconditioner `pre` at
/// the body's positions `x`.
LinearSolveStats solve(const Problem& p, PreconditionerKind pre, const Eigen::VectorXd& x, const SystemCoeffs& c,
                       const Eigen::VectorXd& b, Eigen::VectorXd& answer, double tolerance = 1e-10) {
  SolverDesc s;
  s.preconditioner = pre;
  s.tolerance = tolerance;
  s.maxIterations = 5000;
  auto backend = test::createReferenceBackend(p, s);
  backend->setPositions(x);
  answer = Eigen::VectorXd::Zero(b.size());
  return backend->solve(c, b, answer);
}

TEST(WarpedCholesky, ABodyTurnedRigidlyIsSolvedInOneIteration) {
  // Every element turned by one rotation Q: A_t = W A_0 W^T with W = blockdiag(Q) exactly (the
  // mass lumped), so the warped factor is A_t's inverse and PCG stops after one iteration. Without
  // the warp (the factor at rest alone) or with a wrong one, it takes many.
  // With Rayleigh damping (m + c alpha) M + (s + c beta) K_t: the factor's ratio includes both.
  Problem p = clampedBeam(12);
  p.rayleighMass = 2.0;
  p.rayleighStiffness = 0.05;
  std::mt19937 rng(5);
  const Mat3 Q = test::randomRotation(rng);
  Eigen::VectorXd x = p.restPositions;
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) x.segment<3>(3 * n) = Q * x.segment<3>(3 * n);
  const Eigen::VectorXd b = randomVector(p.dofCount(), 6);
  for (const SystemCoeffs& c : {SystemCoeffs{kBackwardEulerMass, 0.0, 1.0}, SystemCoeffs{0.0, 0.0, 1.0},
                                SystemCoeffs{kBackwardEulerMass, 60.0, 1.0}}) {
    Eigen::VectorXd warped, diagonal;
    const LinearSolveStats sw = solve(p, PreconditionerKind::WarpedCholesky, x, c, b, warped);
    const LinearSolveStats sd = solve(p, PreconditionerKind::Diagonal, x, c, b, diagonal);
    EXPECT_TRUE(sw.converged && sd.converged);
    EXPECT_LE(sw.iterations, 1) << "m = " << c.mass;
    EXPECT_GT(sd.iterations, 30) << "m = " << c.mass;
    EXPECT_LT((warped - diagonal).norm(), 1e-8 * diagonal.norm());
  }

  // The factor applied directly: W A_0^-1 W^T r is A_t^-1 r, and the factor at rest alone is not.
  BodyCholesky body;
  const std::vector<Eigen::Index> free = freeDofsOf(p);
  body.ensure(p, free, kBackwardEulerMass, 1.0);
  auto backend = test::createReferenceBackend(p, SolverDesc{});
  backend->setPositions(x);
  const Eigen::VectorXd r = randomVector(free.size(), 8);
  auto residual = [&](const Eigen::VectorXd& z) {  // |A_t z - r| / |r| on the free dofs
    Eigen::VectorXd full = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(p.dofCount())), y;
    for (std::size_t i = 0; i < free.size(); ++i) full[free[i]] = z[static_cast<Eigen::Index>(i)];
    backend->apply(SystemCoeffs{kBackwardEulerMass, 0.0, 1.0}, full, y);
    Eigen::VectorXd yf(r.size());
    for (std::size_t i = 0; i < free.size(); ++i) yf[static_cast<Eigen::Index>(i)] = y[free[i]];
    return (yf - r).norm() / r.norm();
  };
  Eigen::VectorXd z;
  body.cholesky().apply(r, z);
  EXPECT_GT(residual(z), 1e-2) << "the factor at rest alone is not the turned body's inverse";
  body.cholesky().setNodeRotations(std::vector<Mat3>(p.mesh.nodeCount(), Q));
  body.cholesky().apply(r, z);
  EXPECT_LT(residual(z), 1e-10);
  body.cholesky().setNodeRotations(nodeRotations(p.mesh, std::vector<Mat3>(p.elements.size(), Q)));
  body.cholesky().apply(r, z);
  EXPECT_LT(residual(z), 1e-10) << "the node rotations of elements turned alike";
}

TEST(WarpedCholesky, ACurledBeamTakesFewIterationsWhereJacobiTakesHundredsToTheSameAnswer) {
  for (Formulation f : {Formulation::Corotational, Formulation::StVenantKirchhoff}) {
    const Problem p = clampedBeam(40, f);
    const Eigen::VectorXd x = curled(p, f == Formulation::Corotational ? 1.0 : 0.1, 11);
    const Eigen::VectorXd b = randomVector(p.dofCount(), 12);
    const SystemCoeffs c{kBackwardEulerMass, 0.0, 1.0};
    Eigen::VectorXd warped, diagonal;
    const LinearSolveStats sw = solve(p, PreconditionerKind::WarpedCholesky, x, c, b, warped);
    const LinearSolveStats sd = solve(p, PreconditionerKind::Diagonal, x, c, b, diagonal);
    EXPECT_TRUE(sw.converged && sd.converged) << toString(f) << ": " << sw.iterations << " and " << sd.iterations;
    EXPECT_LE(sw.iterations, 25) << toString(f) << ": diagonal " << sd.iterations;
    EXPECT_LT(8 * sw.iterations, sd.iterations) << toString(f);
    EXPECT_LT((warped - diagonal).norm(), 1e-8 * diagonal.norm()) << toString(f);
  }
  // The linear formulation has no warp: its tangent is K_0, and the factor its system's inverse.
  const Problem p = clampedBeam(20, Formulation::Linear);
  Eigen::VectorXd answer;
  const LinearSolveStats s = solve(p, PreconditionerKind::WarpedCholesky, curled(p, 1.0, 3),
                                   SystemCoeffs{kBackwardEulerMass, 0.0, 1.0}, randomVector(p.dofCount(), 4), answer);
  EXPECT_TRUE(s.converged);
  EXPECT_LE(s.iterations, 1);
}

TEST(WarpedCholesky, PartlyConstrainedNodesKeepTheirFreeDofs) {
  // Slip conditions: the tip slides in x and y (z constrained), or in x alone (y and z
  // constrained). A node's free dofs are warped by the nearest orthogonal matrix to their block of
  // its rotation; the block itself, at a quarter turn about y with only x free, is zero, and the
  // preconditioner would be singular (PCG stopped short of the answer).
  for (int constrainedDofs : {1, 2}) {
    Problem p = clampedBeam(24);
    for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
      if (std::abs(p.mesh.nodes[3 * n] - 1.0) < 1e-12)
        for (int c = 3 - constrainedDofs; c < 3; ++c) p.constrained[3 * n + c] = 1;
    for (double turn : {0.5, 0.5 * 3.14159265358979}) {
      const Eigen::VectorXd x = curled(p, turn, 13), b = randomVector(p.dofCount(), 14);
      const SystemCoeffs c{kBackwardEulerMass, 0.0, 1.0};
      Eigen::VectorXd warped, diagonal;
      const LinearSolveStats sw = solve(p, PreconditionerKind::WarpedCholesky, x, c, b, warped);
      const LinearSolveStats sd = solve(p, PreconditionerKind::Diagonal, x, c, b, diagonal);
      EXPECT_TRUE(sw.converged && sd.converged) << constrainedDofs << " constrained, turn " << turn;
      // A quarter turn: 37-43 iterations here (the raw blocks of R took 121-136).
      EXPECT_LE(sw.iterations, turn > 1.0 ? 60 : 30) << constrainedDofs << " constrained, turn " << turn << ": diagonal " << sd.iterations;
      EXPECT_LT((warped - diagonal).norm(), 1e-8 * diagonal.norm()) << constrainedDofs << " constrained, turn " << turn;
    }
  }
}

TEST(WarpedCholesky, AGrabThroughTheDeviceMakesAFactorAndTheReleaseTakesBackTheOneBefore) {
  const Problem p = clampedBeam(20);
  SolverDesc s;
  s.preconditioner = PreconditionerKind::WarpedCholesky;
  s.tolerance = 1e-10;
  auto warped = test::createReferenceBackend(p, s);
  s.preconditioner = PreconditionerKind::Diagonal;
  s.maxIterations = 5000;
  auto diagonal = test::createReferenceBackend(p, s);
  const Eigen::VectorXd x = curled(p, 0.4, 21), b = randomVector(p.dofCount(), 22);
  std::vector<std::uint8_t> grabbed = p.constrained;
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
    if (p.mesh.nodes[3 * n] > 1.0 - 1e-12)
      for (int c = 0; c < 3; ++c) grabbed[3 * n + c] = 1;
  auto factors = [&] {
    for (const DeviceCounter& c : warped->device().counters())
      if (c.name == "warped_cholesky_factors_made") return c.value;
    ADD_FAILURE() << "no counter warped_cholesky_factors_made";
    return -1LL;
  };
  int k = 0;
  for (const std::vector<std::uint8_t>* mask : std::vector<const std::vector<std::uint8_t>*>{&p.constrained, &grabbed, &p.constrained}) {
    for (auto* backend : {warped.get(), diagonal.get()}) {
      backend->device().setConstraints({0}, {mask});
      backend->setPositions(x);
    }
    Eigen::VectorXd xw = Eigen::VectorXd::Zero(b.size()), xd = xw;
    const LinearSolveStats sw = warped->solve(SystemCoeffs{kBackwardEulerMass, 0.0, 1.0}, b, xw);
    const LinearSolveStats sd = diagonal->solve(SystemCoeffs{kBackwardEulerMass, 0.0, 1.0}, b, xd);
    EXPECT_TRUE(sw.converged && sd.converged) << "solve " << k;
    EXPECT_LE(sw.iterations, 25) << "solve " << k;
    EXPECT_LT((xw - xd).norm(), 1e-8 * xd.norm()) << "solve " << k;
    EXPECT_EQ(factors(), k == 0 ? 1 : 2) << "solve " << k;  // the release: the spare, no factor
    ++k;
  }
}

TEST(WarpedCholesky, ABodyKeepsItsFactorWithinAFactorOfTwoAndTakesBackTheOneItReplaced) {
  const Problem p = clampedBeam(10);
  const std::vector<Eigen::Index> free = freeDofsOf(p);
  BodyCholesky body;
  EXPECT_EQ(body.ensure(p, free, kBackwardEulerMass, 1.0), Made::Built);
  EXPECT_GT(body.cholesky().factorEntries(), 0);
  EXPECT_EQ(body.ensure(p, free, 1.5 * kBackwardEulerMass, 1.0), Made::Kept);  // h a little shorter
  EXPECT_EQ(body.ensure(p, free, 4.0 * kBackwardEulerMass, 1.0), Made::Built);  // a substep: h / 2
  EXPECT_EQ(body.ensure(p, free, kBackwardEulerMass, 1.0), Made::Switched);     // the next full step
  // A grab: other free dofs, one factor; its release takes back the one before.
  Problem grabbed = p;
  for (std::size_t n = 0; n < grabbed.mesh.nodeCount(); ++n)
    if (grabbed.mesh.nodes[3 * n] > 1.0 - 1e-12)
      for (int c = 0; c < 3; ++c) grabbed.constrained[3 * n + c] = 1;
  EXPECT_EQ(body.ensure(grabbed, freeDofsOf(grabbed), kBackwardEulerMass, 1.0), Made::Built);
  EXPECT_EQ(body.cholesky().builtFreeDofs(), freeDofsOf(grabbed));
  EXPECT_EQ(body.ensure(p, free, kBackwardEulerMass, 1.0), Made::Switched);
  EXPECT_EQ(body.builds(), 3);
  body.clear();  // a material change
  EXPECT_EQ(body.ensure(p, free, kBackwardEulerMass, 1.0), Made::Built);
}

TEST(WarpedCholesky, AMaterialChangeReachesTheFactor) {
  // The reference backend's setMaterial clears the factor; with the old one kept, a stiffened body
  // would need many iterations where the new factor gives one (the linear formulation: exact).
  Problem p = clampedBeam(16, Formulation::Linear);
  SolverDesc s;
  s.preconditioner = PreconditionerKind::WarpedCholesky;
  s.tolerance = 1e-10;
  auto backend = test::createReferenceBackend(p, s);
  backend->setPositions(p.restPositions);
  const Eigen::VectorXd b = randomVector(p.dofCount(), 15);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(b.size());
  EXPECT_LE(backend->solve(SystemCoeffs{100.0, 0.0, 1.0}, b, x).iterations, 1);
  p.lame = lameFromYoungPoisson(5e7, 0.3);
  backend->device().setMaterial({0}, {&p});
  x.setZero();
  EXPECT_LE(backend->solve(SystemCoeffs{100.0, 0.0, 1.0}, b, x).iterations, 1);
  bool counted = false;
  for (const DeviceCounter& c : backend->device().counters())
    if (c.name == "warped_cholesky_factors_made") {
      EXPECT_EQ(c.value, 2);
      counted = true;
    }
  EXPECT_TRUE(counted) << "the reference backend counts its factorisations";
}

TEST(WarpedCholesky, StaticsOfABodyNothingHoldsFailsWithTheFix) {
  // Rounding leaves the pivots of a free body's rigid motions about 1e-11 of the largest, of
  // either sign: the rigid motions themselves are tested, on three meshes (in statics A_0 = K_0,
  // whose Rayleigh quotients do not depend on E), free and held at one node.
  auto refused = [](const Problem& p, const std::string& what) {
    Eigen::VectorXd answer;
    try {
      solve(p, PreconditionerKind::WarpedCholesky, p.restPositions, SystemCoeffs{0.0, 0.0, 1.0},
            randomVector(p.dofCount(), 16), answer);
      ADD_FAILURE() << what << ": a singular rest system was factored";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::SolveFailed) << what;
      const std::string message = e.what();
      EXPECT_NE(message.find("\"warped_cholesky\""), std::string::npos) << message;
      EXPECT_NE(message.find("Hold the body with \"fixed\" nodes"), std::string::npos) << message;
    }
  };
  for (int cells : {4, 12, 20}) {
    Problem p = test::makeProblem(test::boxMesh(cells, 3, 3, 1.0, 0.1, 0.1, 0.0, 6), 1e6, 0.3, 1000.0);
    refused(p, "free, " + std::to_string(cells) + " cells");
    // With mass (dynamics) the free body factors and is solved at once (no rigid rotation: W = I).
    Eigen::VectorXd answer;
    LinearSolveStats s = solve(p, PreconditionerKind::WarpedCholesky, p.restPositions,
                               SystemCoeffs{kBackwardEulerMass, 0.0, 1.0}, randomVector(p.dofCount(), 17), answer);
    EXPECT_TRUE(s.converged);
    EXPECT_LE(s.iterations, 1);
    // Held at one node: it can still turn about it.
    p.constrained[0] = p.constrained[1] = p.constrained[2] = 1;
    refused(p, "one node fixed, " + std::to_string(cells) + " cells");
  }
}

TEST(WarpedCholesky, LongHeldBodiesAndStiffFreeOnesInDynamicsAreNotRefused) {
  // Held bodies are not refused, however long (the smallest rigid quotient falls as the length
  // cubed: 8.3e-12 here, a threshold of 1e-9 refused this beam), and neither is a free body in
  // dynamics whose mass is tiny against its stiffness (steel-stiff, 1.6e-9).
  const Problem longBeam = [] {
    Problem p = test::makeProblem(test::boxMesh(3000, 1, 1, 30.0, 0.01, 0.01, 0.0, 6), 1e6, 0.3, 1000.0);
    for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
      if (p.mesh.nodes[3 * n] < 1e-12)
        for (int c = 0; c < 3; ++c) p.constrained[3 * n + c] = 1;
    return p;
  }();
  BodyCholesky held;
  EXPECT_NO_THROW(held.ensure(longBeam, freeDofsOf(longBeam), 0.0, 1.0));
  const Problem steel = test::makeProblem(test::boxMesh(60, 3, 3, 1.0, 0.1, 0.1, 0.0, 6), 2e11, 0.3, 1000.0);
  BodyCholesky stiff;
  EXPECT_NO_THROW(stiff.ensure(steel, freeDofsOf(steel), kBackwardEulerMass, 1.0));
  const Problem clamped = clampedBeam(20);
  Eigen::VectorXd answer;
  EXPECT_TRUE(solve(clamped, PreconditionerKind::WarpedCholesky, clamped.restPositions, SystemCoeffs{0.0, 0.0, 1.0},
                    randomVector(clamped.dofCount(), 18), answer)
                  .converged);
}

TEST(WarpedCholesky, ABodyWithEveryDofConstrainedHasNothingToSolve) {
  Problem p = clampedBeam(3);
  std::fill(p.constrained.begin(), p.constrained.end(), std::uint8_t{1});
  Eigen::VectorXd answer;
  const LinearSolveStats s = solve(p, PreconditionerKind::WarpedCholesky, p.restPositions,
                                   SystemCoeffs{kBackwardEulerMass, 0.0, 1.0}, randomVector(p.dofCount(), 19), answer);
  EXPECT_TRUE(s.converged);
  EXPECT_TRUE(answer.isZero(0.0));
  BodyCholesky body;
  EXPECT_EQ(body.ensure(p, {}, kBackwardEulerMass, 1.0), Made::Built);
  body.cholesky().setNodeRotations(std::vector<Mat3>(p.mesh.nodeCount(), Mat3::Identity()));
  Eigen::VectorXd z;
  body.cholesky().apply(Eigen::VectorXd(), z);
  EXPECT_EQ(z.size(), 0);
}

TEST(WarpedCholesky, ARestSystemThatIsNotPositiveDefiniteFailsWithTheFix) {
  // A mechanism the rigid motions do not show: one coupling made larger than its two dofs'
  // stiffness allows (the 2 x 2 minor indefinite). The two dofs are the x of two free nodes at the
  // same y and z, which every rigid motion moves alike (v_i = v_j), so a positive coupling adds
  // 2 c v_i^2 >= 0 to each rigid motion's energy and the rigid-motion check passes: the
  // factorisation must meet the pivot that is not positive.
  const Problem p = clampedBeam(4);
  const std::vector<Eigen::Index> free = freeDofsOf(p);
  AmgMatrix A0 = restOperator(restStiffness(p), p, free, kBackwardEulerMass, 1.0);
  Eigen::Index i = -1, j = -1;
  const Eigen::VectorXd& X = p.restPositions;
  for (std::size_t a = 0; a < free.size() && j < 0; ++a) {
    if (free[a] % 3 != 0) continue;
    for (std::size_t b = a + 1; b < free.size() && j < 0; ++b)
      if (free[b] % 3 == 0 && X[free[b]] != X[free[a]] && X[free[b] + 1] == X[free[a] + 1] &&
          X[free[b] + 2] == X[free[a] + 2]) {
        i = static_cast<Eigen::Index>(a);
        j = static_cast<Eigen::Index>(b);
      }
  }
  ASSERT_GE(j, 0) << "no two free nodes at the same y and z";
  const double coupling = 3.0 * std::sqrt(A0.coeff(i, i) * A0.coeff(j, j));
  A0.coeffRef(i, j) = coupling;
  A0.coeffRef(j, i) = coupling;
  WarpedCholesky w;
  try {
    w.build(A0, free, p.restPositions, "indefinite");
    ADD_FAILURE() << "an indefinite rest system was factored";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::SolveFailed);
    const std::string message = e.what();
    EXPECT_NE(message.find("body 'indefinite'"), std::string::npos) << message;
    EXPECT_NE(message.find("\"warped_cholesky\""), std::string::npos) << message;
  }
  EXPECT_FALSE(w.built());
}

TEST(WarpedCholesky, InconsistentSizesAreInternalErrors) {
  const Problem p = clampedBeam(4);
  const std::vector<Eigen::Index> free = freeDofsOf(p);
  WarpedCholesky w;
  const AmgMatrix A0 = restOperator(restStiffness(p), p, free, 1.0, 1.0);
  EXPECT_THROW(w.build(A0, {free.begin(), free.end() - 1}, p.restPositions, p.name), Error);
  w.build(A0, free, p.restPositions, p.name);
  EXPECT_THROW(w.setNodeRotations(std::vector<Mat3>(3, Mat3::Identity())), Error);
  Eigen::VectorXd z;
  EXPECT_THROW(w.apply(Eigen::VectorXd::Ones(5), z), Error);
  EXPECT_THROW(nodeRotations(p.mesh, {}), Error);
}

}  // namespace

namespace {

TEST(WarpedCholesky, BodiesSolvedTogetherGetTheBitsEachGetsAlone) {
  // Two bodies of one device (a batch: one solve of both) each with its own factor and warp: the
  // same bits as each on a device of its own.
  const Problem a = clampedBeam(16), b = clampedBeam(10);
  const Eigen::VectorXd xa = curled(a, 0.6, 31), xb = curled(b, 0.2, 32);
  const Eigen::VectorXd ba = randomVector(a.dofCount(), 33), bb = randomVector(b.dofCount(), 34);
  SolverDesc s;
  s.preconditioner = PreconditionerKind::WarpedCholesky;
  s.tolerance = 1e-9;
  const std::vector<SystemCoeffs> coeffs = {{kBackwardEulerMass, 0.0, 1.0}, {0.5 * kBackwardEulerMass, 0.0, 1.0}};
  auto both = createReferenceDevice({&a, &b}, s);
  both->setPositions({0, 1}, {&xa, &xb});
  std::vector<PcgSolve> solves(2);
  Eigen::VectorXd ua = Eigen::VectorXd::Zero(ba.size()), ub = Eigen::VectorXd::Zero(bb.size());
  solves[0] = PcgSolve{coeffs[0], &ba, &ua, {}, {}};
  solves[1] = PcgSolve{coeffs[1], &bb, &ub, {}, {}};
  solvePcg(*both, {0, 1}, solves, s);
  for (int i = 0; i < 2; ++i) {
    const Problem& p = i == 0 ? a : b;
    const Eigen::VectorXd& x = i == 0 ? xa : xb;
    const Eigen::VectorXd& rhs = i == 0 ? ba : bb;
    auto alone = test::createReferenceBackend(p, s);
    alone->setPositions(x);
    Eigen::VectorXd u = Eigen::VectorXd::Zero(rhs.size());
    const LinearSolveStats st = alone->solve(coeffs[static_cast<std::size_t>(i)], rhs, u);
    EXPECT_TRUE(st.converged && solves[static_cast<std::size_t>(i)].stats.converged) << "body " << i;
    EXPECT_EQ(st.iterations, solves[static_cast<std::size_t>(i)].stats.iterations) << "body " << i;
    EXPECT_EQ(0, std::memcmp(u.data(), (i == 0 ? ua : ub).data(), sizeof(double) * static_cast<std::size_t>(u.size())))
        << "body " << i;
  }
}

}  // namespace
