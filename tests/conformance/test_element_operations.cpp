// Conformance, element operations (device/device.hpp): setPositions, internalForces, apply with each
// body's own coefficients, elasticEnergy, on the whole set of the suite's bodies and on subsets,
// against the reference device. Tolerances: conformance_support.hpp (kOpDouble, kOpFloat for
// forces and energies, kProductDouble, kProductFloat for products).
#include "conformance/conformance_support.hpp"

#include <gtest/gtest.h>

#include <cstdio>

namespace corofem::test {
namespace {

class ConformanceElements : public ConformanceBase {
 protected:
  /// Mixed coefficients, one per body: Newmark-like, static, mass only, damping only, scaled.
  static detail::SystemCoeffs mixed(std::size_t i) {
    static const detail::SystemCoeffs c[] = {{14400.0, 120.0, 1.0}, {0.0, 0.0, 1.0}, {1.0, 0.0, 0.0},
                                             {900.0, 30.0, 2.0},     {0.0, 5.0, 1.0}, {250.0, 0.0, 0.5},
                                             {3600.0, 60.0, 1.0}};
    return c[i % (sizeof(c) / sizeof(c[0]))];
  }

  /// Forces, energies and products (coefficients coeffs(i), vectors p) of `set` on a device.
  struct Answers {
    std::vector<Eigen::VectorXd> f, y;
    std::vector<double> energy;
  };
  static Answers answers(detail::Device& dev, const detail::BodySet& set, const std::vector<Eigen::VectorXd>& p,
                         const std::vector<detail::SystemCoeffs>& coeffs) {
    Answers a;
    a.f.resize(set.size());
    a.y.resize(set.size());
    detail::Vectors f, y;
    detail::ConstVectors in;
    for (std::size_t k = 0; k < set.size(); ++k) {
      f.push_back(&a.f[k]);
      y.push_back(&a.y[k]);
      in.push_back(&p[k]);
    }
    dev.internalForces(set, f);
    dev.elasticEnergy(set, a.energy);
    dev.apply(set, coeffs, in, y);
    return a;
  }

  /// Every answer of `got` against the reference's `want` for the bodies `set`.
  void expectClose(const detail::BodySet& set, const Answers& got, const Answers& want, const std::string& what) {
    const double tol = opTolerance();
    ASSERT_EQ(got.energy.size(), set.size());
    for (std::size_t k = 0; k < set.size(); ++k) {
      const detail::Problem& p = problem(set[k]);
      SCOPED_TRACE(what + ", body '" + p.name + "'");
      ASSERT_EQ(got.f[k].size(), static_cast<Eigen::Index>(p.dofCount()));
      ASSERT_EQ(got.y[k].size(), static_cast<Eigen::Index>(p.dofCount()));
      std::printf("[info] %s, %s: forces %.1e, energy %.1e, product %.1e relative\n", what.c_str(), p.name.c_str(),
                  maxRel(got.f[k], want.f[k]), std::abs(got.energy[k] - want.energy[k]) / want.energy[k],
                  maxRel(got.y[k], want.y[k]));
      EXPECT_GT(want.f[k].cwiseAbs().maxCoeff(), 0.0) << "a deformed body has forces";
      EXPECT_LE(maxRel(got.f[k], want.f[k]), tol) << "forces";
      EXPECT_NEAR(got.energy[k], want.energy[k], tol * want.energy[k]) << "energy";
      EXPECT_LE(maxRel(got.y[k], want.y[k]), productTolerance()) << "product";
    }
  }
};

TEST_P(ConformanceElements, EveryBodyOfTheSetMatchesTheReference) {
  // All bodies in one call of each operation, twice: the second positions replace the first (no
  // state of the first survives: rotations, the energy, the tangent of the product).
  const detail::BodySet all = detail::allBodies(count());
  std::vector<Eigen::VectorXd> p(count());
  std::vector<detail::SystemCoeffs> coeffs(count());
  for (std::size_t i = 0; i < count(); ++i) {
    p[i] = randomVector(problem(i).dofCount(), 500 + static_cast<unsigned>(i));
    coeffs[i] = mixed(i);
  }
  for (unsigned seed : {10u, 20u}) {
    setRandomPositions(seed);
    const Answers got = answers(device(), all, p, coeffs), want = answers(reference(), all, p, coeffs);
    expectClose(all, got, want, "positions " + std::to_string(seed));
  }
  // The same bodies one call each (a set of one): the same answers as in the set, bit for bit
  // (no arithmetic mixes two bodies).
  const Answers together = answers(device(), all, p, coeffs);
  for (std::size_t i = 0; i < count(); ++i) {
    const Answers alone = answers(device(), {i}, {p[i]}, {coeffs[i]});
    EXPECT_TRUE(sameBits(alone.f[0], together.f[i])) << problem(i).name;
    EXPECT_TRUE(sameBits(alone.y[0], together.y[i])) << problem(i).name;
    EXPECT_EQ(alone.energy[0], together.energy[i]) << problem(i).name;
  }
}

TEST_P(ConformanceElements, ProductsWithEveryCoefficientMatchTheReference) {
  // Every body with every kind of coefficients (each term alone, Rayleigh damping alone, mixed),
  // one set call per kind; vectors with entries on the constrained dofs too (no projection).
  setRandomPositions(30);
  const detail::BodySet all = detail::allBodies(count());
  for (std::size_t kind = 0; kind < 7; ++kind) {
    std::vector<Eigen::VectorXd> p(count()), y(count()), yRef(count());
    detail::ConstVectors in;
    detail::Vectors out, outRef;
    for (std::size_t i = 0; i < count(); ++i) {
      p[i] = randomVector(problem(i).dofCount(), 600 + 10 * static_cast<unsigned>(kind) + static_cast<unsigned>(i));
      in.push_back(&p[i]);
      out.push_back(&y[i]);
      outRef.push_back(&yRef[i]);
    }
    const std::vector<detail::SystemCoeffs> c(count(), mixed(kind));
    device().apply(all, c, in, out);
    reference().apply(all, c, in, outRef);
    for (std::size_t i = 0; i < count(); ++i)
      EXPECT_LE(maxRel(y[i], yRef[i]), productTolerance())
          << problem(i).name << ", m " << c[i].mass << ", c " << c[i].damping << ", k " << c[i].stiffness;
  }
}

TEST_P(ConformanceElements, ASubsetLeavesTheOtherBodiesUntouched) {
  // Every body set and answered; then a subset (the first, a middle one and the largest, not
  // adjacent) moves, answers and solves; the others' next answers are those they gave before, bit
  // for bit, and the subset's match the reference at its new positions.
  setRandomPositions(40);
  const detail::BodySet all = detail::allBodies(count());
  std::vector<Eigen::VectorXd> p(count());
  std::vector<detail::SystemCoeffs> coeffs(count());
  for (std::size_t i = 0; i < count(); ++i) {
    p[i] = randomVector(problem(i).dofCount(), 700 + static_cast<unsigned>(i));
    coeffs[i] = mixed(i + 2);
  }
  const Answers before = answers(device(), all, p, coeffs);

  const detail::BodySet some = {0, 3, count() - 1};
  std::vector<Eigen::VectorXd> x, ps, b, sol;
  std::vector<detail::SystemCoeffs> cs, solveCoeffs;
  for (std::size_t i : some) {
    x.push_back(randomPositions(problem(i), 4000 + static_cast<unsigned>(i)));
    ps.push_back(p[i]);
    cs.push_back(coeffs[i]);
    b.push_back(randomVector(problem(i).dofCount(), 800 + static_cast<unsigned>(i)));
    sol.push_back(Eigen::VectorXd::Zero(b.back().size()));
    solveCoeffs.push_back(bodies()[i].solve);
  }
  detail::ConstVectors xs;
  for (const Eigen::VectorXd& v : x) xs.push_back(&v);
  device().setPositions(some, xs);
  reference().setPositions(some, xs);
  const Answers moved = answers(device(), some, ps, cs), movedRef = answers(reference(), some, ps, cs);
  expectClose(some, moved, movedRef, "the subset");
  const SetSolve solved = solveSet(device(), some, b, sol, solver(), solveCoeffs);
  for (std::size_t k = 0; k < some.size(); ++k) {
    EXPECT_TRUE(solved.solves[k].failure.empty()) << solved.solves[k].failure;
    EXPECT_TRUE(solved.solves[k].stats.converged) << problem(some[k]).name;
  }
  for (std::size_t k = 0; k < some.size(); ++k)
    EXPECT_FALSE(sameBits(moved.f[k], before.f[some[k]])) << problem(some[k]).name << " moved";

  // The others, alone and all together, answer as before.
  detail::BodySet others;
  for (std::size_t i = 0; i < count(); ++i)
    if (std::find(some.begin(), some.end(), i) == some.end()) others.push_back(i);
  std::vector<Eigen::VectorXd> po;
  std::vector<detail::SystemCoeffs> co;
  for (std::size_t i : others) {
    po.push_back(p[i]);
    co.push_back(coeffs[i]);
  }
  const Answers after = answers(device(), others, po, co);
  for (std::size_t k = 0; k < others.size(); ++k) {
    const std::size_t i = others[k];
    EXPECT_TRUE(sameBits(after.f[k], before.f[i])) << problem(i).name << ": forces";
    EXPECT_TRUE(sameBits(after.y[k], before.y[i])) << problem(i).name << ": product";
    EXPECT_EQ(after.energy[k], before.energy[i]) << problem(i).name << ": energy";
  }
  // And the whole set again: the subset at its new positions, the others at their old ones.
  const Answers again = answers(device(), all, p, coeffs), againRef = answers(reference(), all, p, coeffs);
  expectClose(all, again, againRef, "the whole set after the subset");
}

TEST_P(ConformanceElements, BeforeAnyPositionsEveryBodyIsAtRest) {
  // A device made and never given positions holds the rest shapes: no forces, no energy (to the
  // rounding of the rest positions in the device's precision, against a deformed state's scale).
  const detail::BodySet all = detail::allBodies(count());
  std::vector<Eigen::VectorXd> f(count()), fDeformed(count());
  detail::Vectors out, outDeformed;
  for (std::size_t i = 0; i < count(); ++i) {
    out.push_back(&f[i]);
    outDeformed.push_back(&fDeformed[i]);
  }
  std::vector<double> energy, deformedEnergy;
  device().internalForces(all, out);
  device().elasticEnergy(all, energy);
  setRandomPositions(50);
  reference().internalForces(all, outDeformed);
  reference().elasticEnergy(all, deformedEnergy);
  for (std::size_t i = 0; i < count(); ++i) {
    EXPECT_LE(f[i].cwiseAbs().maxCoeff(), opTolerance() * fDeformed[i].cwiseAbs().maxCoeff()) << problem(i).name;
    EXPECT_LE(std::abs(energy[i]), opTolerance() * deformedEnergy[i]) << problem(i).name;
  }
}

TEST_P(ConformanceElements, TheEnergyFollowsThePositionsAndTheMaterial) {
  // A device may keep what a pass computed for later calls (the Vulkan backend on a CPU device
  // reads the energies with the forces): the energy asked for first, after the forces, after a
  // change of material and after new positions is the reference's each time.
  const detail::BodySet all = detail::allBodies(count());
  auto expectEnergies = [&](const char* when) {
    std::vector<double> got, want;
    device().elasticEnergy(all, got);
    reference().elasticEnergy(all, want);
    ASSERT_EQ(got.size(), count());
    for (std::size_t i = 0; i < count(); ++i)
      EXPECT_NEAR(got[i], want[i], opTolerance() * std::abs(want[i])) << when << ", " << problem(i).name;
  };
  setRandomPositions(60);
  expectEnergies("asked for first");
  std::vector<Eigen::VectorXd> f(count()), g(count());
  detail::Vectors fs, gs;
  for (std::size_t i = 0; i < count(); ++i) {
    fs.push_back(&f[i]);
    gs.push_back(&g[i]);
  }
  device().internalForces(all, fs);
  reference().internalForces(all, gs);
  expectEnergies("after the forces");
  std::vector<detail::Problem> stiffer;
  for (std::size_t i = 0; i < count(); ++i) {
    stiffer.push_back(problem(i));
    stiffer.back().lame.lambda *= 2.5;
    stiffer.back().lame.mu *= 2.5;
  }
  std::vector<const detail::Problem*> ps;
  for (const detail::Problem& p : stiffer) ps.push_back(&p);
  device().setMaterial(all, ps);
  reference().setMaterial(all, ps);
  expectEnergies("after a stiffer material");
  setRandomPositions(61);
  device().internalForces(all, fs);
  reference().internalForces(all, gs);
  expectEnergies("at new positions");
}

COROFEM_CONFORMANCE_SUITE(ConformanceElements);

// The cases the suite runs, from the registry; one clear skip where there are none. Each names
// its device again when resolved by its selector.
TEST(ConformanceBackends, ListedByTheRegistry) {
  const std::vector<RegisteredBackend> backends = backendsUnderTest();
  const std::vector<ConformanceCase> cases = conformanceCases();
  std::string listed;
  for (const RegisteredBackend& b : backends)
    listed += (listed.empty() ? "" : ", ") + b.name + " (" + std::to_string(b.candidates.size()) + " devices" +
              (b.error.empty() ? "" : ": " + b.error) + ")";
  const auto entries = detail::registeredBackends();
  ASSERT_FALSE(entries.empty());
  EXPECT_EQ(entries.back().name, "reference") << "the reference backend is registered, last";
  if (cases.empty())
    GTEST_SKIP() << "no device to test: no registered backend other than the reference one lists a candidate ("
                 << (listed.empty() ? "none registered" : listed)
                 << "); the conformance suite compares nothing here (build with -DCOROFEM_WITH_OPENCL=ON and "
                    "install a GPU driver or pocl-opencl-icd)";
  // Each candidate is found again by its selector (what "<backend>:<selector>" in
  // SimulationOptions::devices, and the steps' tests, rely on).
  for (const ConformanceCase& c : cases) {
    std::printf("[info] under test: %s\n", c.describe().c_str());
    const auto entry = detail::findBackend(c.backend);
    ASSERT_TRUE(entry) << c.backend;
    ASSERT_TRUE(entry->resolve) << c.backend << " has no resolve";
    const detail::Candidate again = entry->resolve(c.selector);
    EXPECT_EQ(again.backend, c.backend);
    EXPECT_EQ(again.selector, c.selector);
    EXPECT_EQ(again.device, c.device);
  }
}

}  // namespace
}  // namespace corofem::test
