// The contract of a StepStore (solve/step_store.hpp), the dynamics driver's vectors and per-dof
// passes: each pass against the expressions of DynamicsDriver's documentation written out here in
// plain Eigen, on random states of two bodies with every feature a pass reads (loads with ramps,
// prescribed and fixed dofs, held targets with NaN entries, applied forces, springs, Rayleigh
// damping), one of them larger than a chunk of the host's threads (16,384 dofs). A store that keeps
// the vectors on a device joins the parameter list and meets the same expressions within its
// precision; the host store meets them to rounding. The whole states' swaps and copies, and a
// body's independence of the set it is passed in, are checked too.
#include "common/random_vector.hpp"
#include "common/test_problems.hpp"

#include "backends/reference/reference_device.hpp"
#include "device/registry.hpp"
#include "solve/device_slot.hpp"
#include "solve/step_store.hpp"
#include "util/error.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <vector>

namespace corofem {
namespace {

using detail::BeginArgs;
using detail::EndSums;
using detail::ResidualSums;
using detail::SchemeMaps;
using detail::Scratch;
using detail::StateSlot;
using detail::StateVec;
using test::randomVector;

/// Relative difference of two vectors (infinity norm), 0 for two zero vectors.
double relDiff(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  if (a.size() != b.size()) return INFINITY;
  const double scale = std::max(a.lpNorm<Eigen::Infinity>(), b.lpNorm<Eigen::Infinity>());
  return scale == 0.0 ? 0.0 : (a - b).lpNorm<Eigen::Infinity>() / scale;
}

double relDiff(double a, double b) {
  const double scale = std::max(std::abs(a), std::abs(b));
  return scale == 0.0 ? 0.0 : std::abs(a - b) / scale;
}

/// A box of cells of edge h with every feature a pass reads: the nodes at x = 0 fixed, those at
/// the far end prescribed (ramped over 0.5 s), two loads (one ramped over 2 s), springs on every
/// fifth dof, and Rayleigh damping.
detail::Problem featureBody(int nx, int ny, int nz, double h, unsigned seed) {
  detail::Problem p = test::makeProblem(test::cellBox(nx, ny, nz, h, h, h), 2e5, 0.3, 900.0);
  const Eigen::Index n = p.restPositions.size();
  detail::PrescribedDisplacement moved;
  moved.rampTime = 0.5;
  for (Eigen::Index d = 0; d < n; ++d) {
    const double x = p.restPositions[d - d % 3];
    if (x < 1e-9) p.constrained[static_cast<std::size_t>(d)] = 1;
    if (x > h * nx - 1e-9 && d % 3 == 1) {
      p.constrained[static_cast<std::size_t>(d)] = 1;
      moved.dofs.push_back(static_cast<std::uint32_t>(d));
      moved.values.push_back(-0.01 * static_cast<double>(1 + d % 7));
    }
  }
  p.prescribed.push_back(moved);
  p.forces.push_back({randomVector(static_cast<std::size_t>(n), seed), 0.0, false});
  p.forces.push_back({randomVector(static_cast<std::size_t>(n), seed + 1), 2.0, false});
  p.springStiffness = Eigen::VectorXd::Zero(n);
  for (Eigen::Index d = 0; d < n; d += 5) p.springStiffness[d] = 50.0 + static_cast<double>(d % 13);
  p.rayleighMass = 0.3;
  p.rayleighStiffness = 0.002;
  return p;
}

Eigen::ArrayXd freeOf(const detail::Problem& p) {
  Eigen::ArrayXd f = Eigen::ArrayXd::Ones(p.restPositions.size());
  for (std::size_t d = 0; d < p.constrained.size(); ++d)
    if (p.constrained[d]) f[static_cast<Eigen::Index>(d)] = 0.0;
  return f;
}

/// A state near rest: x = X + 0.01 * random, v, a, f_ext and reactions random.
void randomState(detail::StepStore& store, std::size_t body, StateSlot slot, const detail::Problem& p, unsigned seed) {
  const auto n = static_cast<std::size_t>(p.restPositions.size());
  store.setState(body, slot, StateVec::X, p.restPositions + 0.01 * randomVector(n, seed));
  store.setState(body, slot, StateVec::V, randomVector(n, seed + 1));
  store.setState(body, slot, StateVec::A, 3.0 * randomVector(n, seed + 2));
  store.setState(body, slot, StateVec::Fext, randomVector(n, seed + 3));
  store.setState(body, slot, StateVec::Reaction, randomVector(n, seed + 4));
}

/// The application's controls: held targets on half of the constrained dofs (NaN on the others),
/// applied forces everywhere, spring targets near rest.
detail::BodyControls randomControls(const detail::Problem& p, unsigned seed) {
  const auto n = static_cast<std::size_t>(p.restPositions.size());
  detail::BodyControls c;
  c.targets = Eigen::VectorXd::Constant(static_cast<Eigen::Index>(n), std::numeric_limits<double>::quiet_NaN());
  for (std::size_t d = 0; d < n; ++d)
    if (p.constrained[d] && d % 2 == 0)
      c.targets[static_cast<Eigen::Index>(d)] = p.restPositions[static_cast<Eigen::Index>(d)] + 0.02;
  c.forces = randomVector(n, seed);
  c.springTargets = p.restPositions + 0.05 * randomVector(n, seed + 1);
  return c;
}

SchemeMaps newmarkMaps(double h) {
  const double beta = 0.25, gamma = 0.5;
  SchemeMaps m;
  m.newmark = true;
  m.h = h;
  m.ka = 1.0 / (h * gamma);
  m.kx = h * beta / gamma;
  m.cv = h * (1.0 - gamma);
  m.ca = h * h * (0.5 - beta);
  return m;
}

SchemeMaps eulerMaps(double h) {
  SchemeMaps m;
  m.h = h;
  m.ka = 1.0 / h;
  m.kx = h;
  return m;
}

/// A store of the contract: the host's, or a Vulkan device's in double or float. `floor`: the
/// relative difference its precision allows wherever the host's meets an expression to rounding (a
/// device store keeps positions relative to an origin of its own, where the device's own calls take
/// them relative to their centroid: the forces and products the test compares differ by rounding
/// there; in float, Newton's starting v on held dofs, (t - xb) / kx, loses most).
struct StoreKind {
  const char* name;
  bool vulkan;
  Precision precision;
  double floor;
};

const StoreKind kStores[] = {
    {"host", false, Precision::Double, 0.0},
    {"vulkan_double", true, Precision::Double, 1e-12},
    {"vulkan_float", true, Precision::Float, 2e-5},
};

class StepStoreContract : public ::testing::TestWithParam<StoreKind> {
 protected:
  /// The bound of a comparison the host's store meets to `t`.
  double tol(double t) const { return std::max(t, GetParam().floor); }

  void SetUp() override {
    // Body 0: 6 x 3 x 3 cells of 10 cm (112 nodes); body 1: a rod of 1,400 x 1 x 1 cells of 1 cm
    // (5,604 nodes, 16,812 dofs: two chunks of the host's threads, in few elements for the
    // sanitizer job's -O0).
    problems_.push_back(featureBody(6, 3, 3, 0.1, 11));
    problems_.push_back(featureBody(1400, 1, 1, 0.01, 21));
    problems_[1].rayleighStiffness = 0.0;  // mass damping alone: the damping's other path
    ASSERT_GT(problems_[1].restPositions.size(), 16384);
    SolverDesc solver;
    solver.linearSolver = LinearSolverKind::Pcg;
    solver.tolerance = 1e-6;  // the solves are compared with the slot's own, not with an answer
    solver.maxIterations = 2000;
    solver.precision = GetParam().precision;
    std::vector<const detail::Problem*> ps;
    for (const detail::Problem& p : problems_) ps.push_back(&p);
    if (!GetParam().vulkan) {
      slot_ = std::make_unique<detail::DeviceSlot>(detail::createReferenceDevice(ps, solver), solver);
      store_ = detail::createHostStepStore(*slot_);
    } else {
      const auto entry = detail::findBackend("vulkan");
      if (!entry || entry->candidates().empty()) GTEST_SKIP() << "no Vulkan device";
      std::unique_ptr<detail::Device> device;
      detail::DeviceOptions options;
      options.vulkan.deviceStore = 1;  // the default keeps the host's
      try {
        device = entry->create(ps, solver, entry->resolve(""), options);
      } catch (const detail::Error& e) {
        GTEST_SKIP() << "no Vulkan device for this precision: " << e.what();
      }
      slot_ = std::make_unique<detail::DeviceSlot>(std::move(device), solver);
      store_ = slot_->device().createStepStore(*slot_);
      ASSERT_NE(store_, nullptr);
    }
    for (std::size_t b = 0; b < problems_.size(); ++b) {
      randomState(*store_, b, StateSlot::Committed, problems_[b], 100 + 10 * static_cast<unsigned>(b));
      randomState(*store_, b, StateSlot::Start, problems_[b], 200 + 10 * static_cast<unsigned>(b));
      store_->setControls(b, randomControls(problems_[b], 300 + 10 * static_cast<unsigned>(b)));
    }
  }

  /// Runs begin and positions for `set` with `maps` (t1 = 0.3 s, halfway through the step, from
  /// the step's start).
  void beginAndPositions(const detail::BodySet& set, const std::vector<SchemeMaps>& maps) {
    std::vector<BeginArgs> args;
    for (const SchemeMaps& m : maps) args.push_back(BeginArgs{m, 0.3, 0.5, StateSlot::Start});
    store_->begin(set, args);
    store_->positions(set, maps);
  }

  /// beginAndPositions, then the device's positions, forces and damping at the result state.
  void evaluate(const detail::BodySet& set, const std::vector<SchemeMaps>& maps) {
    beginAndPositions(set, maps);
    store_->setPositions(*slot_, set, StateSlot::Result);
    store_->internalForces(*slot_, set);
    store_->damping(*slot_, set, StateSlot::Result);
  }

  std::vector<detail::Problem> problems_;
  std::unique_ptr<detail::DeviceSlot> slot_;
  std::unique_ptr<detail::StepStore> store_;
};

TEST_P(StepStoreContract, BeginAndPositionsFormTheSchemesAffineMapsTargetsAndLoads) {
  const std::vector<SchemeMaps> maps = {newmarkMaps(1.0 / 60.0), eulerMaps(0.01)};
  beginAndPositions({0, 1}, maps);
  for (std::size_t b = 0; b < 2; ++b) {
    SCOPED_TRACE("body " + std::to_string(b));
    const detail::Problem& p = problems_[b];
    const SchemeMaps& m = maps[b];
    const Eigen::ArrayXd free = freeOf(p);
    const Eigen::VectorXd x = store_->state(b, StateSlot::Committed, StateVec::X);
    const Eigen::VectorXd v = store_->state(b, StateSlot::Committed, StateVec::V);
    const Eigen::VectorXd a = store_->state(b, StateSlot::Committed, StateVec::A);
    const Eigen::VectorXd x0 = store_->state(b, StateSlot::Start, StateVec::X);
    const detail::BodyControls& c = store_->controls(b);
    const Eigen::VectorXd vb = m.newmark ? Eigen::VectorXd(v + m.cv * a) : v;
    const Eigen::VectorXd xb = m.newmark ? Eigen::VectorXd(x + m.h * v + m.ca * a - m.kx * vb) : x;
    EXPECT_LT(relDiff(store_->scratch(b, Scratch::Vb), vb), tol(1e-15));
    EXPECT_LT(relDiff(store_->scratch(b, Scratch::Xb), xb), tol(1e-15));
    // Targets at t1 = 0.3 s: rest on fixed dofs, X + 0.6 u on prescribed ones (ramp 0.5 s), the
    // held ones halfway from the step's start.
    Eigen::VectorXd target = p.restPositions;
    for (const detail::PrescribedDisplacement& pd : p.prescribed)
      for (std::size_t k = 0; k < pd.dofs.size(); ++k) target[pd.dofs[k]] += 0.6 * pd.values[k];
    for (Eigen::Index d = 0; d < target.size(); ++d)
      if (!std::isnan(c.targets[d])) target[d] = x0[d] + 0.5 * (c.targets[d] - x0[d]);
    const Eigen::VectorXd fext = p.forces[0].f + 0.15 * p.forces[1].f + c.forces;  // ramps: 1 and 0.3 / 2
    EXPECT_LT(relDiff(store_->state(b, StateSlot::Result, StateVec::Fext), fext), tol(1e-15));
    Eigen::VectorXd vStart = v;
    for (Eigen::Index d = 0; d < v.size(); ++d)
      if (free[d] == 0.0) vStart[d] = (target[d] - xb[d]) / m.kx;
    // The result state at Newton's start: free dofs keep v_n; constrained ones land on their targets.
    const Eigen::VectorXd vNew = store_->state(b, StateSlot::Result, StateVec::V);
    const Eigen::VectorXd xNew = store_->state(b, StateSlot::Result, StateVec::X);
    EXPECT_LT(relDiff(vNew, vStart), tol(1e-14));
    EXPECT_LT(relDiff(xNew, xb + m.kx * vNew), tol(1e-15));
    EXPECT_LT(relDiff(store_->state(b, StateSlot::Result, StateVec::A), m.ka * (vNew - vb)), tol(1e-15));
    for (Eigen::Index d = 0; d < x.size(); ++d)
      if (free[d] == 0.0) EXPECT_NEAR(xNew[d], target[d], tol(1e-14)) << "dof " << d;
    EXPECT_EQ(store_->scratch(b, Scratch::Cv).norm(), 0.0);
  }
  // The step's first advance (fraction 1, from the committed state): held targets exactly.
  store_->begin({0}, {BeginArgs{maps[0], 0.3, 1.0, StateSlot::Committed}});
  const detail::BodyControls& c = store_->controls(0);
  const Eigen::VectorXd& target = store_->scratch(0, Scratch::Target);
  int held = 0;
  for (Eigen::Index d = 0; d < target.size(); ++d)
    if (!std::isnan(c.targets[d])) {
      EXPECT_NEAR(target[d], c.targets[d], tol(0.0) * std::abs(c.targets[d])) << "dof " << d;
      ++held;
    }
  EXPECT_GT(held, 0);
}

TEST_P(StepStoreContract, DeviceCallsResidualUpdateAndEndAreTheDriversExpressions) {
  const std::vector<SchemeMaps> maps = {newmarkMaps(1.0 / 60.0), eulerMaps(0.01)};
  const detail::BodySet set = {0, 1};
  evaluate(set, maps);
  std::vector<ResidualSums> sums;
  store_->residual(set, maps, sums);
  std::vector<detail::PcgSolve> solves(2);
  for (std::size_t b = 0; b < 2; ++b) solves[b].coeffs = {1.0, 1.0 / maps[b].ka, maps[b].kx / maps[b].ka};
  // The solve's expected answer: the slot's own solve of the same system from host vectors.
  std::vector<Eigen::VectorXd> rhs(2), dvExpected(2);
  std::vector<detail::PcgSolve> direct(2);
  for (std::size_t b = 0; b < 2; ++b) {
    rhs[b] = store_->scratch(b, Scratch::Rhs);
    dvExpected[b] = Eigen::VectorXd::Zero(rhs[b].size());
    direct[b].coeffs = solves[b].coeffs;
    direct[b].b = &rhs[b];
    direct[b].x = &dvExpected[b];
  }
  std::vector<Eigen::VectorXd> vBefore;
  for (std::size_t b = 0; b < 2; ++b) vBefore.push_back(store_->state(b, StateSlot::Result, StateVec::V));
  store_->solve(*slot_, set, solves);
  for (std::size_t b = 0; b < 2; ++b) {
    SCOPED_TRACE("body " + std::to_string(b));
    EXPECT_TRUE(solves[b].failure.empty()) << solves[b].failure;
    EXPECT_TRUE(solves[b].stats.converged);
    EXPECT_GT(solves[b].stats.iterations, 0);
  }
  std::vector<double> bad;
  store_->update(set, bad);
  std::vector<EndSums> ends;
  store_->end(set, ends);
  // A solve starts from Dv = 0, not from the last answer: the same solve again gives the same bits
  // (body 0's: the rod's solves are the slow part of this test in the sanitizer job).
  const Eigen::VectorXd dvFirst = store_->scratch(0, Scratch::Dv);
  std::vector<detail::PcgSolve> again(1);
  again[0].coeffs = solves[0].coeffs;
  store_->solve(*slot_, {0}, again);
  EXPECT_TRUE(test::sameBits(store_->scratch(0, Scratch::Dv), dvFirst));
  EXPECT_EQ(again[0].stats.iterations, solves[0].stats.iterations);

  for (std::size_t b = 0; b < 2; ++b) {
    SCOPED_TRACE("body " + std::to_string(b));
    const detail::Problem& p = problems_[b];
    const Eigen::ArrayXd free = freeOf(p);
    const detail::BodyControls& c = store_->controls(b);
    const Eigen::VectorXd x = store_->state(b, StateSlot::Result, StateVec::X);
    const Eigen::VectorXd a = store_->state(b, StateSlot::Result, StateVec::A);
    // The device calls: f_int at the result's x, C v at its v (before the update).
    Eigen::VectorXd fint, cv;
    slot_->setPositions({b}, {&x});
    slot_->internalForces({b}, {&fint});
    slot_->apply({b}, {detail::SystemCoeffs{0.0, 1.0, 0.0}}, {&vBefore[b]}, {&cv});
    EXPECT_LT(relDiff(store_->scratch(b, Scratch::Fint), fint), tol(1e-15));
    EXPECT_LT(relDiff(store_->scratch(b, Scratch::Cv), cv), tol(1e-15));
    // The residual and its sums.
    Eigen::VectorXd spring = Eigen::VectorXd::Zero(x.size());
    for (Eigen::Index d = 0; d < x.size(); ++d)
      if (p.springStiffness[d] != 0.0) spring[d] = p.springStiffness[d] * (x[d] - c.springTargets[d]);
    const Eigen::VectorXd ma = p.lumpedMass.cwiseProduct(a);
    const Eigen::VectorXd fextNew = p.forces[0].f + 0.15 * p.forces[1].f + c.forces;
    const Eigen::VectorXd r = ma + cv + fint + spring - fextNew;
    EXPECT_LT(relDiff(store_->scratch(b, Scratch::R), r), tol(1e-14));
    auto freeSq = [&](const Eigen::VectorXd& u) { return (u.array() * free).matrix().squaredNorm(); };
    EXPECT_LT(relDiff(sums[b].ma, freeSq(ma)), tol(1e-13));
    EXPECT_LT(relDiff(sums[b].cv, freeSq(cv)), tol(1e-13));
    EXPECT_LT(relDiff(sums[b].fint, freeSq(fint)), tol(1e-13));
    EXPECT_LT(relDiff(sums[b].spring, freeSq(spring)), tol(1e-13));
    EXPECT_LT(relDiff(sums[b].r, freeSq(r)), tol(1e-13));
    EXPECT_LT(relDiff(sums[b].fext, freeSq(fextNew)), tol(1e-13));
    EXPECT_EQ(sums[b].nonFinite, 0.0);
    EXPECT_LT(relDiff(rhs[b], -r / maps[b].ka), tol(1e-14));
    // The solve: the slot's own answer for the store's right-hand side (body 0's), and v += dv.
    const Eigen::VectorXd dv = store_->scratch(b, Scratch::Dv);
    if (b == 0) {
      std::vector<detail::PcgSolve> alone = {direct[b]};
      slot_->solve({b}, alone);
      EXPECT_LT(relDiff(dv, dvExpected[b]), tol(1e-12));
    }
    EXPECT_GT(dv.norm(), 0.0);
    EXPECT_EQ(bad[b], 0.0);
    const Eigen::VectorXd vNew = store_->state(b, StateSlot::Result, StateVec::V);
    EXPECT_LT(relDiff(vNew, vBefore[b] + dv), tol(1e-15));
    // The end: reactions on constrained rows, the springs' pull joining f_ext on free dofs, the
    // work sums over dx and m v^2.
    const Eigen::VectorXd reaction = (r.array() * (1.0 - free)).matrix();
    EXPECT_LT(relDiff(store_->state(b, StateSlot::Result, StateVec::Reaction), reaction), tol(1e-15));
    const Eigen::VectorXd fEnd = fextNew - (spring.array() * free).matrix();
    EXPECT_LT(relDiff(store_->state(b, StateSlot::Result, StateVec::Fext), fEnd), tol(1e-14));
    const Eigen::VectorXd dx = x - store_->state(b, StateSlot::Committed, StateVec::X);
    const Eigen::VectorXd fPrev = store_->state(b, StateSlot::Committed, StateVec::Fext);
    const Eigen::VectorXd rPrev = store_->state(b, StateSlot::Committed, StateVec::Reaction);
    const EndSums want = {(rPrev + reaction).dot(dx), (fPrev + fEnd).dot(dx), rPrev.dot(dx), reaction.dot(dx),
                          fPrev.dot(dx),           fEnd.dot(dx),           p.lumpedMass.dot(vNew.cwiseProduct(vNew))};
    for (std::size_t k = 0; k < want.size(); ++k) EXPECT_LT(relDiff(ends[b][k], want[k]), tol(1e-12)) << "sum " << k;
  }
}

TEST_P(StepStoreContract, ResidualCountsTheDofsWhereTheResultStateIsNotFinite) {
  const std::vector<SchemeMaps> maps = {eulerMaps(0.01), eulerMaps(0.01)};
  const detail::BodySet set = {0, 1};
  evaluate(set, maps);
  // A Newton iterate that went non-finite at one dof of body 0: x(v) and a(v) follow it there.
  Eigen::VectorXd v = store_->state(0, StateSlot::Result, StateVec::V);
  v[4] = std::numeric_limits<double>::quiet_NaN();
  store_->setState(0, StateSlot::Result, StateVec::V, v);
  store_->positions({0}, {maps[0]});
  std::vector<ResidualSums> sums;
  store_->residual({1, 0}, {maps[1], maps[0]}, sums);
  EXPECT_EQ(sums[0].nonFinite, 0.0);
  EXPECT_EQ(sums[1].nonFinite, 1.0);  // one dof, whose x, v and a are all NaN
  EXPECT_TRUE(std::isfinite(sums[0].r));
}

TEST_P(StepStoreContract, SwapsAndCopiesMoveWholeStatesOfOneBody) {
  auto snapshot = [&](std::size_t b, StateSlot s) {
    std::vector<Eigen::VectorXd> out;
    for (StateVec v : {StateVec::X, StateVec::V, StateVec::A, StateVec::Fext, StateVec::Reaction})
      out.push_back(store_->state(b, s, v));
    return out;
  };
  const auto committed0 = snapshot(0, StateSlot::Committed), start0 = snapshot(0, StateSlot::Start);
  const auto committed1 = snapshot(1, StateSlot::Committed);
  store_->swap(0, StateSlot::Committed, StateSlot::Start);
  EXPECT_EQ(snapshot(0, StateSlot::Committed), start0);
  EXPECT_EQ(snapshot(0, StateSlot::Start), committed0);
  EXPECT_EQ(snapshot(1, StateSlot::Committed), committed1);  // the other body keeps its states
  store_->copy(0, StateSlot::Start, StateSlot::Previous);
  EXPECT_EQ(snapshot(0, StateSlot::Previous), committed0);
  EXPECT_EQ(snapshot(0, StateSlot::Start), committed0);
  // A copy is a copy: changing the source leaves it.
  store_->setState(0, StateSlot::Start, StateVec::X, problems_[0].restPositions);
  EXPECT_EQ(store_->state(0, StateSlot::Previous, StateVec::X), committed0[0]);
}

TEST_P(StepStoreContract, SetZeroClearsOneVectorOfOneStateAndLeavesEveryOther) {
  const std::vector<StateSlot> slots = {StateSlot::Committed, StateSlot::Start};
  const std::vector<StateVec> vecs = {StateVec::X, StateVec::V, StateVec::A, StateVec::Fext, StateVec::Reaction};
  std::vector<Eigen::VectorXd> before;
  for (std::size_t b = 0; b < 2; ++b)
    for (StateSlot s : slots)
      for (StateVec v : vecs) before.push_back(store_->state(b, s, v));
  store_->setZero(1, StateSlot::Committed, StateVec::A);
  store_->setZero(0, StateSlot::Start, StateVec::Fext);
  std::size_t k = 0;
  for (std::size_t b = 0; b < 2; ++b)
    for (StateSlot s : slots)
      for (StateVec v : vecs) {
        const Eigen::VectorXd& now = store_->state(b, s, v);
        const bool cleared = (b == 1 && s == StateSlot::Committed && v == StateVec::A) ||
                             (b == 0 && s == StateSlot::Start && v == StateVec::Fext);
        SCOPED_TRACE("body " + std::to_string(b) + ", entry " + std::to_string(k));
        ASSERT_EQ(now.size(), problems_[b].restPositions.size());
        if (cleared) {
          EXPECT_TRUE(before[k].cwiseAbs().maxCoeff() > 0.0);  // the random state it replaced
          EXPECT_EQ(now.cwiseAbs().maxCoeff(), 0.0);
        } else {
          EXPECT_EQ(now, before[k]);
        }
        ++k;
      }
  // A state the store never held gets its 3N zeros too; a body it lacks is an error.
  store_->setZero(1, StateSlot::Result, StateVec::V);
  EXPECT_EQ(store_->state(1, StateSlot::Result, StateVec::V), Eigen::VectorXd::Zero(problems_[1].restPositions.size()));
  EXPECT_THROW(store_->setZero(2, StateSlot::Committed, StateVec::X), detail::Error);
}

TEST_P(StepStoreContract, ABodyGetsTheSameBitsAloneAsInASet) {
  const std::vector<SchemeMaps> maps = {newmarkMaps(1.0 / 60.0), eulerMaps(0.01)};
  auto run = [&](const detail::BodySet& set) {
    std::vector<SchemeMaps> m;
    for (std::size_t b : set) m.push_back(maps[b]);
    evaluate(set, m);
    std::vector<ResidualSums> sums;
    store_->residual(set, m, sums);
    std::vector<EndSums> ends;
    store_->end(set, ends);
    std::vector<std::vector<double>> out;
    for (std::size_t k = 0; k < set.size(); ++k) {
      const ResidualSums& s = sums[k];
      std::vector<double> row = {s.ma, s.cv, s.fint, s.spring, s.r, s.fext};
      row.insert(row.end(), ends[k].begin(), ends[k].end());
      out.push_back(row);
    }
    return out;
  };
  const auto both = run({0, 1});
  const Eigen::VectorXd r1 = store_->scratch(1, Scratch::R);
  const auto alone = run({1});
  EXPECT_EQ(both[1], alone[0]);  // bitwise: the same doubles
  EXPECT_TRUE(test::sameBits(store_->scratch(1, Scratch::R), r1));
}

/// A device error in a Vulkan store's world: the slot moves to its next candidate (here the
/// reference), which takes the positions the store last set on the Vulkan device (not any the slot
/// was given), and the store's calls go on through the slot with host vectors.
TEST(VulkanStepStoreFailover, TheNextDeviceTakesThePositionsTheStoreSetAndTheCallsGoOn) {
  const auto vulkan = detail::findBackend("vulkan");
  const auto reference = detail::findBackend("reference");
  ASSERT_NE(reference, nullptr);
  if (!vulkan || vulkan->candidates().empty()) GTEST_SKIP() << "no Vulkan device";
  const detail::Problem problem = featureBody(6, 3, 3, 0.1, 11);
  SolverDesc solver;
  solver.linearSolver = LinearSolverKind::Pcg;
  solver.precision = Precision::Double;
  detail::DeviceOptions options;
  options.vulkan.deviceStore = 1;
  std::unique_ptr<detail::DeviceSlot> slot;
  try {
    slot = std::make_unique<detail::DeviceSlot>(std::vector<const detail::Problem*>{&problem}, solver,
                                                std::vector<detail::Candidate>{vulkan->resolve(""), reference->resolve("")},
                                                /*fallbackAtCreate=*/false, options);
  } catch (const detail::Error& e) {
    GTEST_SKIP() << "no Vulkan device for double: " << e.what();
  }
  ASSERT_EQ(slot->current().backend, "vulkan");
  std::unique_ptr<detail::StepStore> store = slot->device().createStepStore(*slot);
  ASSERT_NE(store, nullptr);
  const auto n = static_cast<std::size_t>(problem.restPositions.size());
  slot->setPositions({0}, {&problem.restPositions});  // what the slot was given: rest
  const Eigen::VectorXd x = problem.restPositions + 0.01 * randomVector(n, 5);
  store->setState(0, StateSlot::Committed, StateVec::X, x);
  store->setPositions(*slot, {0}, StateSlot::Committed);  // on the device, from the store's buffer
  std::vector<double> before, after;
  slot->elasticEnergy({0}, before);
  ASSERT_GT(before[0], 0.0);

  slot->failover("a test", detail::Error(ErrorCode::DeviceError, "a device lost on purpose"));
  EXPECT_EQ(slot->current().backend, "reference");
  EXPECT_EQ(slot->failovers(), 1u);
  slot->elasticEnergy({0}, after);
  EXPECT_NEAR(after[0], before[0], 1e-9 * before[0]) << "the reference was not given the store's positions";

  // The store's calls now go through the slot: its forces are the reference's at x.
  store->internalForces(*slot, {0});
  Eigen::VectorXd f;
  slot->internalForces({0}, {&f});
  EXPECT_TRUE(test::sameBits(store->scratch(0, Scratch::Fint), f));
  EXPECT_GT(f.norm(), 0.0);
}

/// The device calls a store makes count in the slot's statistics (the batch report's
/// rounds_by_call) as the slot's own calls do: the same calls with the Vulkan store as with the
/// host's, which makes them through the slot.
TEST(VulkanStepStoreCounts, TheStoresDeviceCallsCountAsTheSlotsOwnDo) {
  const auto vulkan = detail::findBackend("vulkan");
  if (!vulkan || vulkan->candidates().empty()) GTEST_SKIP() << "no Vulkan device";
  const detail::Problem problem = featureBody(6, 3, 3, 0.1, 11);  // damped by mass and stiffness
  SolverDesc solver;
  solver.linearSolver = LinearSolverKind::Pcg;
  solver.precision = Precision::Float;
  detail::DeviceOptions options;
  options.vulkan.deviceStore = 1;
  const auto n = static_cast<std::size_t>(problem.restPositions.size());
  const auto calls = [&](bool deviceStore) {
    detail::DeviceSlot slot({&problem}, solver, {vulkan->resolve("")}, /*fallbackAtCreate=*/false, options);
    std::unique_ptr<detail::StepStore> store =
        deviceStore ? slot.device().createStepStore(slot) : detail::createHostStepStore(slot);
    EXPECT_NE(store, nullptr);
    store->setState(0, StateSlot::Committed, StateVec::X, problem.restPositions + 0.01 * randomVector(n, 5));
    store->setState(0, StateSlot::Committed, StateVec::V, 0.1 * randomVector(n, 6));
    for (StateVec z : {StateVec::A, StateVec::Fext, StateVec::Reaction}) store->setZero(0, StateSlot::Committed, z);
    // One Newton iteration of a step, as the driver makes it.
    const SchemeMaps maps = eulerMaps(1.0 / 60.0);
    slot.beginStep();
    store->begin({0}, {BeginArgs{maps, maps.h, 1.0, StateSlot::Committed}});
    store->positions({0}, {maps});
    store->setPositions(slot, {0}, StateSlot::Result);
    store->internalForces(slot, {0});
    store->damping(slot, {0}, StateSlot::Result);
    std::vector<detail::ResidualSums> sums;
    store->residual({0}, {maps}, sums);
    std::vector<detail::PcgSolve> solves(1);
    solves[0].coeffs = detail::SystemCoeffs{1.0, 1.0 / maps.ka, maps.kx / maps.ka};
    store->solve(slot, {0}, solves);
    EXPECT_TRUE(solves[0].failure.empty()) << solves[0].failure;
    EXPECT_GT(solves[0].stats.iterations, 0);
    slot.endStep();
    std::vector<long long> out;
    for (const detail::SlotCallStats& c : slot.stats().byCall) out.push_back(c.calls);
    return out;
  };
  const std::vector<long long> host = calls(false), device = calls(true);
  EXPECT_EQ(device, host);
  for (const auto call : {detail::SlotStats::SetPositions, detail::SlotStats::InternalForces, detail::SlotStats::Apply,
                          detail::SlotStats::Solve})
    EXPECT_EQ(device[call], 1) << detail::slotCallName(call);
}

/// A store's positions that cannot be read during a failover (its device lost): the read's own
/// failover request is refused, the failover goes on to the next candidate once, and the body
/// reaches it with no positions (its driver restarts it) instead of exhausting the candidates.
TEST(DeviceSlotPositionSource, AReadThatFailsDuringAFailoverMovesTheSlotOnce) {
  const auto reference = detail::findBackend("reference");
  ASSERT_NE(reference, nullptr);
  const detail::Problem problem = featureBody(2, 2, 2, 0.1, 3);
  SolverDesc solver;
  detail::DeviceSlot slot({&problem}, solver, {reference->resolve(""), reference->resolve(""), reference->resolve("")},
                          /*fallbackAtCreate=*/false);
  int reads = 0;
  const int owner = 0;
  slot.setPositionSource(&owner, [&](std::size_t, Eigen::VectorXd&) {
    ++reads;
    const detail::Error lost(ErrorCode::DeviceError, "a device lost on purpose");
    slot.failover("a read of the positions", lost);  // what a store's wait does on such an error
    throw lost;
  });
  slot.positionsSetElsewhere({0});
  ASSERT_NO_THROW(slot.failover("a test", detail::Error(ErrorCode::DeviceError, "the first error")));
  EXPECT_EQ(reads, 1);
  EXPECT_EQ(slot.failovers(), 1u);
  EXPECT_FALSE(slot.exhausted());
  std::vector<double> energy;
  slot.elasticEnergy({0}, energy);  // the new device works, at its own rest positions
  EXPECT_EQ(energy[0], 0.0);
  slot.dropPositionSource(&owner);
}

INSTANTIATE_TEST_SUITE_P(Stores, StepStoreContract, ::testing::ValuesIn(kStores),
                         [](const ::testing::TestParamInfo<StoreKind>& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace corofem

