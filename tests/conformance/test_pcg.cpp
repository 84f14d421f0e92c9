// Conformance, PCG (device/device.hpp's building blocks, driven by solve/pcg.hpp's solvePcg and
// solveLinear, and directly): every body of the suite solved on the device and on the reference
// device, which runs the same single-reduction PCG in double. Iteration counts, residuals and
// solutions within the bounds conformance_support.hpp derives; stopped bodies, b = 0, warm starts,
// the iteration cap, the check cadence and non-finite right-hand sides.
#include "conformance/conformance_support.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <limits>
#include <set>

namespace corofem::test {
namespace {

class ConformancePcg : public ConformanceBase {
 protected:
  /// Random right-hand sides (seed + body) of every body.
  std::vector<Eigen::VectorXd> rightHandSides(unsigned seed) const {
    std::vector<Eigen::VectorXd> b(count());
    for (std::size_t i = 0; i < count(); ++i)
      b[i] = randomVector(problem(i).dofCount(), seed + static_cast<unsigned>(i));
    return b;
  }
  std::vector<Eigen::VectorXd> zeros() const {
    std::vector<Eigen::VectorXd> x(count());
    for (std::size_t i = 0; i < count(); ++i)
      x[i] = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(problem(i).dofCount()));
    return x;
  }
  std::vector<detail::SystemCoeffs> systems(const detail::BodySet& set) const {
    std::vector<detail::SystemCoeffs> c;
    for (std::size_t i : set) c.push_back(bodies()[i].solve);
    return c;
  }
  static std::vector<Eigen::VectorXd> pick(const std::vector<Eigen::VectorXd>& v, const detail::BodySet& set) {
    std::vector<Eigen::VectorXd> out;
    for (std::size_t i : set) out.push_back(v[i]);
    return out;
  }

  /// A device's solve and the reference's of one body both converged, in iteration counts within the
  /// margin of each other (in float up to `roundingSensitive` times the reference's count and the
  /// margin where that is > 0: slabInFloat). False, with a failure, where either did not converge.
  template <class Solve>
  bool convergedAlike(const Solve& got, const Solve& want, double roundingSensitive) const {
    EXPECT_TRUE(got.failure.empty()) << got.failure;
    EXPECT_TRUE(want.stats.converged) << "the reference must converge for the comparison to mean anything";
    EXPECT_TRUE(got.stats.converged);
    if (!got.failure.empty() || !want.stats.converged || !got.stats.converged) return false;
    const int k = got.stats.iterations, kRef = want.stats.iterations;
    const double margin = isDouble() ? 1.0 + kRef / 50.0 : 2.0 + kRef / 4.0;
    const double slack = roundingSensitive > 0.0 && !isDouble() ? (roundingSensitive - 1.0) * kRef : 0.0;
    EXPECT_LE(std::abs(k - kRef), slack + margin) << k << " iterations, reference " << kRef;
    return true;
  }

  /// What device d counts as made under `counter` (a failure where it keeps no such count).
  static long long madeBy(const detail::Device& d, const char* counter) {
    for (const detail::DeviceCounter& c : d.counters())
      if (c.name == counter) return c.value;
    ADD_FAILURE() << d.name() << " does not count what it made (" << counter << ")";
    return -1LL;
  }

  /// |free (b - A x)| / |free b| of body i with A from `ref`'s product, the free dofs those `fixed`
  /// does not mark (x must be 0 on the others).
  double freeResidual(detail::Device& ref, std::size_t i, const Eigen::VectorXd& b, const Eigen::VectorXd& x,
                      const std::vector<std::uint8_t>& fixed) const {
    Eigen::VectorXd y;
    ref.apply({i}, {bodies()[i].solve}, {&x}, {&y});
    double rr = 0.0, bb = 0.0;
    for (std::size_t d = 0; d < problem(i).dofCount(); ++d) {
      const Eigen::Index e = static_cast<Eigen::Index>(d);
      if (fixed[d]) {
        EXPECT_EQ(x[e], 0.0) << "constrained dof " << d;
        continue;
      }
      rr += (b[e] - y[e]) * (b[e] - y[e]);
      bb += b[e] * b[e];
    }
    return std::sqrt(rr / bb);
  }

  /// The slab (a light body held in x and y on one face, turned at random: its constraints do not
  /// turn with it, so a warped rest operator fits it poorly) solved in float with a warped
  /// preconditioner: the multigrid took 116 iterations against the double reference's 67 at the
  /// float tolerance. The warped factor took 264 to 361 against 108 or 109 over the suite's cases
  /// and the device's two node orders (151 in double, the reference 152): float's lost
  /// orthogonality over a hundred iterations of a preconditioner with outlying eigenvalues delays
  /// it most. The multiple of the reference's count the checks allow there, else 0.
  double slabInFloat(PreconditionerKind pc, std::size_t i) const {
    if (problem(i).name != "slab") return 0.0;
    return pc == PreconditionerKind::Amg ? 2.0 : pc == PreconditionerKind::WarpedCholesky ? 5.0 : 0.0;
  }

  /// Every body solved at once, from zero, on a device and on the reference with preconditioner pc.
  void everyBodyMatches(PreconditionerKind pc) {
    const SolverDesc s = solver(pc);
    if (const std::string why = refusal(s); !why.empty()) GTEST_SKIP() << GetParam().describe() << ": " << why;
    const std::vector<const detail::Problem*> problems = problemsOf(bodies());
    std::unique_ptr<detail::Device> own, ownRef;
    detail::Device* dev = &device();
    detail::Device* ref = &reference();
    if (pc != PreconditionerKind::BlockDiagonal) {  // the fixture's devices precondition with node blocks
      own = makeDevice(problems, s);
      ownRef = makeReference(problems, s);
      dev = own.get();
      ref = ownRef.get();
    }
    std::vector<detail::Device*> on = {dev, ref};
    if (ref != &reference()) on.push_back(&reference());  // expectSolveMatches's A (no preconditioner in it)
    setRandomPositionsOn(on, 100);
    setMatches(*dev, *ref, rightHandSides(200), s, "preconditioner ");
  }

  /// Every body solved at once from zero on `dev` and on `ref` with `s`, each matching (what: names
  /// the case in failures, with the preconditioner's name).
  void setMatches(detail::Device& dev, detail::Device& ref, const std::vector<Eigen::VectorXd>& b, const SolverDesc& s,
                  const std::string& what) {
    const detail::BodySet all = detail::allBodies(count());
    const SetSolve got = solveSet(dev, all, b, zeros(), s, systems(all));
    const SetSolve want = solveSet(ref, all, b, zeros(), s, systems(all));
    for (std::size_t i = 0; i < count(); ++i) {
      ASSERT_TRUE(got.solves[i].failure.empty()) << got.solves[i].failure;
      ASSERT_TRUE(want.solves[i].failure.empty()) << want.solves[i].failure;
      expectSolveMatches(i, bodies()[i].solve, b[i], got.x[i], got.solves[i].stats, want.x[i], want.solves[i].stats,
                         s.tolerance, what + toString(s.preconditioner), nullptr, slabInFloat(s.preconditioner, i));
    }
  }

  /// An application pins a node of every body after a first solve: device and reference each make
  /// a preconditioner for the new free dofs (the one before kept as a spare), with the same
  /// iterations. Then every body's scene constraints are released but the pin: made again on both
  /// (a device that kept the old one would still converge, in other counts than the reference's).
  /// `counter`: the devices' count of the preconditioners made.
  void followsChangedConstraints(PreconditionerKind pc, const char* counter) {
    const SolverDesc s = solver(pc);
    if (const std::string why = refusal(s); !why.empty()) GTEST_SKIP() << GetParam().describe() << ": " << why;
    const std::vector<const detail::Problem*> problems = problemsOf(bodies());
    std::unique_ptr<detail::Device> dev = makeDevice(problems, s), ref = makeReference(problems, s);
    setRandomPositionsOn({dev.get(), ref.get(), &reference()}, 500);
    const detail::BodySet all = detail::allBodies(count());
    solveSet(*dev, all, rightHandSides(510), zeros(), s, systems(all));  // made for the old constraints
    solveSet(*ref, all, rightHandSides(510), zeros(), s, systems(all));
    // Every body's last node pinned, on top of its scene constraints (`scene`) or alone; told to
    // the three devices.
    std::vector<std::vector<std::uint8_t>> masks(count());
    auto pinLastNode = [&](bool scene) {
      std::vector<const std::vector<std::uint8_t>*> masked;
      for (std::size_t i = 0; i < count(); ++i) {
        masks[i] = scene ? problem(i).constrained : std::vector<std::uint8_t>(problem(i).dofCount(), 0);
        const std::size_t last = problem(i).mesh.nodeCount() - 1;
        for (std::size_t k = 0; k < 3; ++k) masks[i][3 * last + k] = 1;
        masked.push_back(&masks[i]);
      }
      for (detail::Device* d : {dev.get(), ref.get(), &reference()}) d->setConstraints(all, masked);
    };
    auto made = [counter](const detail::Device& d) { return madeBy(d, counter); };
    const long long devMade = made(*dev), refMade = made(*ref);
    EXPECT_EQ(devMade, refMade);
    EXPECT_GE(devMade, static_cast<long long>(count()) - 1);  // every body with free dofs has one
    pinLastNode(true);
    const std::vector<Eigen::VectorXd> b = rightHandSides(520);
    const SetSolve got = solveSet(*dev, all, b, zeros(), s, systems(all));
    const SetSolve want = solveSet(*ref, all, b, zeros(), s, systems(all));
    for (std::size_t i = 0; i < count(); ++i) {
      ASSERT_TRUE(got.solves[i].failure.empty()) << got.solves[i].failure;
      expectSolveMatches(i, bodies()[i].solve, b[i], got.x[i], got.solves[i].stats, want.x[i], want.solves[i].stats,
                         s.tolerance, std::string(toString(pc)) + " after a pin", nullptr, slabInFloat(pc, i));
      const std::size_t last = problem(i).mesh.nodeCount() - 1;
      for (std::size_t k = 0; k < 3; ++k) EXPECT_EQ(got.x[i][static_cast<Eigen::Index>(3 * last + k)], 0.0);
    }
    // The scene's constraints released, the pin kept: bodies that had some get free dofs their
    // preconditioner lacks. (expectSolveMatches reads the suite's constraints: the checks are here.)
    EXPECT_GT(made(*dev), devMade) << "a pin and nothing made for it";
    EXPECT_EQ(made(*dev) - devMade, made(*ref) - refMade);
    const long long pinnedMade = made(*dev), pinnedRefMade = made(*ref);
    pinLastNode(false);
    const std::vector<std::vector<std::uint8_t>>& released = masks;
    // A static body held by one node is singular: the warped factor refuses it, so it is left out
    // there (the multigrid solves it, unchecked).
    detail::BodySet held;
    for (std::size_t i = 0; i < count(); ++i)
      if (bodies()[i].solve.mass != 0.0 || pc != PreconditionerKind::WarpedCholesky) held.push_back(i);
    const std::vector<Eigen::VectorXd> b2 = pick(rightHandSides(530), held);
    const SetSolve got2 = solveSet(*dev, held, b2, pick(zeros(), held), s, systems(held));
    const SetSolve want2 = solveSet(*ref, held, b2, pick(zeros(), held), s, systems(held));
    for (std::size_t j = 0; j < held.size(); ++j) {
      const std::size_t i = held[j];
      if (bodies()[i].solve.mass == 0.0) continue;  // a static body held by one node: singular
      SCOPED_TRACE(std::string(toString(pc)) + " after a release, body '" + problem(i).name + "'");
      if (!convergedAlike(got2.solves[j], want2.solves[j], slabInFloat(pc, i))) continue;
      // The true residual on the new free dofs, from the reference's product.
      EXPECT_LE(freeResidual(reference(), i, b2[j], got2.x[j], released[i]), 20.0 * s.tolerance);
    }
    EXPECT_GT(made(*dev), pinnedMade) << "freed dofs and nothing made for them";
    EXPECT_EQ(made(*dev) - pinnedMade, made(*ref) - pinnedRefMade);
    // The pin on the scene's constraints again: what was made for them is the spare, taken back
    // with nothing made, on both.
    const long long releasedMade = made(*dev), releasedRefMade = made(*ref);
    pinLastNode(true);
    const std::vector<Eigen::VectorXd> b3 = rightHandSides(540);
    const SetSolve got3 = solveSet(*dev, all, b3, zeros(), s, systems(all));
    const SetSolve want3 = solveSet(*ref, all, b3, zeros(), s, systems(all));
    EXPECT_EQ(made(*dev), releasedMade) << "the spare was not taken back";
    EXPECT_EQ(made(*ref), releasedRefMade);
    for (std::size_t i = 0; i < count(); ++i) {
      ASSERT_TRUE(got3.solves[i].failure.empty()) << got3.solves[i].failure;
      expectSolveMatches(i, bodies()[i].solve, b3[i], got3.x[i], got3.solves[i].stats, want3.x[i],
                         want3.solves[i].stats, s.tolerance, std::string(toString(pc)) + " after the pin again", nullptr,
                         slabInFloat(pc, i));
    }
  }

  /// The bodies' material made 2.5 times stiffer after a first solve, in place in the problems the
  /// devices were made from (as an application's setMaterial does): device and reference each make
  /// their preconditioners again for the new stiffness, and solve alike with them (a device that
  /// kept the old ones would still converge, in other counts than the reference's).
  void followsAMaterialChange(PreconditionerKind pc, const char* counter) {
    const SolverDesc s = solver(pc);
    if (const std::string why = refusal(s); !why.empty()) GTEST_SKIP() << GetParam().describe() << ": " << why;
    std::vector<detail::Problem> local;
    for (std::size_t i = 0; i < count(); ++i) local.push_back(problem(i));
    std::vector<const detail::Problem*> problems;
    for (const detail::Problem& p : local) problems.push_back(&p);
    std::unique_ptr<detail::Device> dev = makeDevice(problems, s), ref = makeReference(problems, s);
    setRandomPositionsOn({dev.get(), ref.get()}, 900);
    const detail::BodySet all = detail::allBodies(count());
    solveSet(*dev, all, rightHandSides(910), zeros(), s, systems(all));
    solveSet(*ref, all, rightHandSides(910), zeros(), s, systems(all));
    auto made = [counter](const detail::Device& d) { return madeBy(d, counter); };
    const long long devMade = made(*dev), refMade = made(*ref);
    for (detail::Problem& p : local) {
      p.lame.lambda *= 2.5;
      p.lame.mu *= 2.5;
    }
    for (detail::Device* d : {dev.get(), ref.get()}) d->setMaterial(all, problems);
    const std::vector<Eigen::VectorXd> b = rightHandSides(920);
    const SetSolve got = solveSet(*dev, all, b, zeros(), s, systems(all));
    const SetSolve want = solveSet(*ref, all, b, zeros(), s, systems(all));
    EXPECT_GT(made(*dev), devMade) << "a new material and nothing made for it";
    EXPECT_EQ(made(*dev) - devMade, made(*ref) - refMade);
    for (std::size_t i = 0; i < count(); ++i) {
      SCOPED_TRACE(std::string(toString(pc)) + " after a stiffer material, body '" + problem(i).name + "'");
      if (!convergedAlike(got.solves[i], want.solves[i], slabInFloat(pc, i))) continue;
      // The true residual with the new material, from the reference's product.
      EXPECT_LE(freeResidual(*ref, i, b[i], got.x[i], problem(i).constrained), 20.0 * s.tolerance);
    }
  }

  /// Each body's solution and iteration count in the set are those of its solve alone on the same
  /// device, bit for bit, while the others stop at other iterations around it.
  void givesEachBodyOfASetTheBitsItGetsAlone(PreconditionerKind pc) {
    const SolverDesc s = solver(pc);
    if (const std::string why = refusal(s); !why.empty()) GTEST_SKIP() << GetParam().describe() << ": " << why;
    std::unique_ptr<detail::Device> dev = makeDevice(problemsOf(bodies()), s);
    setRandomPositionsOn({dev.get()}, 600);
    const detail::BodySet all = detail::allBodies(count());
    const std::vector<Eigen::VectorXd> b = rightHandSides(610);
    const SetSolve together = solveSet(*dev, all, b, zeros(), s, systems(all));
    std::set<int> counts;
    for (std::size_t i = 0; i < count(); ++i) {
      SCOPED_TRACE(problem(i).name);
      const SetSolve alone = solveSet(*dev, {i}, {b[i]}, {zeros()[i]}, s, systems({i}));
      ASSERT_TRUE(together.solves[i].failure.empty()) << together.solves[i].failure;
      EXPECT_EQ(together.solves[i].stats.iterations, alone.solves[0].stats.iterations);
      EXPECT_TRUE(sameBits(together.x[i], alone.x[0])) << "max rel. difference " << maxRel(together.x[i], alone.x[0]);
      counts.insert(together.solves[i].stats.iterations);
    }
    EXPECT_GE(counts.size(), 3u) << "the bodies should stop at different iterations for the test to mean something";
  }
};

TEST_P(ConformancePcg, EveryBodyMatchesTheReferenceWithoutPreconditioner) {
  everyBodyMatches(PreconditionerKind::None);
}
TEST_P(ConformancePcg, EveryBodyMatchesTheReferenceWithTheDiagonal) {
  everyBodyMatches(PreconditionerKind::Diagonal);
}
TEST_P(ConformancePcg, EveryBodyMatchesTheReferenceWithNodeBlocks) {
  everyBodyMatches(PreconditionerKind::BlockDiagonal);
}
TEST_P(ConformancePcg, EveryBodyMatchesTheReferenceWithMultigrid) {
  everyBodyMatches(PreconditionerKind::Amg);
}

TEST_P(ConformancePcg, EveryBodyMatchesTheReferenceWithTheWarpedFactor) {
  everyBodyMatches(PreconditionerKind::WarpedCholesky);
}

TEST_P(ConformancePcg, MultigridFollowsChangedConstraints) {
  followsChangedConstraints(PreconditionerKind::Amg, "amg_hierarchies_made");
}
TEST_P(ConformancePcg, WarpedFactorFollowsChangedConstraints) {
  followsChangedConstraints(PreconditionerKind::WarpedCholesky, "warped_cholesky_factors_made");
}
TEST_P(ConformancePcg, MultigridFollowsAMaterialChange) {
  followsAMaterialChange(PreconditionerKind::Amg, "amg_hierarchies_made");
}
TEST_P(ConformancePcg, WarpedFactorFollowsAMaterialChange) {
  followsAMaterialChange(PreconditionerKind::WarpedCholesky, "warped_cholesky_factors_made");
}

// The multigrid's coarse levels of every body run together (a stopped body's rows are scratch no
// running body reads); the warped factor is applied on the host body by body between launches
// that serve them all.
TEST_P(ConformancePcg, MultigridGivesEachBodyOfASetTheBitsItGetsAlone) {
  givesEachBodyOfASetTheBitsItGetsAlone(PreconditionerKind::Amg);
}
TEST_P(ConformancePcg, WarpedFactorGivesEachBodyOfASetTheBitsItGetsAlone) {
  givesEachBodyOfASetTheBitsItGetsAlone(PreconditionerKind::WarpedCholesky);
}

TEST_P(ConformancePcg, SpringsJoinTheProductsAndTheSolves) {
  // An application's springs (spring handles: Problem::springStiffness S, A = m M + c C + s (K_t +
  // S)) on a random third of the dofs of every body with mass, from 0 to 10 times the mass term:
  // the products with the solves' coefficients and with a damping product's (s = 0: the OpenCL
  // backend folds S into its mass buffer per ratio s / m, and must unfold it) match the reference's,
  // the solves match it with every preconditioner on devices made with the springs already there
  // (a failover) and on the fixture's told of them later, and removed they leave the plain product.
  std::vector<detail::Problem> sprung;
  for (std::size_t i = 0; i < count(); ++i) {
    sprung.push_back(problem(i));
    const detail::SystemCoeffs& c = bodies()[i].solve;
    if (c.mass == 0.0) continue;  // static: run-time springs are a dynamic analysis's
    const Eigen::VectorXd u = randomVector(problem(i).dofCount(), 700 + static_cast<unsigned>(i));
    detail::Problem& p = sprung.back();
    p.springStiffness = Eigen::VectorXd::Zero(u.size());
    for (Eigen::Index d = 0; d < u.size(); ++d)
      if (u[d] > 1.0 / 3.0) p.springStiffness[d] = 15.0 * (u[d] - 1.0 / 3.0) * c.mass * p.lumpedMass[d] / c.stiffness;
  }
  std::vector<const detail::Problem*> withSprings;
  for (const detail::Problem& p : sprung) withSprings.push_back(&p);
  const detail::BodySet all = detail::allBodies(count());
  device().setSprings(all, withSprings);
  reference().setSprings(all, withSprings);
  const std::vector<Eigen::VectorXd> x = setRandomPositions(800);

  auto productsMatch = [&](const char* what) {
    for (const detail::SystemCoeffs damping : {detail::SystemCoeffs{0.0, 1.0, 0.0}, detail::SystemCoeffs{}}) {
      for (int round = 0; round < 2; ++round) {  // the solves' coefficients, then the damping's, twice over
        std::vector<Eigen::VectorXd> p(count()), y(count()), yRef(count());
        detail::ConstVectors in;
        detail::Vectors out, outRef;
        std::vector<detail::SystemCoeffs> c;
        for (std::size_t i = 0; i < count(); ++i) {
          p[i] = randomVector(problem(i).dofCount(), 810 + static_cast<unsigned>(i + 10 * round));
          in.push_back(&p[i]);
          out.push_back(&y[i]);
          outRef.push_back(&yRef[i]);
          c.push_back(round == 0 ? bodies()[i].solve : damping);
        }
        device().apply(all, c, in, out);
        reference().apply(all, c, in, outRef);
        for (std::size_t i = 0; i < count(); ++i)
          EXPECT_LE(maxRel(y[i], yRef[i]), productTolerance())
              << what << ", " << problem(i).name << ", m " << c[i].mass << ", c " << c[i].damping << ", k "
              << c[i].stiffness;
      }
    }
  };
  productsMatch("with springs");
  // Body 2's product on `dev` against a reference without springs, relative difference.
  auto fromPlain = [&](detail::Device& dev, unsigned seed) {
    const std::unique_ptr<detail::Device> plain = makeReference(problemsOf(bodies()), solver());
    detail::ConstVectors xs;
    for (const Eigen::VectorXd& v : x) xs.push_back(&v);
    plain->setPositions(all, xs);
    const Eigen::VectorXd p = randomVector(problem(2).dofCount(), seed);
    Eigen::VectorXd y, yPlain;
    dev.apply({2}, {bodies()[2].solve}, {&p}, {&y});
    plain->apply({2}, {bodies()[2].solve}, {&p}, {&yPlain});
    return maxRel(y, yPlain);
  };
  EXPECT_GT(fromPlain(reference(), 830), 0.1);  // the springs matter (else the test means nothing)

  const std::vector<Eigen::VectorXd> b = rightHandSides(840);
  for (PreconditionerKind pc : {PreconditionerKind::BlockDiagonal, PreconditionerKind::Diagonal, PreconditionerKind::Amg,
                                PreconditionerKind::WarpedCholesky}) {
    const SolverDesc s = solver(pc);
    if (const std::string why = refusal(s); !why.empty()) {
      std::printf("[info] springs, preconditioner %s: not on %s: %s\n", toString(pc), GetParam().describe().c_str(),
                  why.c_str());
      continue;
    }
    std::unique_ptr<detail::Device> own, ownRef;
    detail::Device* dev = &device();
    detail::Device* ref = &reference();
    if (pc != PreconditionerKind::BlockDiagonal) {  // made with the springs there (as a failover makes them)
      own = makeDevice(withSprings, s);
      ownRef = makeReference(withSprings, s);
      dev = own.get();
      ref = ownRef.get();
      detail::ConstVectors xs;
      for (const Eigen::VectorXd& v : x) xs.push_back(&v);
      dev->setPositions(all, xs);
      ref->setPositions(all, xs);
    }
    setMatches(*dev, *ref, b, s, "springs, preconditioner ");
  }

  // Removed: the plain products again.
  std::vector<detail::Problem> unsprung(sprung);
  std::vector<const detail::Problem*> without;
  for (detail::Problem& p : unsprung) {
    p.springStiffness.resize(0);
    without.push_back(&p);
  }
  device().setSprings(all, without);
  reference().setSprings(all, without);
  productsMatch("springs removed");
  EXPECT_LE(fromPlain(device(), 850), productTolerance());
}

TEST_P(ConformancePcg, SolveLinearOfOneBodyIsItsSolveInTheSet) {
  // solveLinear, one body at a time: the reference's answer within the bounds, and the same bits,
  // iterations and residual as the body's solve beside all the others (a body's PCG is its own:
  // its scalars, its stop test, no arithmetic shared with another body).
  setRandomPositions(300);
  const detail::BodySet all = detail::allBodies(count());
  const std::vector<Eigen::VectorXd> b = rightHandSides(310);
  const SetSolve together = solveSet(device(), all, b, zeros(), solver(), systems(all));
  for (std::size_t i = 0; i < count(); ++i) {
    const detail::SystemCoeffs c = bodies()[i].solve;
    Eigen::VectorXd x = Eigen::VectorXd::Zero(b[i].size()), xRef = x;
    const detail::LinearSolveStats st = detail::solveLinear(device(), i, c, b[i], x, solver());
    const detail::LinearSolveStats stRef = detail::solveLinear(reference(), i, c, b[i], xRef, solver());
    expectSolveMatches(i, c, b[i], x, st, xRef, stRef, solver().tolerance, "solveLinear");
    EXPECT_TRUE(sameBits(x, together.x[i])) << problem(i).name << ": max rel. difference " << maxRel(x, together.x[i]);
    EXPECT_EQ(st.iterations, together.solves[i].stats.iterations) << problem(i).name;
    EXPECT_EQ(st.relativeResidual, together.solves[i].stats.relativeResidual) << problem(i).name;
  }
}

/// What driving the blocks by hand gave: per body of the set.
struct Driven {
  std::vector<detail::PcgStart> entered;
  std::vector<int> stoppedAt;            ///< iterations when the host first saw it stopped (-1: never)
  std::vector<detail::PcgStop> stop;     ///< how it stopped
  std::vector<int> laterChanges;         ///< reads after its stop whose iteration count differed
  std::vector<Eigen::VectorXd> x;
  std::vector<detail::PcgScalars> residual;
  int reads = 0;
};

/// pcgBegin, then pcgIterate(1) twice with two reads in flight (the host's `running` one read
/// behind), pcgTake in order, until every body stopped or the cap; pcgResidual for every body that
/// ran, pcgEnd.
Driven drive(detail::Device& dev, const detail::BodySet& set, const std::vector<detail::SystemCoeffs>& c,
             const std::vector<Eigen::VectorXd>& b, const std::vector<Eigen::VectorXd>& x0, double tol, int cap) {
  const std::size_t n = set.size();
  Driven d;
  d.x = x0;
  detail::ConstVectors bs, xs;
  detail::Vectors out;
  for (std::size_t k = 0; k < n; ++k) {
    bs.push_back(&b[k]);
    xs.push_back(&x0[k]);
    out.push_back(&d.x[k]);
  }
  d.entered = dev.pcgBegin(set, c, bs, xs, tol, cap);
  d.stoppedAt.assign(n, -1);
  d.stop.assign(n, detail::PcgStop::Running);
  d.laterChanges.assign(n, 0);
  std::vector<char> running(n, 0);
  for (std::size_t k = 0; k < n; ++k) running[k] = d.entered[k] == detail::PcgStart::Running;
  std::vector<detail::PcgScalars> sc;
  auto take = [&](detail::PcgTicket t) {
    dev.pcgTake(t, sc);
    ++d.reads;
    for (std::size_t k = 0; k < n; ++k) {
      if (d.entered[k] != detail::PcgStart::Running) continue;
      if (d.stoppedAt[k] >= 0) {
        d.laterChanges[k] += sc[k].iterations != d.stoppedAt[k] || sc[k].stop != d.stop[k];
      } else if (sc[k].stop != detail::PcgStop::Running) {
        d.stoppedAt[k] = sc[k].iterations;
        d.stop[k] = sc[k].stop;
        running[k] = 0;
      }
    }
  };
  if (dev.pcgSetupReadable()) take(dev.pcgRead());
  int enqueued = 0;
  while (enqueued < cap && std::any_of(running.begin(), running.end(), [](char r) { return r != 0; })) {
    dev.pcgIterate(1, running);
    const detail::PcgTicket a = dev.pcgRead();
    ++enqueued;
    if (enqueued < cap) {
      dev.pcgIterate(1, running);  // before the first read is taken: `running` lags one read
      ++enqueued;
    }
    const detail::PcgTicket t = dev.pcgRead();
    take(a);
    take(t);
  }
  std::vector<char> ran(n, 0);
  std::vector<int> iterations(n, 0);
  for (std::size_t k = 0; k < n; ++k) {
    ran[k] = d.entered[k] == detail::PcgStart::Running;
    iterations[k] = d.stoppedAt[k] >= 0 ? d.stoppedAt[k] : cap;
  }
  dev.pcgResidual(ran);
  dev.pcgEnd(iterations, out, d.residual);
  return d;
}

TEST_P(ConformancePcg, DrivenByHandStoppedBodiesCostNothingAndKeepTheirX) {
  // The blocks driven directly, for a set of: a body whose free b is 0 (b only on its constrained
  // dofs: ZeroRhs), a body started at x0 with b = A x0 (converged at the set-up), an easy dynamic
  // body (few iterations), a hard static one (many), and a dynamic beam. Once the device stops a
  // body its scalars never change again (the iterations the others go on with cost it nothing),
  // and its x at pcgEnd is the x of its solve alone, bit for bit. Each body against the
  // reference driven the same way.
  setRandomPositions(400);
  const detail::BodySet set = {0, 2, 4, 5, 6};
  const std::size_t n = set.size();
  std::vector<Eigen::VectorXd> b(n), x0(n);
  const std::vector<detail::SystemCoeffs> c = systems(set);
  for (std::size_t k = 0; k < n; ++k) {
    const detail::Problem& p = problem(set[k]);
    b[k] = randomVector(p.dofCount(), 410 + static_cast<unsigned>(k));
    x0[k] = Eigen::VectorXd::Zero(b[k].size());
  }
  // Body 0 (single-element): b on its constrained dofs only.
  for (std::size_t d = 0; d < problem(0).dofCount(); ++d)
    if (!problem(0).constrained[d]) b[0][static_cast<Eigen::Index>(d)] = 0.0;
  ASSERT_GT(b[0].norm(), 0.0);
  // Body 4 (slab, set index 2): x0 random on the free dofs, b = A x0 from the device itself.
  x0[2] = freeOnly(problem(4), randomVector(problem(4).dofCount(), 420));
  device().apply({4}, {c[2]}, {&x0[2]}, {&b[2]});

  const int cap = solver().maxIterations;
  const double tol = solver().tolerance;
  const Driven got = drive(device(), set, c, b, x0, tol, cap);
  const Driven want = drive(reference(), set, c, b, x0, tol, cap);
  EXPECT_EQ(got.entered[0], detail::PcgStart::ZeroRhs);
  for (std::size_t k = 1; k < n; ++k) EXPECT_EQ(got.entered[k], detail::PcgStart::Running) << problem(set[k]).name;
  EXPECT_EQ(got.stoppedAt[2], 0) << "b = A x0: converged at the set-up";
  EXPECT_EQ(got.stop[2], detail::PcgStop::Converged);
  EXPECT_GT(got.stoppedAt[4], got.stoppedAt[1]) << "the static block outlasts the easy soup";

  for (std::size_t k = 1; k < n; ++k) {
    const std::size_t i = set[k];
    SCOPED_TRACE(problem(i).name);
    EXPECT_EQ(got.laterChanges[k], 0) << "its scalars changed after it stopped at " << got.stoppedAt[k];
    EXPECT_EQ(got.stop[k], detail::PcgStop::Converged);
    // Alone, through solvePcg, from the same start.
    const SetSolve alone = solveSet(device(), {i}, {b[k]}, {x0[k]}, solver(), {c[k]});
    EXPECT_TRUE(sameBits(got.x[k], alone.x[0])) << "max rel. difference " << maxRel(got.x[k], alone.x[0]);
    EXPECT_EQ(got.stoppedAt[k], alone.solves[0].stats.iterations);
    if (got.stoppedAt[k] == 0) continue;  // nothing iterated: the residual below is its start's
    detail::LinearSolveStats st, stRef;
    st.iterations = got.stoppedAt[k];
    st.converged = got.stop[k] == detail::PcgStop::Converged;
    st.relativeResidual = std::sqrt(got.residual[k].rr / got.residual[k].bb);
    stRef.iterations = want.stoppedAt[k];
    stRef.converged = want.stop[k] == detail::PcgStop::Converged;
    stRef.relativeResidual = std::sqrt(want.residual[k].rr / want.residual[k].bb);
    expectSolveMatches(i, c[k], b[k], got.x[k], st, want.x[k], stRef, tol, "driven by hand");
  }
}

TEST_P(ConformancePcg, ZeroRightHandSideConvergesAtOnceWithXZero) {
  // b = 0 (two bodies) and b zero on the free dofs only (one body), each started at x0 = 3 (not a
  // solution), beside bodies with random b started at 0: converged at once, no iteration, x = 0
  // exactly; the others as the reference.
  setRandomPositions(500);
  const detail::BodySet all = detail::allBodies(count());
  std::vector<Eigen::VectorXd> b = rightHandSides(510), start = zeros();
  for (std::size_t i : {1, 3, 5}) start[i].setConstant(3.0);
  b[1].setZero();
  b[5].setZero();
  for (std::size_t d = 0; d < problem(3).dofCount(); ++d)
    if (!problem(3).constrained[d]) b[3][static_cast<Eigen::Index>(d)] = 0.0;
  const SetSolve got = solveSet(device(), all, b, start, solver(), systems(all));
  const SetSolve want = solveSet(reference(), all, b, start, solver(), systems(all));
  for (std::size_t i = 0; i < count(); ++i) {
    SCOPED_TRACE(problem(i).name);
    ASSERT_TRUE(got.solves[i].failure.empty()) << got.solves[i].failure;
    if (i == 1 || i == 3 || i == 5) {
      EXPECT_TRUE(got.solves[i].stats.converged);
      EXPECT_EQ(got.solves[i].stats.iterations, 0);
      EXPECT_EQ(got.solves[i].stats.relativeResidual, 0.0);
      EXPECT_EQ(got.x[i].cwiseAbs().maxCoeff(), 0.0);
    } else {
      expectSolveMatches(i, bodies()[i].solve, b[i], got.x[i], got.solves[i].stats, want.x[i], want.solves[i].stats,
                         solver().tolerance, "beside b = 0");
    }
  }
  // solveLinear too.
  Eigen::VectorXd x = Eigen::VectorXd::Constant(b[5].size(), -2.0);
  const detail::LinearSolveStats st = detail::solveLinear(device(), 5, bodies()[5].solve, b[5], x, solver());
  EXPECT_TRUE(st.converged);
  EXPECT_EQ(st.iterations, 0);
  EXPECT_EQ(x.cwiseAbs().maxCoeff(), 0.0);
}

TEST_P(ConformancePcg, WarmStartsMatchTheReferenceFromTheSameStart) {
  // From x0 != 0 as a step's solve starts: the solution of the previous right-hand side (here b
  // minus a random third of it), with random entries on the constrained dofs too (taken as 0); as
  // the reference from the same x0. Then from the reference's solution: double converges within
  // the margin of the reference's count from there (0 or 1); float, whose rounding of that start
  // leaves a residual of ~eps_float |A| |x| / |b| that may exceed its tolerance, in fewer
  // iterations than from zero.
  setRandomPositions(600);
  const detail::BodySet all = detail::allBodies(count());
  const std::vector<Eigen::VectorXd> b = rightHandSides(610);
  std::vector<Eigen::VectorXd> previous(count());
  for (std::size_t i = 0; i < count(); ++i)
    previous[i] = b[i] - 0.3 * randomVector(problem(i).dofCount(), 620 + static_cast<unsigned>(i)).cwiseProduct(b[i]);
  std::vector<Eigen::VectorXd> x0 = solveSet(reference(), all, previous, zeros(), solver(), systems(all)).x;
  for (std::size_t i = 0; i < count(); ++i)
    for (std::size_t d = 0; d < problem(i).dofCount(); ++d)
      if (problem(i).constrained[d]) x0[i][static_cast<Eigen::Index>(d)] = 0.5 + 0.1 * static_cast<double>(d % 7);
  const SetSolve got = solveSet(device(), all, b, x0, solver(), systems(all));
  const SetSolve want = solveSet(reference(), all, b, x0, solver(), systems(all));
  const SetSolve cold = solveSet(device(), all, b, zeros(), solver(), systems(all));
  for (std::size_t i = 0; i < count(); ++i) {
    ASSERT_TRUE(got.solves[i].failure.empty()) << got.solves[i].failure;
    expectSolveMatches(i, bodies()[i].solve, b[i], got.x[i], got.solves[i].stats, want.x[i], want.solves[i].stats,
                       solver().tolerance, "warm start", &x0[i]);
  }
  const SetSolve again = solveSet(device(), all, b, want.x, solver(), systems(all));
  const SetSolve againRef = solveSet(reference(), all, b, want.x, solver(), systems(all));
  for (std::size_t i = 0; i < count(); ++i) {
    SCOPED_TRACE(problem(i).name);
    EXPECT_TRUE(again.solves[i].stats.converged);
    if (isDouble())
      EXPECT_LE(std::abs(again.solves[i].stats.iterations - againRef.solves[i].stats.iterations), 1)
          << again.solves[i].stats.iterations << " iterations, reference " << againRef.solves[i].stats.iterations;
    else
      EXPECT_LT(again.solves[i].stats.iterations, std::max(1, cold.solves[i].stats.iterations));
  }
}

TEST_P(ConformancePcg, TheIterationCapIsReportedNotConverged) {
  // A cap of 7 with an unreachable tolerance: every body the reference does not converge within
  // the cap stops at exactly 7, not converged, with a finite x, its true residual reported, and the
  // reference's 7th iterate: the same 7 steps of the same recurrence from the same start, whose
  // rounding (~64 u per product, amplified by at most kappa per step) stays below 7 x 64 u kappa.
  setRandomPositions(700);
  SolverDesc s = solver();
  s.maxIterations = 7;
  s.tolerance = 1e-14;
  const detail::BodySet all = detail::allBodies(count());
  const std::vector<Eigen::VectorXd> b = rightHandSides(710);
  const SetSolve got = solveSet(device(), all, b, zeros(), s, systems(all));
  const SetSolve want = solveSet(reference(), all, b, zeros(), s, systems(all));
  int capped = 0;
  for (std::size_t i = 0; i < count(); ++i) {
    const detail::Problem& p = problem(i);
    SCOPED_TRACE(p.name);
    ASSERT_TRUE(got.solves[i].failure.empty()) << got.solves[i].failure;
    const detail::LinearSolveStats& st = got.solves[i].stats;
    if (want.solves[i].stats.converged) {  // 6 free dofs: CG's exact answer in 6 iterations
      std::printf("[info] %s: the reference converges in %d iterations\n", p.name.c_str(),
                  want.solves[i].stats.iterations);
      continue;
    }
    ++capped;
    EXPECT_EQ(st.iterations, 7);
    EXPECT_FALSE(st.converged);
    EXPECT_TRUE(got.x[i].allFinite());
    const double res = trueResidual(reference(), i, bodies()[i].solve, b[i], got.x[i]);
    const Spectrum sp = spectrum(reference(), i, bodies()[i].solve);
    const double growth = sp.lambdaMax * freeOnly(p, want.x[i]).norm() / freeOnly(p, b[i]).norm();
    EXPECT_GT(st.relativeResidual, s.tolerance);
    EXPECT_NEAR(st.relativeResidual, res, 64.0 * unit() * (1.0 + growth)) << "the reported residual is the true one";
    const double bound = 7 * 64.0 * unit() * sp.kappa();
    std::printf("[info] %s: the 7th iterate against the reference's: %.2e (bound %.2e)\n", p.name.c_str(),
                relErr(got.x[i], want.x[i]), bound);
    EXPECT_LE(relErr(got.x[i], want.x[i]), bound);
  }
  EXPECT_GE(capped, static_cast<int>(count()) - 1) << "all but the single element reach the cap";
  // solveLinear reports it without throwing.
  Eigen::VectorXd x = Eigen::VectorXd::Zero(b[6].size());
  const detail::LinearSolveStats st = detail::solveLinear(device(), 6, bodies()[6].solve, b[6], x, s);
  EXPECT_EQ(st.iterations, 7);
  EXPECT_FALSE(st.converged);
  EXPECT_TRUE(sameBits(x, got.x[6]));
}

TEST_P(ConformancePcg, TheCheckCadenceChangesNeitherCountNorBits) {
  // The device tests convergence after every iteration; checkEvery only sets how often the host
  // reads: every body the same iterations and the same x, bit for bit, for any cadence.
  setRandomPositions(800);
  const detail::BodySet all = detail::allBodies(count());
  const std::vector<Eigen::VectorXd> b = rightHandSides(810);
  const SetSolve base = solveSet(device(), all, b, zeros(), solver(), systems(all));
  std::vector<Eigen::VectorXd> x(count());
  detail::ConstVectors xs;
  for (std::size_t i = 0; i < count(); ++i) {
    x[i] = randomPositions(problem(i), 800 + static_cast<unsigned>(i));
    xs.push_back(&x[i]);
  }
  for (int every : {1, 3, 1000}) {
    SolverDesc s = solver();
    s.checkEvery = every;
    std::unique_ptr<detail::Device> other = makeDevice(problemsOf(bodies()), s);
    other->setPositions(all, xs);
    const SetSolve got = solveSet(*other, all, b, zeros(), s, systems(all));
    for (std::size_t i = 0; i < count(); ++i) {
      EXPECT_EQ(got.solves[i].stats.iterations, base.solves[i].stats.iterations) << "checkEvery " << every << ", "
                                                                                  << problem(i).name;
      EXPECT_TRUE(sameBits(got.x[i], base.x[i])) << "checkEvery " << every << ", " << problem(i).name;
    }
  }
}

TEST_P(ConformancePcg, NonFiniteRightHandSideIsASolveFailureNamingTheBody) {
  // A NaN in a free dof of one body and an Inf in another's fail those two solves, each with a
  // message naming its body; a NaN in a constrained dof of a third is ignored (its row is not
  // solved); the other bodies' answers are those of the set without the failing bodies, bit for
  // bit. solveLinear throws Error(SolveFailed) naming the body.
  setRandomPositions(900);
  const detail::BodySet all = detail::allBodies(count());
  std::vector<Eigen::VectorXd> b = rightHandSides(910);
  auto firstDof = [&](std::size_t i, bool constrained) {
    for (std::size_t d = 0; d < problem(i).dofCount(); ++d)
      if ((problem(i).constrained[d] != 0) == constrained) return static_cast<Eigen::Index>(d);
    return Eigen::Index{-1};
  };
  const Eigen::Index soupDof = firstDof(2, false) + 7, slabDof = firstDof(4, false), blockDof = firstDof(6, true);
  ASSERT_GE(blockDof, 0);
  std::vector<Eigen::VectorXd> clean = b;
  b[2][soupDof] = std::numeric_limits<double>::quiet_NaN();
  b[4][slabDof] = std::numeric_limits<double>::infinity();
  b[6][blockDof] = std::numeric_limits<double>::quiet_NaN();
  clean[6][blockDof] = 0.0;
  const SetSolve got = solveSet(device(), all, b, zeros(), solver(), systems(all));
  for (std::size_t i : {std::size_t{2}, std::size_t{4}}) {
    const std::string& failure = got.solves[i].failure;
    EXPECT_NE(failure.find("body '" + problem(i).name + "'"), std::string::npos) << failure;
    EXPECT_NE(failure.find("not finite"), std::string::npos) << failure;
  }
  const detail::BodySet fine = {0, 1, 3, 5, 6};
  const SetSolve without = solveSet(device(), fine, pick(clean, fine), pick(zeros(), fine), solver(), systems(fine));
  for (std::size_t k = 0; k < fine.size(); ++k) {
    const std::size_t i = fine[k];
    EXPECT_TRUE(got.solves[i].failure.empty()) << got.solves[i].failure;
    EXPECT_TRUE(got.solves[i].stats.converged) << problem(i).name;
    EXPECT_TRUE(sameBits(got.x[i], without.x[k])) << problem(i).name;
  }
  Eigen::VectorXd x = Eigen::VectorXd::Zero(b[2].size());
  try {
    detail::solveLinear(device(), 2, bodies()[2].solve, b[2], x, solver());
    ADD_FAILURE() << "expected SolveFailed";
  } catch (const detail::Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::SolveFailed);
    EXPECT_NE(std::string(e.what()).find(problem(2).name), std::string::npos) << e.what();
  }
  // A finite b beyond float's range (3.4e38): solved (a device that keeps more precision than it
  // was asked for), or a SolveFailed naming the body; never a wrong answer.
  Eigen::VectorXd huge = clean[1];
  huge[3] = 1e39;
  Eigen::VectorXd xh = Eigen::VectorXd::Zero(huge.size()), xhRef = xh;
  try {
    const detail::LinearSolveStats st = detail::solveLinear(device(), 1, bodies()[1].solve, huge, xh, solver());
    const detail::LinearSolveStats stRef =
        detail::solveLinear(reference(), 1, bodies()[1].solve, huge, xhRef, solver());
    expectSolveMatches(1, bodies()[1].solve, huge, xh, st, xhRef, stRef, solver().tolerance, "b beyond float's range");
  } catch (const detail::Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::SolveFailed) << e.what();
    EXPECT_NE(std::string(e.what()).find(problem(1).name), std::string::npos) << e.what();
  }
}

COROFEM_CONFORMANCE_SUITE(ConformancePcg);

}  // namespace
}  // namespace corofem::test
