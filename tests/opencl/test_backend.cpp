// The OpenCL backend's own behaviour against the reference backend (createReferenceBackend:
// assembled Eigen, double) on the same Problem: the energy the forces' pass sums, the kernel
// configurations, the preconditioner formed at the solve's positions, warm starts without an
// upload, the product queued behind the forces, host chunks, the locality order, denormals, a body
// far from the origin and the adopted-context path. The comparisons every backend must pass
// (forces, products, energy, PCG against the reference, determinism, warm starts, b = 0, the cap,
// the check cadence, non-finite right-hand sides) are tests/conformance/, run for every device of
// every registered backend.
//
// Tolerances. Double: PCG to a relative residual of 1e-10 versus the reference's direct solve;
// the error is bounded by cond(A) * 1e-10 with cond(A) ~1e2 for these small, mass-dominated
// systems (and well below the worst case for the static one): 1e-8 relative; forces/products agree
// to rounding (1e-10 relative). Float: the achievable relative residual is ~ eps_float * cond(A)
// ~ 1e-5..1e-4; we ask PCG for 1e-5 and accept a true residual (recomputed in double by the
// reference) of 1e-3, the solution to 1e-3 and forces/products to 1e-4 relative (positions
// rounded to float; see test_kernels.cpp).
#include "backends/opencl/opencl_backend.hpp"
#include "common/body_backend.hpp"
#include "common/shuffled_mesh.hpp"
#include "opencl/opencl_test_support.hpp"
#include "util/error.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <cstdlib>
#include <numeric>
#include <random>

namespace corofem {
namespace {

using test::DeviceCase;

class OpenCLBackendVsReference : public ::testing::TestWithParam<DeviceCase> {
 protected:
  bool isDouble() const { return GetParam().precision == Precision::Double; }

  /// A 2 x 0.5 x 0.5 m box beam (8 x 2 x 2 cells, 192 tets) clamped at x = 0, with Rayleigh
  /// damping, bent and rotated as a whole by 50 degrees about a skew axis.
  static detail::Problem beam() {
    detail::Problem p = test::makeProblem(test::cellBox(8, 2, 2, 0.25, 0.25, 0.25), 1e5, 0.45, 1000.0);
    p.rayleighMass = 0.2;
    p.rayleighStiffness = 0.01;
    for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
      if (p.mesh.nodes[3 * n] < 1e-9)
        for (int k = 0; k < 3; ++k) p.constrained[3 * n + k] = 1;
    return p;
  }
  static Eigen::VectorXd bent(const detail::Problem& p) {
    Eigen::VectorXd x = p.restPositions;
    const Eigen::Matrix3d R = Eigen::AngleAxisd(0.9, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
    for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) {
      Eigen::Vector3d X = p.restPositions.segment<3>(3 * n);
      Eigen::Vector3d u(0.02 * X.y(), -0.15 * X.x() * X.x(), 0.05 * X.x() * X.z());
      x.segment<3>(3 * n) = R * (X + u);
    }
    return x;
  }
  SolverDesc solver(PreconditionerKind pc = PreconditionerKind::BlockDiagonal) const {
    SolverDesc s;
    s.precision = GetParam().precision;
    s.preconditioner = pc;
    s.tolerance = isDouble() ? 1e-10 : 1e-5;
    s.maxIterations = 2000;
    s.checkEvery = 4;
    return s;
  }
  std::unique_ptr<detail::OpenCLBackendInternal> openclBackend(const detail::Problem& p, const SolverDesc& s,
                                                              const detail::OpenCLTuning& o = {}) {
    return test::openclOn(p, s, detail::cl::Context::shared(std::to_string(GetParam().device)), o);
  }
  static double relErr(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
    return (a - b).norm() / std::max(b.norm(), 1e-300);
  }
  static Eigen::VectorXd randomVector(std::size_t n, unsigned seed) { return test::randomVector(n, seed); }
  static Eigen::VectorXd freeOnly(const detail::Problem& p, Eigen::VectorXd v) {
    for (std::size_t d = 0; d < p.dofCount(); ++d)
      if (p.constrained[d]) v[d] = 0;
    return v;
  }
};

TEST_P(OpenCLBackendVsReference, EnergyKnownFromTheForcesIsTheEnergyOfThosePositions) {
  // On CPU devices the forces' pass also sums the strain energy, which elasticEnergy then returns
  // without a pass of its own while the positions stay those of the forces. It must be the same
  // bits as the energy computed afresh at those positions, and never the energy of positions set
  // before the current ones.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = beam();
  const SolverDesc s = solver();
  auto ocl = openclBackend(p, s), fresh = openclBackend(p, s);
  auto ref = test::createReferenceBackend(p, s);
  const Eigen::VectorXd x1 = bent(p), x2 = p.restPositions + 0.5 * (x1 - p.restPositions);
  Eigen::VectorXd f;
  ocl->setPositions(x1);
  ocl->internalForces(f);
  const double known = ocl->elasticEnergy();
  fresh->setPositions(x1);
  EXPECT_EQ(known, fresh->elasticEnergy()) << "the forces' energy is the energy pass's, bit for bit";
  ref->setPositions(x1);
  const double tol = isDouble() ? 1e-10 : 1e-4;
  EXPECT_NEAR(known, ref->elasticEnergy(), tol * ref->elasticEnergy());
  EXPECT_EQ(ocl->elasticEnergy(), known) << "asked again";
  // New positions after the forces: their own energy, not the one the forces left.
  ocl->setPositions(x2);
  const double second = ocl->elasticEnergy();
  fresh->setPositions(x2);
  EXPECT_EQ(second, fresh->elasticEnergy());
  ref->setPositions(x2);
  EXPECT_NEAR(second, ref->elasticEnergy(), tol * ref->elasticEnergy());
  EXPECT_GT(std::abs(second - known), 0.1 * known) << "the two states store different energies";
  // A product and a solve in between change neither.
  Eigen::VectorXd y, sol = Eigen::VectorXd::Zero(p.dofCount());
  ocl->internalForces(f);
  ocl->apply({14400.0, 120.0, 1.0}, randomVector(p.dofCount(), 5), y);
  ocl->solve({14400.0, 120.0, 1.0}, freeOnly(p, randomVector(p.dofCount(), 6)), sol);
  EXPECT_EQ(ocl->elasticEnergy(), second);
}

TEST_P(OpenCLBackendVsReference, GpuAndCpuKernelConfigurationsAgree) {
  // GPUs run one element per work-item (vector width 1) and local-memory tree reductions (chunk
  // 1); CPUs 8-wide elements and 16-node chunks. Both configurations run here on whatever device
  // is present and must solve the same system to the tolerance.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = beam();
  const Eigen::VectorXd x = bent(p), b = randomVector(p.dofCount(), 7);
  Eigen::VectorXd sols[2];
  int config = 0;
  for (std::size_t width : {1, 8}) {
    detail::OpenCLTuning o;
    o.elementsPerItem = width;
    o.nodesPerItem = width == 1 ? 1 : 0;
    o.workGroupSums = width == 1 ? 1 : -1;
    auto ocl = openclBackend(p, solver(), o);
    ocl->setPositions(x);
    sols[config] = Eigen::VectorXd::Zero(b.size());
    EXPECT_TRUE(ocl->solve({14400.0, 120.0, 1.0}, b, sols[config]).converged) << "width " << width;
    ++config;
  }
  EXPECT_LE(relErr(sols[1], sols[0]), isDouble() ? 1e-8 : 1e-3);
}

TEST_P(OpenCLBackendVsReference, BlockPreconditionerNeedsNoMoreIterationsThanDiagonal) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = beam();
  const Eigen::VectorXd x = bent(p), b = randomVector(p.dofCount(), 9);
  int iterations[3] = {0, 0, 0};
  for (PreconditionerKind pc :
       {PreconditionerKind::None, PreconditionerKind::Diagonal, PreconditionerKind::BlockDiagonal}) {
    SolverDesc s = solver(pc);
    s.checkEvery = 1;
    auto ocl = openclBackend(p, s);
    ocl->setPositions(x);
    Eigen::VectorXd xo = Eigen::VectorXd::Zero(b.size());
    iterations[static_cast<int>(pc)] = ocl->solve({0.0, 0.0, 1.0}, b, xo).iterations;
  }
  std::printf("[info] static beam PCG iterations: none %d, diagonal %d, block %d\n", iterations[0],
              iterations[1], iterations[2]);
  EXPECT_LE(iterations[2], iterations[1]);
}

TEST_P(OpenCLBackendVsReference, PreconditionerIsFormedAtThePositionsOfTheSolve) {
  // The node blocks of the preconditioner rotate with the elements. setPositions leaves them stale
  // and the solve that follows forms them (a step's last evaluation is followed by no solve): a
  // solve must use the blocks of the positions set last, however many positions, forces and solves
  // came before. Checked on the iterate after a few iterations, which depends on the preconditioner
  // (the converged solution would not show it): the same bits as a fresh backend's at those
  // positions, and the reference's PCG iterate with the same preconditioner there, which the blocks
  // of other positions (the rest state's, a rotation by another angle) miss by far.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = beam();
  const Eigen::VectorXd x = bent(p), b = freeOnly(p, randomVector(p.dofCount(), 21));
  Eigen::VectorXd y = p.restPositions;
  const Eigen::Matrix3d Q = Eigen::AngleAxisd(-1.3, Eigen::Vector3d(3, -1, 2).normalized()).toRotationMatrix();
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) y.segment<3>(3 * n) = Q * p.restPositions.segment<3>(3 * n);
  const detail::SystemCoeffs c{0.0, 0.0, 1.0};  // static: the stiffness alone, where the blocks matter most
  for (PreconditionerKind pc : {PreconditionerKind::Diagonal, PreconditionerKind::BlockDiagonal}) {
    SolverDesc s = solver(pc);
    s.checkEvery = 1;
    s.maxIterations = 6;
    auto solveAfter = [&](const std::vector<Eigen::VectorXd>& before, bool solveBetween) {
      auto ocl = openclBackend(p, s);
      Eigen::VectorXd f, sol;
      for (const Eigen::VectorXd& z : before) {
        ocl->setPositions(z);
        ocl->internalForces(f);
        if (solveBetween) {
          sol = Eigen::VectorXd::Zero(b.size());
          ocl->solve(c, b, sol);
        }
      }
      ocl->setPositions(x);
      ocl->internalForces(f);
      sol = Eigen::VectorXd::Zero(b.size());
      EXPECT_EQ(ocl->solve(c, b, sol).iterations, s.maxIterations);
      return sol;
    };
    const Eigen::VectorXd fresh = solveAfter({}, false);
    const std::string what = "preconditioner " + std::to_string(static_cast<int>(pc));
    for (const auto& [before, solveBetween] : std::vector<std::pair<std::vector<Eigen::VectorXd>, bool>>{
             {{y}, false}, {{y, p.restPositions}, true}, {{p.restPositions}, true}}) {
      const Eigen::VectorXd other = solveAfter(before, solveBetween);
      EXPECT_EQ(0, std::memcmp(fresh.data(), other.data(), sizeof(double) * b.size()))
          << what << " after " << before.size() << " other positions" << (solveBetween ? " and solves" : "");
    }
    auto ref = test::createReferenceBackend(p, s);
    Eigen::VectorXd xr = Eigen::VectorXd::Zero(b.size());
    ref->setPositions(x);
    ref->solve(c, b, xr);
    std::printf("[info] %s: the iterate after %d iterations against the reference's: %.2e relative\n", what.c_str(),
                s.maxIterations, relErr(fresh, xr));
    // Measured: 1e-15 (double), 5e-7 (float); with the rest state's blocks 0.11 and 0.30.
    EXPECT_LE(relErr(fresh, xr), isDouble() ? 1e-9 : 1e-4) << what;
  }
}

// A solve warm-started from the previous solution uploads no x (the device still holds it). Each
// warm start below must give the bits of a fresh backend given the same start: the previous
// solution itself, the same with one entry changed (must be uploaded), and the previous solution
// again after another solve from a different start (the device's x moved on).
TEST_P(OpenCLBackendVsReference, WarmStartFromThePreviousSolutionMatchesAFreshUpload) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = beam();
  const Eigen::VectorXd x = bent(p), b1 = randomVector(p.dofCount(), 21), b2 = randomVector(p.dofCount(), 22);
  const detail::SystemCoeffs c{14400.0, 120.0, 1.0};
  SolverDesc s = solver();
  s.maxIterations = 9;  // capped: the answers depend on the start
  s.tolerance = 1e-14;
  auto fresh = [&](const Eigen::VectorXd& start, const Eigen::VectorXd& rhs) {
    auto other = openclBackend(p, s);
    other->setPositions(x);
    Eigen::VectorXd out = start;
    other->solve(c, rhs, out);
    return out;
  };
  auto ocl = openclBackend(p, s);
  ocl->setPositions(x);
  Eigen::VectorXd first = Eigen::VectorXd::Zero(b1.size());
  ocl->solve(c, b1, first);
  const Eigen::VectorXd previous = first;
  Eigen::VectorXd same = previous;
  ocl->solve(c, b2, same);
  EXPECT_TRUE(test::sameBits(same, fresh(previous, b2))) << "warm start = the previous solution";
  Eigen::VectorXd changed = same;
  const Eigen::Index d = changed.size() - 1;  // a free dof (the beam is clamped at x = 0)
  changed[d] += 0.125;
  const Eigen::VectorXd changedStart = changed;
  ocl->solve(c, b1, changed);
  EXPECT_TRUE(test::sameBits(changed, fresh(changedStart, b1))) << "warm start with one entry changed";
  Eigen::VectorXd back = previous;
  ocl->solve(c, b2, back);
  EXPECT_TRUE(test::sameBits(back, same)) << "warm start = an older solution";
}

// A frame warm-started from the previous solution: internalForces queues A x behind its read of
// the forces, and the solve that follows uses it when x, the rotations and the coefficients are
// those it was formed with. Against a second backend whose every A x is formed in the solve (an
// apply() between the forces and the solve takes q_ and discards the early product), frame by frame
// and bit for bit: plain frames; a frame with other coefficients; a frame whose positions change
// between the forces and the solve; a frame whose start was changed by the caller; a zero start.
TEST_P(OpenCLBackendVsReference, ProductQueuedBehindTheForcesGivesTheSolveItsOwnBits) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = beam();
  SolverDesc s = solver();
  s.maxIterations = 12;  // capped: the answers depend on the start and on A x
  s.tolerance = 1e-14;
  auto early = openclBackend(p, s), late = openclBackend(p, s);
  const Eigen::VectorXd x0 = bent(p);
  Eigen::VectorXd x1 = x0;
  for (Eigen::Index d = 0; d < x1.size(); ++d) x1[d] += 1e-3 * std::sin(0.7 * static_cast<double>(d));
  const Eigen::VectorXd probe = randomVector(p.dofCount(), 41);
  Eigen::VectorXd vEarly = Eigen::VectorXd::Zero(p.dofCount()), vLate = vEarly, f, y;
  struct Frame {
    const char* what;
    detail::SystemCoeffs c;
    bool moveBeforeSolve, changeStart, zeroStart;
  };
  const Frame frames[] = {{"first (zero start)", {14400.0, 120.0, 1.0}, false, false, false},
                          {"warm", {14400.0, 120.0, 1.0}, false, false, false},
                          {"warm", {14400.0, 120.0, 1.0}, false, false, false},
                          {"other coefficients", {3600.0, 60.0, 1.0}, false, false, false},
                          {"positions changed before the solve", {3600.0, 60.0, 1.0}, true, false, false},
                          {"start changed by the caller", {3600.0, 60.0, 1.0}, false, true, false},
                          {"zero start", {3600.0, 60.0, 1.0}, false, false, true},
                          {"warm after a zero start", {3600.0, 60.0, 1.0}, false, false, false}};
  int k = 0;
  for (const Frame& fr : frames) {
    const Eigen::VectorXd& x = (k % 2 == 0) ? x0 : x1;
    const Eigen::VectorXd b = randomVector(p.dofCount(), 50 + k);
    if (fr.changeStart) {
      vEarly[vEarly.size() - 1] += 0.25;
      vLate[vLate.size() - 1] += 0.25;
    }
    if (fr.zeroStart) {
      vEarly.setZero();
      vLate.setZero();
    }
    early->setPositions(x);
    late->setPositions(x);
    early->internalForces(f);
    late->internalForces(f);
    late->apply(fr.c, probe, y);  // q_ taken: the late backend forms A x in its solve
    if (fr.moveBeforeSolve) {
      early->setPositions(x1);
      late->setPositions(x1);
    }
    const detail::LinearSolveStats a = early->solve(fr.c, b, vEarly), l = late->solve(fr.c, b, vLate);
    EXPECT_TRUE(test::sameBits(vEarly, vLate)) << "frame " << k << ": " << fr.what;
    EXPECT_EQ(a.iterations, l.iterations) << "frame " << k;
    EXPECT_EQ(a.relativeResidual, l.relativeResidual) << "frame " << k;
    ++k;
  }
}

TEST_P(OpenCLBackendVsReference, HostPassesInChunksGiveTheAnswersOfOnePass) {
  // The host packs, converts and checks node vectors in chunks of 65,536 entries on its threads (a
  // 1M-element body makes 9); chunks of 7 and 96 entries run the test beam's 459 dofs the same way.
  // Forces and products as in one pass (only the centroid's sum is in another order: rounding), the
  // solve to its tolerance; and within each chunking, bit for bit, the warm start against a fresh
  // upload, a NaN in the last chunk of the start taken as 0, and a non-finite b found in a chunk
  // other than the first.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = beam();
  const Eigen::VectorXd x = bent(p), v = randomVector(p.dofCount(), 51), b1 = randomVector(p.dofCount(), 52),
                        b2 = randomVector(p.dofCount(), 53);
  const detail::SystemCoeffs c{14400.0, 120.0, 1.0};
  SolverDesc s = solver();
  s.maxIterations = 9;  // capped: the answers depend on the start
  s.tolerance = 1e-14;
  auto run = [&](std::size_t chunk, Eigen::VectorXd& f, Eigen::VectorXd& y, Eigen::VectorXd& sol) {
    detail::OpenCLTuning o;
    o.hostChunk = chunk;
    auto ocl = openclBackend(p, s, o);
    ocl->setPositions(x);
    ocl->internalForces(f);
    ocl->apply(c, v, y);
    sol = Eigen::VectorXd::Zero(b1.size());
    ocl->solve(c, b1, sol);
    return ocl;
  };
  Eigen::VectorXd f0, y0, sol0;
  run(0, f0, y0, sol0);
  const double tol = isDouble() ? 1e-12 : 2e-5;
  for (std::size_t chunk : {std::size_t{7}, std::size_t{96}}) {
    Eigen::VectorXd f, y, sol;
    auto ocl = run(chunk, f, y, sol);
    EXPECT_LE(relErr(f, f0), tol) << "chunk " << chunk;
    EXPECT_LE(relErr(y, y0), tol) << "chunk " << chunk;
    EXPECT_LE(relErr(sol, sol0), isDouble() ? 1e-9 : 1e-3) << "chunk " << chunk;
    auto fresh = [&](const Eigen::VectorXd& start, const Eigen::VectorXd& rhs) {
      detail::OpenCLTuning o;
      o.hostChunk = chunk;
      auto other = openclBackend(p, s, o);
      other->setPositions(x);
      Eigen::VectorXd out = start;
      other->solve(c, rhs, out);
      return out;
    };
    const Eigen::VectorXd previous = sol;
    ocl->solve(c, b2, sol);  // warm start from the previous solution: no upload of x
    EXPECT_TRUE(test::sameBits(sol, fresh(previous, b2))) << "chunk " << chunk;
    Eigen::VectorXd nanStart = sol, zeroed = sol;
    nanStart[nanStart.size() - 2] = std::nan("");
    zeroed[zeroed.size() - 2] = 0.0;
    ocl->solve(c, b1, nanStart);
    EXPECT_TRUE(test::sameBits(nanStart, fresh(zeroed, b1))) << "chunk " << chunk;
    Eigen::VectorXd badB = b1, untouched = sol;
    badB[badB.size() - 1] = std::numeric_limits<double>::infinity();
    EXPECT_THROW(ocl->solve(c, badB, untouched), detail::Error) << "chunk " << chunk;
    EXPECT_TRUE(test::sameBits(untouched, sol)) << "the caller's x stays as it was";
  }
}

TEST_P(OpenCLBackendVsReference, LocalityOrderChangesNothingTheHostSees) {
  // The device numbers a mesh's elements and nodes along a Morton curve where the mesh's own
  // numbering scatters the kernels' loads (OpenCLTuning::localityOrder, mesh/locality_order.hpp);
  // every host vector keeps the mesh's numbering. A beam numbered at random (as Gmsh numbers its
  // meshes) is reordered by the default rule; its answers match the mesh's own numbering on the
  // device: each element's rotation to its convergence (the same positions reach each element, but
  // the CPU polar iteration's step count is shared by the elements of a vector), forces, energy and
  // products to the rounding of the gathers' other order, the solve to its tolerance.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem ordered = beam();
  detail::Problem p = test::makeProblem(test::shuffledMesh(ordered.mesh, 11), 1e5, 0.45, 1000.0);
  p.rayleighMass = ordered.rayleighMass;
  p.rayleighStiffness = ordered.rayleighStiffness;
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
    if (p.mesh.nodes[3 * n] < 1e-9)
      for (int k = 0; k < 3; ++k) p.constrained[3 * n + k] = 1;
  const Eigen::VectorXd x = bent(p), v = randomVector(p.dofCount(), 61), b = randomVector(p.dofCount(), 62);
  const detail::SystemCoeffs c{14400.0, 120.0, 1.0};
  struct Answers {
    bool reordered = false;
    Eigen::VectorXd f, y, sol;
    double energy = 0.0;
    std::vector<double> rotations;
  };
  auto run = [&](int order) {
    detail::OpenCLTuning o;
    o.localityOrder = order;
    auto ocl = openclBackend(p, solver(), o);
    Answers a;
    detail::DevicePositions where;
    EXPECT_TRUE(ocl->devicePositions(where));
    a.reordered = where.deviceNode != nullptr;
    ocl->setPositions(x);
    ocl->internalForces(a.f);
    a.energy = ocl->elasticEnergy();
    ocl->apply(c, v, a.y);
    a.sol = Eigen::VectorXd::Zero(b.size());
    EXPECT_TRUE(ocl->solve(c, b, a.sol).converged);
    a.rotations = ocl->readRotations();
    return a;
  };
  const double tol = isDouble() ? 1e-12 : 2e-5;
  double forceScale = 0.0, energyScale = 0.0;  // of the bent beam, for the rest state below
  const Answers own = run(0), rule = run(-1);
  forceScale = own.f.cwiseAbs().maxCoeff();
  energyScale = own.energy;
  EXPECT_FALSE(own.reordered);
  EXPECT_TRUE(rule.reordered) << "a randomly numbered mesh is reordered by default";
  ASSERT_EQ(own.rotations.size(), rule.rotations.size());
  double worst = 0.0;
  for (std::size_t i = 0; i < own.rotations.size(); ++i) worst = std::max(worst, std::abs(own.rotations[i] - rule.rotations[i]));
  EXPECT_LE(worst, isDouble() ? 1e-12 : 1e-5) << "rotations, per element in the mesh's order";
  EXPECT_LE(relErr(rule.f, own.f), tol);
  EXPECT_NEAR(rule.energy, own.energy, tol * own.energy);
  EXPECT_LE(relErr(rule.y, own.y), tol);
  EXPECT_LE(relErr(rule.sol, own.sol), isDouble() ? 1e-8 : 1e-3);
  for (std::size_t d = 0; d < p.dofCount(); ++d)
    if (p.constrained[d]) EXPECT_EQ(rule.sol[static_cast<Eigen::Index>(d)], 0.0) << "constrained dof " << d;
  // Before any setPositions the device holds the rest shape (the interface's promise), in its own
  // numbering too: no forces, no energy.
  {
    detail::OpenCLTuning o;
    o.localityOrder = 1;
    auto atRest = openclBackend(p, solver(), o);
    Eigen::VectorXd f;
    atRest->internalForces(f);
    EXPECT_LE(f.cwiseAbs().maxCoeff(), (isDouble() ? 1e-9 : 1e-4) * forceScale) << "forces at rest";
    EXPECT_LE(std::abs(atRest->elasticEnergy()), (isDouble() ? 1e-12 : 1e-6) * energyScale) << "energy at rest";
  }
  // The box generator's layered numbering is kept by the rule (unless the suite's second run forces
  // the Morton order, --corofem_morton).
  if (!test::mortonEverywhere()) {
    auto boxBackend = openclBackend(ordered, solver());
    detail::DevicePositions where;
    ASSERT_TRUE(boxBackend->devicePositions(where));
    EXPECT_EQ(where.deviceNode, nullptr);
  }
}

TEST_P(OpenCLBackendVsReference, DenormalsAreFlushedOnCpuDevicesAndChangeNoAnswer) {
  // -cl-denorms-are-zero by default on CPU devices only (OpenCLTuning::flushDenormals): a denormal
  // float costs an x86 core a microcode assist per operation (bench_mesh_order: the Armadillo in
  // other units). Forced either way, the beam's forces, product and solve agree to the precision.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = beam();
  const Eigen::VectorXd x = bent(p), v = randomVector(p.dofCount(), 71), b = randomVector(p.dofCount(), 72);
  const detail::SystemCoeffs c{14400.0, 120.0, 1.0};
  const bool cpu = detail::cl::Context::shared(std::to_string(GetParam().device))->info().cpu;
  Eigen::VectorXd f[2], y[2], sol[2];
  for (int flush : {-1, 0, 1}) {
    detail::OpenCLTuning o;
    o.flushDenormals = flush;
    auto ocl = openclBackend(p, solver(), o);
    const bool flushed = ocl->buildOptions().find("-cl-denorms-are-zero") != std::string::npos;
    EXPECT_EQ(flushed, flush == 1 || (flush == -1 && cpu)) << "flush " << flush;
    if (flush < 0) continue;
    ocl->setPositions(x);
    ocl->internalForces(f[flush]);
    ocl->apply(c, v, y[flush]);
    sol[flush] = Eigen::VectorXd::Zero(b.size());
    EXPECT_TRUE(ocl->solve(c, b, sol[flush]).converged);
  }
  const double tol = isDouble() ? 1e-12 : 1e-5;
  EXPECT_LE(relErr(f[1], f[0]), tol);
  EXPECT_LE(relErr(y[1], y[0]), tol);
  EXPECT_LE(relErr(sol[1], sol[0]), isDouble() ? 1e-8 : 1e-3);
}

TEST_P(OpenCLBackendVsReference, BodyFarFromTheOriginKeepsItsAccuracy) {
  // The beam translated by ~2e4 m: float positions there have a resolution of ~1e-3 m, larger
  // than the strains' displacements; the backend uploads positions relative to their centroid, so
  // forces and energy keep the accuracy of the beam at the origin. The oracle is the reference at
  // the origin (forces and energy are translation invariant), since the reference's own
  // R^T x - X loses ~|x| / |u| = 1e5 of its precision to cancellation out there.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem atOrigin = beam();
  detail::Problem p = atOrigin;
  const Eigen::Vector3d shift(1e4, -2e4, 5e3);
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) {
    p.restPositions.segment<3>(3 * n) += shift;
    for (int k = 0; k < 3; ++k) p.mesh.nodes[3 * n + k] = p.restPositions[3 * n + k];
  }
  const Eigen::VectorXd x0 = bent(atOrigin);
  Eigen::VectorXd x = x0;
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) x.segment<3>(3 * n) += shift;
  auto ref = test::createReferenceBackend(atOrigin, solver());
  auto ocl = openclBackend(p, solver());
  ref->setPositions(x0);
  ocl->setPositions(x);
  Eigen::VectorXd fr, fo;
  ref->internalForces(fr);
  ocl->internalForces(fo);
  const double tol = isDouble() ? 1e-10 : 1e-4;  // as at the origin (ForcesProductAndEnergyMatch)
  EXPECT_LE((fo - fr).cwiseAbs().maxCoeff(), tol * fr.cwiseAbs().maxCoeff());
  EXPECT_NEAR(ocl->elasticEnergy(), ref->elasticEnergy(), tol * ref->elasticEnergy());
}

TEST_P(OpenCLBackendVsReference, AdoptedContextGivesTheSameForces) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = beam();
  const auto info = detail::cl::listDevices().at(static_cast<std::size_t>(GetParam().device));
  cl_int status = CL_SUCCESS;
  cl_context ctx = clCreateContext(nullptr, 1, &info.device, nullptr, nullptr, &status);
  ASSERT_EQ(status, CL_SUCCESS);
  cl_command_queue queue = clCreateCommandQueue(ctx, info.device, 0, &status);
  ASSERT_EQ(status, CL_SUCCESS);
  Eigen::VectorXd fa, fs;
  {
    auto adopted = detail::createOpenCLBackendAdopting(p, solver(), ctx, queue, info.device, test::morton());
    adopted->setPositions(bent(p));
    adopted->internalForces(fa);
  }
  auto shared = openclBackend(p, solver());
  shared->setPositions(bent(p));
  shared->internalForces(fs);
  EXPECT_EQ(0, std::memcmp(fa.data(), fs.data(), sizeof(double) * fa.size()));
  // The application's objects are still valid after the backend released its references.
  EXPECT_EQ(clFinish(queue), CL_SUCCESS);
  clReleaseCommandQueue(queue);
  clReleaseContext(ctx);
}

TEST_P(OpenCLBackendVsReference, AdoptingAnOutOfOrderOrForeignQueueIsAClearError) {
  // The backend orders its work by the queue alone: it refuses an out-of-order queue, and a queue
  // of another context, with a message that says what to pass instead.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const detail::Problem p = beam();
  const auto info = detail::cl::listDevices().at(static_cast<std::size_t>(GetParam().device));
  cl_int status = CL_SUCCESS;
  cl_context ctx = clCreateContext(nullptr, 1, &info.device, nullptr, nullptr, &status);
  ASSERT_EQ(status, CL_SUCCESS);
  cl_context other = clCreateContext(nullptr, 1, &info.device, nullptr, nullptr, &status);
  ASSERT_EQ(status, CL_SUCCESS);
  auto expectBadInput = [&](cl_command_queue queue, const char* words) {
    try {
      detail::createOpenCLBackendAdopting(p, solver(), ctx, queue, info.device, test::morton());
      ADD_FAILURE() << "expected BadInput mentioning '" << words << "'";
    } catch (const detail::Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::BadInput);
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
  };
  cl_command_queue foreign = clCreateCommandQueue(other, info.device, 0, &status);
  ASSERT_EQ(status, CL_SUCCESS);
  expectBadInput(foreign, "another context");
  clReleaseCommandQueue(foreign);
  cl_command_queue unordered = clCreateCommandQueue(ctx, info.device, CL_QUEUE_OUT_OF_ORDER_EXEC_MODE_ENABLE, &status);
  if (status == CL_SUCCESS) {
    expectBadInput(unordered, "out of order");
    clReleaseCommandQueue(unordered);
  } else {
    EXPECT_EQ(status, CL_INVALID_QUEUE_PROPERTIES) << "the device may refuse out-of-order queues, nothing else";
  }
  clReleaseContext(other);
  clReleaseContext(ctx);
}

INSTANTIATE_TEST_SUITE_P(Devices, OpenCLBackendVsReference, ::testing::ValuesIn(test::deviceCases()),
                         test::caseName);

}  // namespace
}  // namespace corofem
