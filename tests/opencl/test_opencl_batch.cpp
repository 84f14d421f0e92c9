// The OpenCL device of several bodies (createOpenCLBatchOn): different bodies in one set of buffers
// and launches, driven in rounds of requests (common/device_batch.hpp), each request compared with
// one single-body OpenCL device per body and with the reference backend, in each of OpenCL's
// configurations and strategies (tiles, one-launch iterations, teams, packs). A subset leaving the
// others untouched, bodies stopping on their own beside others and non-finite right-hand sides are
// tests/conformance/ (every backend's).
//
// Tolerances. Batch vs single backend: bit-identical, in double and in float. Both run the same
// kernels of the same program; a body's elements and nodes start at multiples of the work-group
// span, so every element sits in the same vector lane, every gather list has the same order and
// every dot product sums the body's own partials in the same fixed order (reduce_finish: one
// work-group per body); no arithmetic mixes two bodies. So any difference is a bug, not rounding.
// Batch vs reference: as tests/opencl/test_backend.cpp (double: forces 1e-10 relative to the
// largest entry, solutions cond(A) * tol ~ 1e-8; float: positions rounded to float give 1e-4 on
// forces, the float operator times cond(A) ~1e3 gives 1e-3 on solutions).
#include "backends/opencl/opencl_backend.hpp"
#include "backends/opencl/cpu_pcg.hpp"
#include "backends/opencl/segment_engine.hpp"
#include "common/opencl_test_access.hpp"
#include "common/shuffled_mesh.hpp"
#include "opencl/opencl_test_support.hpp"
#include "common/body_backend.hpp"
#include "common/device_batch.hpp"
#include "precond/amg.hpp"
#include "util/error.hpp"
#include "util/parallel.hpp"

#include <gtest/gtest.h>

namespace corofem::test::layout {
#include "../../kernels/shared/corofem_layout.h"
}  // namespace corofem::test::layout

#include <limits>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstdlib>
#include <mutex>
#include <random>
#include <set>
#include <thread>

namespace corofem {
namespace {

using test::sameBits;
using test::DeviceCase;
using test::BatchOp;
using test::BatchRequest;
using test::randomVector;

class BatchOnDevice;

/// The one-launch PCG iterations (detail::CpuPcgCounts) of every BatchOnDevice of the process so
/// far, those alive and those gone: what a test compares before and after a round.
class LaunchTotals {
 public:
  static LaunchTotals& get() {
    static LaunchTotals t;
    return t;
  }
  void add(const BatchOnDevice* b) {
    std::lock_guard<std::mutex> lock(m_);
    live_.insert(b);
  }
  void remove(const BatchOnDevice* b, const detail::CpuPcgCounts& c) {
    std::lock_guard<std::mutex> lock(m_);
    live_.erase(b);
    accumulate(gone_, c);
  }
  detail::CpuPcgCounts now();

 private:
  static void accumulate(detail::CpuPcgCounts& to, const detail::CpuPcgCounts& c) {
    to.groupLaunches += c.groupLaunches;
    to.teamLaunches += c.teamLaunches;
    to.packLaunches += c.packLaunches;
    to.packLanes += c.packLanes;
  }
  std::mutex m_;
  std::set<const BatchOnDevice*> live_;
  detail::CpuPcgCounts gone_;
};

/// Bodies on one OpenCL device, in rounds of requests, with the device and its engine in view.
class BatchOnDevice : public test::DeviceBatch {
 public:
  BatchOnDevice(detail::OpenCLBatch b, const SolverDesc& solver)
      : test::DeviceBatch(*b.device, solver), batch_(std::move(b)) {
    LaunchTotals::get().add(this);
  }
  ~BatchOnDevice() { LaunchTotals::get().remove(this, batch_.engine->pcgCounts()); }
  BatchOnDevice(const BatchOnDevice&) = delete;
  BatchOnDevice& operator=(const BatchOnDevice&) = delete;
  detail::CpuPcgCounts pcgCounts() const { return batch_.engine->pcgCounts(); }
  std::string name() const { return batch_.device->name(); }
  bool devicePositions(std::size_t body, detail::DevicePositions& out) const {
    return batch_.device->devicePositions(body, out);
  }
  detail::Device& device() { return *batch_.device; }
  detail::SegmentEngine& engine() { return *batch_.engine; }
  /// Bytes of device memory the device allocated (the sum of its buffers' sizes).
  std::size_t allocatedBytes() const {
    std::size_t bytes = 0;
    for (const detail::DeviceBuffer& b : batch_.device->buffers()) bytes += b.bytes;
    return bytes;
  }

 private:
  detail::OpenCLBatch batch_;
};

detail::CpuPcgCounts LaunchTotals::now() {
  std::lock_guard<std::mutex> lock(m_);
  detail::CpuPcgCounts sum = gone_;
  for (const BatchOnDevice* b : live_) accumulate(sum, b->pcgCounts());
  return sum;
}

unsigned long long groupPcgLaunchCount() { return LaunchTotals::get().now().groupLaunches; }
unsigned long long teamPcgLaunchCount() { return LaunchTotals::get().now().teamLaunches; }
unsigned long long packPcgLaunchCount() { return LaunchTotals::get().now().packLaunches; }
unsigned long long packPcgLaneCount() { return LaunchTotals::get().now().packLanes; }

/// The bodies `problems` on one device of `context`.
std::unique_ptr<BatchOnDevice> batchOn(const std::vector<const detail::Problem*>& problems, const SolverDesc& s,
                                       std::shared_ptr<detail::cl::Context> context, const detail::OpenCLTuning& o) {
  return std::make_unique<BatchOnDevice>(test::openclBatchOn(problems, s, std::move(context), o), s);
}

/// Five different bodies: different meshes (none a multiple of the work-group span), materials,
/// densities, Rayleigh coefficients, constraints and one linear formulation.
std::vector<detail::Problem> bodies() {
  std::vector<detail::Problem> out;
  auto clampBelow = [](detail::Problem& p, int axis, double limit, int components) {
    for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
      if (p.mesh.nodes[3 * n + axis] < limit)
        for (int k = 0; k < components; ++k) p.constrained[3 * n + k] = 1;
  };
  {  // 0: the beam of test_backend.cpp (192 tets), damped, clamped at x = 0
    detail::Problem p = test::makeProblem(test::cellBox(8, 2, 2, 0.25, 0.25, 0.25), 1e5, 0.45, 1000.0);
    p.name = "beam";
    p.rayleighMass = 0.2;
    p.rayleighStiffness = 0.01;
    clampBelow(p, 0, 1e-9, 3);
    out.push_back(std::move(p));
  }
  {  // 1: a stiff light slab (180 tets), no damping, x and y fixed on z = 0
    detail::Problem p = test::makeProblem(test::cellBox(5, 3, 2, 0.2, 0.3, 0.1), 3e6, 0.3, 500.0);
    p.name = "slab";
    clampBelow(p, 2, 1e-9, 2);
    out.push_back(std::move(p));
  }
  {  // 2: a soup of 37 free random tetrahedra (only the mass holds it)
    std::mt19937 rng(42);
    detail::Problem p = test::makeProblem(test::randomSoup(37, rng), 2e4, 0.2, 1500.0);
    p.name = "soup";
    p.rayleighMass = 0.05;
    out.push_back(std::move(p));
  }
  {  // 3: a linear cube (162 tets), mass damping only
    detail::Problem p = test::makeProblem(test::cellBox(3, 3, 3, 0.1, 0.1, 0.1), 1e6, 0.35, 800.0,
                                          Formulation::Linear);
    p.name = "linear-cube";
    p.rayleighMass = 0.1;
    clampBelow(p, 0, 1e-9, 3);
    out.push_back(std::move(p));
  }
  {  // 4: a long soft bar (600 tets: more than one element work-group on CPUs), stiffness damping
    detail::Problem p = test::makeProblem(test::cellBox(25, 2, 2, 0.1, 0.05, 0.05), 5e5, 0.4, 1200.0);
    p.name = "bar";
    p.rayleighStiffness = 0.02;
    clampBelow(p, 0, 1e-9, 3);
    out.push_back(std::move(p));
  }
  return out;
}

/// bodies() and, first, a block of 3,600 elements and 1,029 nodes clamped at x = 0: the only one
/// whose node phases span several chunks of 64 work-items (5), for the teams' chunk arithmetic and
/// hand-offs within a phase.
std::vector<detail::Problem> bodiesWithABlock() {
  std::vector<detail::Problem> out;
  detail::Problem p = test::makeProblem(test::cellBox(20, 6, 6, 0.1, 0.1, 0.1), 1e5, 0.45, 1000.0);
  p.name = "block";
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
    if (p.mesh.nodes[3 * n] < 1e-9)
      for (int k = 0; k < 3; ++k) p.constrained[3 * n + k] = 1;
  out.push_back(std::move(p));
  for (detail::Problem& b : bodies()) out.push_back(std::move(b));
  return out;
}

/// Copies of one mesh (a plate of 5 x 5 x 2 cells, 300 tets and 108 nodes: counts that are not
/// multiples of 8, so the packs' rows are padded; a last node chunk of its own), `count` of them,
/// each its own: a rest shape rotated and stretched differently (`rotated`; else only moved, so
/// that the Morton order of every copy is the same), material, density, Rayleigh coefficients and
/// constraints (clamped at x = 0, every third on one component only, one free body held by its
/// mass); every fourth linear. Then one body of another mesh (not packed) between them, so that the
/// packs' bodies are not consecutive segments.
std::vector<detail::Problem> instances(std::size_t count, bool rotated = true) {
  std::vector<detail::Problem> out;
  const TetMesh base = test::cellBox(5, 5, 2, 0.1, 0.08, 0.06);
  for (std::size_t i = 0; i < count; ++i) {
    TetMesh mesh = base;
    const Eigen::Matrix3d R = rotated ? Eigen::AngleAxisd(0.4 * static_cast<double>(i), Eigen::Vector3d(1, -1, 2).normalized())
                                            .toRotationMatrix()
                                      : Eigen::Matrix3d::Identity();
    const double stretch = rotated ? 1.0 + 0.07 * static_cast<double>(i % 5) : 1.0;
    for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
      Eigen::Vector3d X(mesh.nodes[3 * n] * stretch, mesh.nodes[3 * n + 1], mesh.nodes[3 * n + 2]);
      X = R * X + Eigen::Vector3d(0.5 * static_cast<double>(i), 0.0, 0.0);
      for (int k = 0; k < 3; ++k) mesh.nodes[3 * n + k] = X[k];
    }
    detail::Problem p = test::makeProblem(mesh, 1e5 * (1.0 + static_cast<double>(i)), 0.2 + 0.02 * static_cast<double>(i % 11),
                                          800.0 + 50.0 * static_cast<double>(i),
                                          i % 4 == 3 ? Formulation::Linear : Formulation::Corotational);
    p.name = "copy" + std::to_string(i);
    p.rayleighMass = i % 3 == 0 ? 0.1 * static_cast<double>(i) : 0.0;
    p.rayleighStiffness = i % 5 == 1 ? 0.01 : 0.0;
    if (i != 2)
      for (std::size_t n = 0; n < base.nodeCount(); ++n)
        if (base.nodes[3 * n] < 1e-9)
          for (int k = 0; k < (i % 3 == 1 ? 1 : 3); ++k) p.constrained[3 * n + k] = 1;
    out.push_back(std::move(p));
    if (i == 4) {
      detail::Problem other = test::makeProblem(test::cellBox(5, 3, 2, 0.2, 0.3, 0.1), 3e6, 0.3, 500.0);
      other.name = "slab";
      out.push_back(std::move(other));
    }
  }
  return out;
}

/// How many of `copies` bodies of one mesh a round packs when packs are forced: 8 to a pack, a
/// remainder of fewer than 3 (OpenCLTuning::packPcgMinLanes' default) in work-groups of their own.
std::size_t packedLanes(std::size_t copies) { return copies / 8 * 8 + (copies % 8 >= 3 ? copies % 8 : 0); }

/// Rotated, bent positions (a different rotation per body).
Eigen::VectorXd deformed(const detail::Problem& p, double angle) {
  Eigen::VectorXd x = p.restPositions;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(angle, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) {
    const Eigen::Vector3d X = p.restPositions.segment<3>(3 * n);
    const Eigen::Vector3d u(0.02 * X.y(), -0.15 * X.x() * X.x(), 0.05 * X.x() * X.z());
    x.segment<3>(3 * n) = R * (X + u) + Eigen::Vector3d(0.3, -0.1, 0.2);
  }
  return x;
}

double maxRel(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / std::max(b.cwiseAbs().maxCoeff(), 1e-300);
}

class OpenCLBatch : public ::testing::TestWithParam<DeviceCase> {
 protected:
  bool isDouble() const { return GetParam().precision == Precision::Double; }
  SolverDesc solver() const {
    SolverDesc s;
    s.precision = GetParam().precision;
    s.preconditioner = PreconditionerKind::BlockDiagonal;
    s.tolerance = isDouble() ? 1e-10 : 1e-5;
    s.maxIterations = 2000;
    s.checkEvery = 4;
    return s;
  }
  /// The solver with each precision of the device (and mixed where it has double), each
  /// preconditioner and iteration caps of 1, 2, 7 and 2,000: the one-launch paths' comparisons.
  std::vector<SolverDesc> pcgSettings() const {
    std::vector<Precision> precisions = {GetParam().precision};
    if (isDouble()) precisions.push_back(Precision::Mixed);  // float vectors, double sums
    std::vector<SolverDesc> out;
    for (Precision precision : precisions)
      for (PreconditionerKind preconditioner : {PreconditionerKind::None, PreconditionerKind::Diagonal,
                                                PreconditionerKind::BlockDiagonal, PreconditionerKind::Amg})
        for (int cap : {1, 2, 7, 2000}) {
          SolverDesc s = solver();
          s.precision = precision;
          s.preconditioner = preconditioner;
          s.maxIterations = cap;
          out.push_back(s);
        }
    return out;
  }
  static std::string describe(const SolverDesc& s) {
    return "cap " + std::to_string(s.maxIterations) + ", " + toString(s.precision) + ", preconditioner " +
           std::to_string(static_cast<int>(s.preconditioner));
  }
  std::shared_ptr<detail::cl::Context> context() const {
    return detail::cl::Context::shared(std::to_string(GetParam().device));
  }
  std::unique_ptr<BatchOnDevice> batchOf(const std::vector<detail::Problem>& ps, const SolverDesc& s,
                                               const detail::OpenCLTuning& o = {}) const {
    std::vector<const detail::Problem*> ptrs;
    for (const auto& p : ps) ptrs.push_back(&p);
    return batchOn(ptrs, s, context(), o);
  }
  std::vector<std::unique_ptr<detail::OpenCLBackendInternal>> singlesOf(const std::vector<detail::Problem>& ps,
                                                                        const SolverDesc& s,
                                                                        const detail::OpenCLTuning& o = {}) const {
    std::vector<std::unique_ptr<detail::OpenCLBackendInternal>> out;
    for (const auto& p : ps) out.push_back(test::openclOn(p, s, context(), o));
    return out;
  }
  void everyRequestMatches(const detail::OpenCLTuning& o, const std::vector<detail::Problem>& ps = bodies());
  /// Runs a round and expects no request to fail.
  static void runOk(test::DeviceBatch& device, std::vector<BatchRequest>& requests) {
    std::vector<BatchRequest*> round;
    for (auto& r : requests) round.push_back(&r);
    device.run(round);
    for (const auto& r : requests)
      if (r.error) {
        try {
          std::rethrow_exception(r.error);
        } catch (const std::exception& e) {
          ADD_FAILURE() << "body " << r.body << ": " << e.what();
        }
      }
  }
  static BatchRequest request(BatchOp op, std::size_t body, const Eigen::VectorXd* in = nullptr,
                              Eigen::VectorXd* out = nullptr, detail::SystemCoeffs c = {}) {
    return BatchRequest{op, body, c, in, out, {}, 0.0, nullptr};
  }
  /// Options whose every solve round runs one work-group per body (pcg_iterate_group; no teams),
  /// in the given numbering and node chunk, with packs (packPcg = 1) or without (0): the packs'
  /// tests compare the two.
  static detail::OpenCLTuning oneLaunchRounds(int packPcg, int localityOrder, std::size_t nodeChunk = 0) {
    detail::OpenCLTuning o;
    o.groupPcg = 1;
    o.teamPcg = 0;
    o.groupPcgSmallElements = 1 << 20;
    o.nodesPerItem = nodeChunk;
    o.localityOrder = localityOrder;
    o.packPcg = packPcg;
    return o;
  }
  /// The same solve, bit for bit: stops, iteration counts, residuals and x.
  static void expectSameSolve(const BatchRequest& a, const BatchRequest& b, const Eigen::VectorXd& xa,
                              const Eigen::VectorXd& xb) {
    EXPECT_EQ(a.stats.iterations, b.stats.iterations);
    EXPECT_EQ(a.stats.converged, b.stats.converged);
    EXPECT_EQ(a.stats.relativeResidual, b.stats.relativeResidual);
    EXPECT_TRUE(sameBits(xa, xb)) << "max rel. difference " << maxRel(xa, xb);
  }
  /// For the rules' tests: bent positions (`set`) and random right-hand sides (seeds seed + i) of
  /// the bodies, and which path a solve round takes.
  struct RoundPaths {
    std::vector<Eigen::VectorXd> x, rhs, sol;
    std::vector<BatchRequest> set;
    RoundPaths(const std::vector<detail::Problem>& ps, unsigned seed) : x(ps.size()), rhs(ps.size()), sol(ps.size()) {
      for (std::size_t i = 0; i < ps.size(); ++i) {
        x[i] = deformed(ps[i], 0.4);
        rhs[i] = randomVector(ps[i].dofCount(), seed + static_cast<unsigned>(i));
        set.push_back(request(BatchOp::SetPositions, i, &x[i]));
      }
    }
    /// Solves the bodies `who` from zero on `batch` (positions set): 2 when their iterations ran
    /// in teams (pcg_iterate_team), 1 in one work-group per body (pcg_iterate_group) or in packs
    /// (pcg_iterate_pack, which such rounds take for bodies of one mesh), 0 launched.
    int path(test::DeviceBatch& batch, const std::vector<std::size_t>& who) {
      std::vector<BatchRequest> round;
      for (std::size_t i : who) {
        sol[i] = Eigen::VectorXd::Zero(rhs[i].size());
        round.push_back(request(BatchOp::Solve, i, &rhs[i], &sol[i], {900.0, 30.0, 1.0}));
      }
      const unsigned long long team = teamPcgLaunchCount(), group = groupPcgLaunchCount(),
                               pack = packPcgLaunchCount();
      runOk(batch, round);
      return teamPcgLaunchCount() > team                                                   ? 2
             : groupPcgLaunchCount() > group || packPcgLaunchCount() > pack ? 1
                                                                                             : 0;
    }
  };
};

/// Every request type for every body (one round per type, then one round of mixed types),
/// batch vs one single backend per body (same options) vs the reference.
void OpenCLBatch::everyRequestMatches(const detail::OpenCLTuning& o, const std::vector<detail::Problem>& ps) {
  const std::size_t K = ps.size();
  const SolverDesc s = solver();
  auto batch = batchOf(ps, s, o);
  ASSERT_EQ(batch->bodyCount(), K);
  EXPECT_EQ(batch->name(), "opencl");
  auto singles = singlesOf(ps, s, o);
  std::vector<std::unique_ptr<test::Backend>> refs;
  std::vector<Eigen::VectorXd> x(K), v(K), b(K);
  for (std::size_t i = 0; i < K; ++i) {
    refs.push_back(test::createReferenceBackend(ps[i], s));
    x[i] = deformed(ps[i], 0.3 + 0.4 * static_cast<double>(i));
    v[i] = randomVector(ps[i].dofCount(), 100 + static_cast<unsigned>(i));
    b[i] = randomVector(ps[i].dofCount(), 200 + static_cast<unsigned>(i));
    singles[i]->setPositions(x[i]);
    refs[i]->setPositions(x[i]);
  }
  {
    std::vector<BatchRequest> round;
    for (std::size_t i = 0; i < K; ++i) round.push_back(request(BatchOp::SetPositions, i, &x[i]));
    runOk(*batch, round);
  }
  const double tolRef = isDouble() ? 1e-10 : 1e-4;
  // Forces and energies of every body in one round each.
  {
    std::vector<Eigen::VectorXd> f(K);
    std::vector<BatchRequest> round;
    for (std::size_t i = 0; i < K; ++i) round.push_back(request(BatchOp::InternalForces, i, nullptr, &f[i]));
    runOk(*batch, round);
    for (std::size_t i = 0; i < K; ++i) {
      Eigen::VectorXd fs, fr;
      singles[i]->internalForces(fs);
      refs[i]->internalForces(fr);
      EXPECT_TRUE(sameBits(f[i], fs)) << ps[i].name << ": max rel. difference " << maxRel(f[i], fs);
      EXPECT_LE(maxRel(f[i], fr), tolRef) << ps[i].name;
    }
  }
  {
    std::vector<BatchRequest> round;
    for (std::size_t i = 0; i < K; ++i) round.push_back(request(BatchOp::ElasticEnergy, i));
    runOk(*batch, round);
    for (std::size_t i = 0; i < K; ++i) {
      EXPECT_EQ(round[i].energy, singles[i]->elasticEnergy()) << ps[i].name;
      EXPECT_NEAR(round[i].energy, refs[i]->elasticEnergy(), tolRef * refs[i]->elasticEnergy()) << ps[i].name;
    }
  }
  // Products with each body's own coefficients (Newmark-like, static, mass only).
  const detail::SystemCoeffs coeffs[3] = {{14400.0, 120.0, 1.0}, {0.0, 0.0, 1.0}, {1.0, 0.0, 0.0}};
  {
    std::vector<Eigen::VectorXd> y(K);
    std::vector<BatchRequest> round;
    for (std::size_t i = 0; i < K; ++i) round.push_back(request(BatchOp::Apply, i, &v[i], &y[i], coeffs[i % 3]));
    runOk(*batch, round);
    for (std::size_t i = 0; i < K; ++i) {
      Eigen::VectorXd ys, yr;
      singles[i]->apply(coeffs[i % 3], v[i], ys);
      refs[i]->apply(coeffs[i % 3], v[i], yr);
      EXPECT_TRUE(sameBits(y[i], ys)) << ps[i].name << ": max rel. difference " << maxRel(y[i], ys);
      EXPECT_LE(maxRel(y[i], yr), tolRef) << ps[i].name;
    }
  }
  // Solves (dynamic systems: the soup is held only by its mass).
  {
    std::vector<Eigen::VectorXd> sol(K);
    std::vector<BatchRequest> round;
    const detail::SystemCoeffs dyn[2] = {{14400.0, 120.0, 1.0}, {900.0, 30.0, 1.0}};
    for (std::size_t i = 0; i < K; ++i) {
      sol[i] = Eigen::VectorXd::Constant(b[i].size(), 0.001);  // warm start
      round.push_back(request(BatchOp::Solve, i, &b[i], &sol[i], dyn[i % 2]));
    }
    runOk(*batch, round);
    for (std::size_t i = 0; i < K; ++i) {
      Eigen::VectorXd xs = Eigen::VectorXd::Constant(b[i].size(), 0.001), xr = Eigen::VectorXd::Zero(b[i].size());
      const detail::LinearSolveStats st = singles[i]->solve(dyn[i % 2], b[i], xs);
      refs[i]->solve(dyn[i % 2], b[i], xr);
      EXPECT_TRUE(round[i].stats.converged) << ps[i].name;
      EXPECT_EQ(round[i].stats.iterations, st.iterations) << ps[i].name;
      EXPECT_EQ(round[i].stats.relativeResidual, st.relativeResidual) << ps[i].name;
      EXPECT_TRUE(sameBits(sol[i], xs)) << ps[i].name << ": max rel. difference " << maxRel(sol[i], xs);
      EXPECT_LE((sol[i] - xr).norm() / xr.norm(), isDouble() ? 1e-8 : 1e-3) << ps[i].name;
      for (std::size_t d = 0; d < ps[i].dofCount(); ++d)
        if (ps[i].constrained[d]) EXPECT_EQ(sol[i][static_cast<Eigen::Index>(d)], 0.0);
    }
  }
  // One round of mixed requests: every op at once, each body its own.
  {
    Eigen::VectorXd x2 = deformed(ps[0], -0.7), y1, f3, sol2 = Eigen::VectorXd::Zero(b[2].size());
    std::vector<BatchRequest> round = {request(BatchOp::SetPositions, 0, &x2),
                                       request(BatchOp::Apply, 1, &v[1], &y1, coeffs[0]),
                                       request(BatchOp::Solve, 2, &b[2], &sol2, coeffs[0]),
                                       request(BatchOp::InternalForces, 3, nullptr, &f3),
                                       request(BatchOp::ElasticEnergy, 4)};
    runOk(*batch, round);
    singles[0]->setPositions(x2);
    Eigen::VectorXd ys, fs, xs = Eigen::VectorXd::Zero(b[2].size());
    singles[1]->apply(coeffs[0], v[1], ys);
    singles[2]->solve(coeffs[0], b[2], xs);
    singles[3]->internalForces(fs);
    EXPECT_TRUE(sameBits(y1, ys));
    EXPECT_TRUE(sameBits(sol2, xs));
    EXPECT_TRUE(sameBits(f3, fs));
    EXPECT_EQ(round[4].energy, singles[4]->elasticEnergy());
    // Body 0's new positions took effect.
    Eigen::VectorXd f0, fs0;
    std::vector<BatchRequest> forces = {request(BatchOp::InternalForces, 0, nullptr, &f0)};
    runOk(*batch, forces);
    singles[0]->internalForces(fs0);
    EXPECT_TRUE(sameBits(f0, fs0));
  }
}

TEST_P(OpenCLBatch, EveryRequestMatchesOneBackendPerBodyAndTheReference) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  everyRequestMatches({});  // the device's default configuration (CPUs: 8 elements per item, chunks of 4 nodes)
}

TEST_P(OpenCLBatch, BodiesInTheMeshsNumberingAndInTheDevicesOwnMatchToo) {
  // By default the device numbers a body in a Morton order of its own only where the mesh's
  // numbering is less local (mesh/locality_order.hpp): here the five bodies keep theirs and a
  // shuffled copy of the first is reordered, in one batch (segments in both numberings side by side).
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::vector<detail::Problem> ps = bodies();
  detail::Problem shuffled = test::makeProblem(test::shuffledMesh(ps[0].mesh, 17), 1e5, 0.45, 1000.0);
  shuffled.name = "shuffled-beam";
  shuffled.rayleighMass = 0.2;
  for (std::size_t n = 0; n < shuffled.mesh.nodeCount(); ++n)
    if (shuffled.mesh.nodes[3 * n] < 1e-9)
      for (int k = 0; k < 3; ++k) shuffled.constrained[3 * n + k] = 1;
  ps.insert(ps.begin() + 2, std::move(shuffled));
  std::vector<const detail::Problem*> ptrs;
  for (const detail::Problem& p : ps) ptrs.push_back(&p);
  auto batch = batchOn(ptrs, solver(), context(), {});
  std::size_t reordered = 0;
  for (std::size_t i = 0; i < ps.size(); ++i) {
    detail::DevicePositions where;
    ASSERT_TRUE(batch->devicePositions(i, where));
    reordered += where.deviceNode != nullptr;
  }
  if (!test::mortonEverywhere()) EXPECT_EQ(reordered, 1u);
  everyRequestMatches({}, ps);
}

TEST_P(OpenCLBatch, GpuKernelConfigurationMatchesToo) {
  // One element per work-item, one node per PCG work-item and work-group tree reductions (the
  // GPU configuration: partials per work-group, segments aligned to 32 nodes and 32 elements),
  // here on whatever device is present.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  detail::OpenCLTuning o;
  o.workGroupSize = 32;
  o.elementsPerItem = 1;
  o.nodesPerItem = 1;
  o.workGroupSums = 1;
  everyRequestMatches(o);
}

TEST_P(OpenCLBatch, TilesOfOneBodyMatchToo) {
  // CPUs run the requesting bodies in tiles that fit the cache; a 1-byte budget makes every body
  // its own tile (one launch sequence per body, per-tile transfers): the same answers.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  detail::OpenCLTuning o;
  o.tileBytes = 1;
  everyRequestMatches(o);
}

TEST_P(OpenCLBatch, LaunchedIterationsMatchToo) {
  // CPUs run the PCG iterations of rounds of small bodies in one launch (pcg_iterate_group); the
  // launched iterations, which larger bodies and GPUs take, give the same answers.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  detail::OpenCLTuning o;
  o.groupPcg = 0;
  everyRequestMatches(o);
}

// The CPU tile budget (tuning.hpp; docs/performance.md: measured on 8 and 32 MiB L3s): 8 MiB where the cache
// holds it, the whole cache below that, a quarter of it above 32 MiB.
TEST(OpenCLBatchTiles, DefaultTileBytesFollowsTheCache) {
  constexpr std::size_t MiB = std::size_t{1} << 20;
  EXPECT_EQ(detail::defaultTileBytes(0), 0u);  // no cache reported: one tile
  EXPECT_EQ(detail::defaultTileBytes(2 * MiB), 2 * MiB);
  EXPECT_EQ(detail::defaultTileBytes(8 * MiB), 8 * MiB);
  EXPECT_EQ(detail::defaultTileBytes(16 * MiB), 8 * MiB);
  EXPECT_EQ(detail::defaultTileBytes(32 * MiB), 8 * MiB);
  EXPECT_EQ(detail::defaultTileBytes(96 * MiB), 24 * MiB);
}

// Frames of every body in one batch: positions, forces, a solve. The even bodies warm-start each
// solve from their previous solution (so internalForces queues their A x behind the forces' read,
// for only some of the round's bodies, with its own segment table and coefficient uploads); the odd
// ones start from zero. Every solution and count equals the body's own backend's, bit for bit, in
// both the default and the one-body-per-tile configurations.
TEST_P(OpenCLBatch, WarmAndColdStartsInOneRoundMatchEachBodyAlone) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const std::vector<detail::Problem> ps = bodies();
  const std::size_t K = ps.size();
  // The node blocks capped (each answer depends on its start and on A x), the multigrid to its
  // tolerance (the bodies stop at different iterations while the coarse levels of all run on) and
  // the warped factor to its tolerance (applied on the host to the running bodies between launches).
  // tileBytes 2: the GPU configuration (work-group sums; amg's coarse products a row per work-item;
  // the warped factor's r . z in the first of a body's work-group partials).
  for (PreconditionerKind pc : {PreconditionerKind::BlockDiagonal, PreconditionerKind::Amg, PreconditionerKind::WarpedCholesky})
  for (std::size_t tileBytes : {std::size_t{0}, std::size_t{1}, std::size_t{2}}) {
    const bool toTolerance = pc != PreconditionerKind::BlockDiagonal;
    SolverDesc s = solver();
    s.preconditioner = pc;
    s.maxIterations = toTolerance ? 60 : 10;
    if (!toTolerance) s.tolerance = 1e-14;
    detail::OpenCLTuning o;
    if (tileBytes == 1) o.tileBytes = 1;
    if (tileBytes == 2) {
      if (!toTolerance) continue;
      o.workGroupSize = 32;
      o.elementsPerItem = 1;
      o.nodesPerItem = 1;
      o.workGroupSums = 1;
    }
    auto batch = batchOf(ps, s, o);
    auto singles = singlesOf(ps, s, o);
    std::vector<Eigen::VectorXd> sol(K), alone(K);
    for (std::size_t i = 0; i < K; ++i) sol[i] = alone[i] = Eigen::VectorXd::Zero(ps[i].dofCount());
    for (int frame = 0; frame < 4; ++frame) {
      std::vector<Eigen::VectorXd> x(K), b(K), f(K);
      std::vector<BatchRequest> set, forces, solves;
      const detail::SystemCoeffs c = frame < 2 ? detail::SystemCoeffs{14400.0, 120.0, 1.0}
                                               : detail::SystemCoeffs{3600.0, 60.0, 1.0};
      for (std::size_t i = 0; i < K; ++i) {
        x[i] = deformed(ps[i], 0.2 * frame + 0.3 * static_cast<double>(i));
        b[i] = randomVector(ps[i].dofCount(), 300 + 10 * static_cast<unsigned>(frame) + static_cast<unsigned>(i));
        if (i % 2 == 1) sol[i].setZero(), alone[i].setZero();
      }
      for (std::size_t i = 0; i < K; ++i) set.push_back(request(BatchOp::SetPositions, i, &x[i]));
      for (std::size_t i = 0; i < K; ++i) forces.push_back(request(BatchOp::InternalForces, i, nullptr, &f[i]));
      for (std::size_t i = 0; i < K; ++i) solves.push_back(request(BatchOp::Solve, i, &b[i], &sol[i], c));
      runOk(*batch, set);
      runOk(*batch, forces);
      runOk(*batch, solves);
      for (std::size_t i = 0; i < K; ++i) {
        Eigen::VectorXd fs;
        singles[i]->setPositions(x[i]);
        singles[i]->internalForces(fs);
        const detail::LinearSolveStats st = singles[i]->solve(c, b[i], alone[i]);
        EXPECT_TRUE(sameBits(f[i], fs)) << ps[i].name << ", frame " << frame;
        EXPECT_TRUE(sameBits(sol[i], alone[i])) << ps[i].name << ", frame " << frame << ", tiles " << tileBytes
                                                << ", " << toString(pc) << ": max rel. difference "
                                                << maxRel(sol[i], alone[i]);
        EXPECT_EQ(solves[i].stats.iterations, st.iterations) << ps[i].name << ", frame " << frame;
        EXPECT_EQ(solves[i].stats.relativeResidual, st.relativeResidual) << ps[i].name << ", frame " << frame;
        if (toTolerance)  // to its tolerance well inside the cap, in every configuration
          EXPECT_TRUE(st.converged) << ps[i].name << ", frame " << frame << ", configuration " << tileBytes << ": "
                                    << st.iterations << " iterations, residual " << st.relativeResidual;
      }
    }
  }
}

TEST_P(OpenCLBatch, OneLaunchIterationsGiveTheLaunchedIterationsBits) {
  // pcg_iterate_group (a work-group per body, every iteration in one launch; CPU devices) and
  // pcg_iterate_team (a team of work-groups per body, handing out the phases' chunks by atomic
  // tickets; CPU devices) against the launched iterations (4 kernels per iteration) on the same
  // bodies: the same x, iteration counts and residuals, bit for bit, whether the bodies converge
  // (each at its own iteration), stop at a cap of 1, 2 or 7 iterations, start cold or warm; with
  // no, diagonal (on CPUs the update's 4-wide vector branch) and block preconditioners, and in
  // mixed precision too. Teams of 2, 3 and 8 work-groups: 8 is more than this machine's cores, so
  // some groups start only after others have done the work (the late group's path). The work-groups
  // of pcg_iterate_group take the bodies in turn: one of them takes them all in a further way.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const std::vector<detail::Problem> ps = bodies();
  const std::size_t K = ps.size();
  // Per-item partials (the CPU configuration) on every device: on a GPU this checks the group
  // kernel's barriers and fences on real hardware (PoCL runs each barrier as a full split,
  // whatever its flags). Teams are for CPU devices only (their hand-offs need coherent caches).
  detail::OpenCLTuning grouped, launched;
  grouped.workGroupSums = launched.workGroupSums = 0;
  grouped.groupPcg = 1;
  grouped.teamPcg = 0;
  grouped.groupPcgSmallElements = 1 << 20;  // every round takes it, whatever the device's cores
  launched.groupPcg = 0;
  struct Way {
    std::string name;
    detail::OpenCLTuning options;
    unsigned long long (*launches)();
  };
  // A work-group per compute unit takes the bodies in turn from a claim word; with one, it takes
  // every body, one after the other.
  detail::OpenCLTuning single = grouped;
  single.claimWorkGroups = 1;
  std::vector<Way> ways = {{"one work-group per body", grouped, &groupPcgLaunchCount},
                           {"one work-group taking every body in turn", single, &groupPcgLaunchCount}};
  if (context()->info().cpu)
    for (std::size_t team : {2, 3, 8}) {
      detail::OpenCLTuning t = grouped;
      t.teamPcg = 1;
      t.teamPcgSize = team;
      ways.push_back({"teams of " + std::to_string(team), t, &teamPcgLaunchCount});
    }
  const detail::SystemCoeffs dyn[2] = {{14400.0, 120.0, 1.0}, {900.0, 30.0, 1.0}};
  for (const SolverDesc& s : pcgSettings()) {
    const int cap = s.maxIterations;
    auto b = batchOf(ps, s, launched);
    std::vector<Eigen::VectorXd> x(K), rhs(K), xb(K);
    std::vector<BatchRequest> setB, solveB;
    for (std::size_t i = 0; i < K; ++i) {
      x[i] = deformed(ps[i], 0.2 + 0.3 * static_cast<double>(i));
      rhs[i] = randomVector(ps[i].dofCount(), 300 + static_cast<unsigned>(i));
      xb[i] = i % 2 ? Eigen::VectorXd::Constant(rhs[i].size(), 1e-3) : Eigen::VectorXd::Zero(rhs[i].size());
      setB.push_back(request(BatchOp::SetPositions, i, &x[i]));
    }
    runOk(*b, setB);
    for (std::size_t i = 0; i < K; ++i) solveB.push_back(request(BatchOp::Solve, i, &rhs[i], &xb[i], dyn[i % 2]));
    const unsigned long long launchedBefore = groupPcgLaunchCount() + teamPcgLaunchCount();
    runOk(*b, solveB);
    EXPECT_EQ(groupPcgLaunchCount() + teamPcgLaunchCount(), launchedBefore)
        << "the launched path took it";
    for (const Way& way : ways) {
      auto a = batchOf(ps, s, way.options);
      std::vector<Eigen::VectorXd> xa(K);
      std::vector<BatchRequest> setA, solveA;
      for (std::size_t i = 0; i < K; ++i) {
        xa[i] = i % 2 ? Eigen::VectorXd::Constant(rhs[i].size(), 1e-3) : Eigen::VectorXd::Zero(rhs[i].size());
        setA.push_back(request(BatchOp::SetPositions, i, &x[i]));
      }
      runOk(*a, setA);
      for (std::size_t i = 0; i < K; ++i) solveA.push_back(request(BatchOp::Solve, i, &rhs[i], &xa[i], dyn[i % 2]));
      const unsigned long long before = way.launches();
      runOk(*a, solveA);
      // The multigrid's cycle runs between launched kernels: its rounds take no one-launch path,
      // whatever the tuning asks (and give the launched bits).
      const bool oneLaunch = s.preconditioner != PreconditionerKind::Amg;
      if (cap > 1) EXPECT_EQ(way.launches(), before + (oneLaunch ? 1 : 0)) << way.name << ": one launch for the round's iterations";
      for (std::size_t i = 0; i < K; ++i) {
        SCOPED_TRACE(way.name + ", " + ps[i].name + ", " + describe(s));
        expectSameSolve(solveA[i], solveB[i], xa[i], xb[i]);
        if (cap < 2000) EXPECT_LE(solveA[i].stats.iterations, cap);
        else EXPECT_TRUE(solveA[i].stats.converged);
      }
      if (cap < 2000 && (s.preconditioner != PreconditionerKind::Amg || cap < 4))  // amg: 4 iterations in float
        EXPECT_EQ(solveA[0].stats.iterations, cap) << "the beam is meant to reach the cap";
    }
  }
}

TEST_P(OpenCLBatch, PacksGiveTheOneWorkGroupIterationsBits) {
  // pcg_iterate_pack (bodies of one mesh in the vector lanes of one work-item) against
  // pcg_iterate_group (a work-group per body) on 11 copies of one mesh and a body of another: a
  // full pack of 8 and one of 3 (5 empty lanes), the other body in its own work-group. The same x,
  // iteration counts and residuals, bit for bit, whether the bodies converge (each at its own
  // iteration: their lanes then stand still while the others go on), stop at a cap of 1, 2 or 7
  // iterations, start cold or warm; with no, diagonal and block preconditioners, in mixed precision
  // too; in two rounds on one batch (the second packs the bodies by their first round's
  // iterations), the second with 9 copies only (a pack of 8, the ninth in a work-group). Four
  // variants: rotated and stretched copies in their own numbering; the same with node chunks of 3
  // (the update's partial sums in the scalar order); static bodies (no mass buffer); copies only
  // moved, in the Morton order (every copy the same order, so they pack). The packed lanes are
  // counted, so a round that quietly left its bodies to pcg_iterate_group fails too. Two variants
  // launch the packs in one work-group, which then takes both slots in turn from the claim word.
  // (The double case runs the first three variants.)
  COROFEM_SKIP_IN_MORTON_REPEAT();
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  if (!context()->info().cpu) GTEST_SKIP() << "packs run where pcg_iterate_group runs: CPU devices";
  struct Variant {
    std::string name;
    std::vector<detail::Problem> bodies;
    std::size_t chunk;  ///< 3: with the diagonal preconditioner only (where the chunk picks the
                        ///< update's branch; another build of the program per precision)
    int order;
    bool dynamic;
    std::size_t takers;  ///< pcg_iterate_pack's work-groups (1: one takes both slots in turn)
  };
  std::vector<detail::Problem> still = instances(11);
  for (detail::Problem& p : still) p.lumpedMass.setZero();  // how a static problem looks to the engine
  const std::vector<Variant> variants = {{"rotated copies", instances(11), 0, 0, true, 0},
                                         {"node chunks of 3", instances(11), 3, 0, true, 1},
                                         {"static", still, 0, 0, false, 1},
                                         {"moved copies, Morton order", instances(11, false), 0, 1, true, 0}};
  for (const Variant& variant : variants) {
    // The double case (double and mixed programs, the only place the mixed pack runs) leaves out
    // the Morton order's variant, which changes the bodies' numbering, not the programs: float
    // runs it.
    if (isDouble() && variant.order == 1) continue;
    const std::vector<detail::Problem>& ps = variant.bodies;
    const std::size_t K = ps.size();
    detail::OpenCLTuning packed = oneLaunchRounds(1, variant.order, variant.chunk);
    const detail::OpenCLTuning grouped = oneLaunchRounds(0, variant.order, variant.chunk);
    packed.claimWorkGroups = variant.takers;
    const detail::SystemCoeffs dyn[2] = {{14400.0, 120.0, 1.0}, {900.0, 30.0, 1.0}};
    const detail::SystemCoeffs stat{0.0, 0.0, 1.0};
    for (const SolverDesc& s : pcgSettings()) {
      if (variant.chunk == 3 && s.preconditioner != PreconditionerKind::Diagonal) continue;
      const int cap = s.maxIterations;
      auto a = batchOf(ps, s, packed), b = batchOf(ps, s, grouped);
      // Rounds 0 and 1 mix zero and nonzero starts; round 2 starts every body at x = 0, where the
      // packs form the whole set-up themselves (node blocks, M^-1, pcg_init: pcg_iterate_pack's `fresh`).
      for (int round = 0; round < 3; ++round) {
        std::vector<std::size_t> who;
        std::size_t copies = 0;
        for (std::size_t i = 0; i < K; ++i)
          if (round == 0 || i % 4 != 1) {
            who.push_back(i);
            copies += ps[i].name != "slab" ? 1 : 0;
          }
        std::vector<Eigen::VectorXd> x(K), rhs(K), xa(K), xb(K);
        std::vector<BatchRequest> setA, setB, solveA, solveB;
        for (std::size_t i : who) {
          x[i] = deformed(ps[i], 0.2 + 0.3 * static_cast<double>(i) + 0.1 * round);
          rhs[i] = randomVector(ps[i].dofCount(), 900 + 20 * static_cast<unsigned>(round) + static_cast<unsigned>(i));
          xa[i] = xb[i] = round < 2 && (i + round) % 2 ? Eigen::VectorXd::Constant(rhs[i].size(), 1e-3)
                                                        : Eigen::VectorXd::Zero(rhs[i].size());
          setA.push_back(request(BatchOp::SetPositions, i, &x[i]));
          setB.push_back(request(BatchOp::SetPositions, i, &x[i]));
        }
        runOk(*a, setA);
        runOk(*b, setB);
        for (std::size_t i : who) {
          const detail::SystemCoeffs c = variant.dynamic ? dyn[(i + round) % 2] : stat;
          solveA.push_back(request(BatchOp::Solve, i, &rhs[i], &xa[i], c));
          solveB.push_back(request(BatchOp::Solve, i, &rhs[i], &xb[i], c));
        }
        const unsigned long long packsBefore = packPcgLaunchCount(), lanesBefore = packPcgLaneCount();
        runOk(*a, solveA);
        if (cap > 1 && s.preconditioner != PreconditionerKind::Amg) {  // amg: launched iterations only
          EXPECT_EQ(packPcgLaunchCount(), packsBefore + 1) << variant.name << ": the packs' iterations in one launch";
          EXPECT_EQ(packPcgLaneCount(), lanesBefore + packedLanes(copies)) << variant.name << ", round " << round;
        } else if (s.preconditioner == PreconditionerKind::Amg) {
          EXPECT_EQ(packPcgLaunchCount(), packsBefore) << variant.name << ": amg took the packs";
        }
        const unsigned long long noPacks = packPcgLaunchCount();
        runOk(*b, solveB);
        EXPECT_EQ(packPcgLaunchCount(), noPacks) << "packPcg = 0 took the packs";
        for (std::size_t j = 0; j < who.size(); ++j) {
          const std::size_t i = who[j];
          SCOPED_TRACE(variant.name + ", " + ps[i].name + ", round " + std::to_string(round) + ", " + describe(s));
          expectSameSolve(solveA[j], solveB[j], xa[i], xb[i]);
          // Static: the bodies held on one component, or not at all, are singular without mass
          // (they end at the cap or break down, in both ways alike).
          if (cap == 2000 && variant.dynamic) EXPECT_TRUE(solveA[j].stats.converged);
        }
      }
    }
  }
}

TEST_P(OpenCLBatch, PackedBodiesConvergeAtTheCapsLastIterationAsInWorkGroups) {
  // The cap's last iteration runs launched, on the vectors pack_out copied back: its update reads
  // p, u, s and w, and only its recurrence residual r (from s and w) decides whether a body that
  // reaches the cap converged there. With the cap at the iteration where one body converges
  // (found by an uncapped solve), that body must be reported converged at the cap, with the other
  // bodies' stops, x and residuals the work-groups' bit for bit (a pack_out that left a block of w
  // stale passed PacksGiveTheOneWorkGroupIterationsBits, whose caps never met a convergence).
  COROFEM_SKIP_IN_MORTON_REPEAT();
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  if (!context()->info().cpu) GTEST_SKIP() << "packs run where pcg_iterate_group runs: CPU devices";
  const std::vector<detail::Problem> ps = instances(11);
  const std::size_t K = ps.size();
  // The mesh's own numbering, so that the rotated copies pack (their Morton orders differ).
  const detail::OpenCLTuning packed = oneLaunchRounds(1, 0), grouped = oneLaunchRounds(0, 0);
  const detail::SystemCoeffs c{900.0, 30.0, 1.0};
  std::vector<Eigen::VectorXd> x(K), rhs(K);
  for (std::size_t i = 0; i < K; ++i) {
    x[i] = deformed(ps[i], 0.25 + 0.3 * static_cast<double>(i));
    rhs[i] = randomVector(ps[i].dofCount(), 1700 + static_cast<unsigned>(i));
  }
  // Solves every body on a batch with the given options and cap: the requests (stats) and the x.
  auto solveAll = [&](const detail::OpenCLTuning& o, int cap, std::vector<Eigen::VectorXd>& sol) {
    SolverDesc s = solver();
    s.preconditioner = PreconditionerKind::Diagonal;
    s.maxIterations = cap;
    auto batch = batchOf(ps, s, o);
    std::vector<BatchRequest> set, solves;
    sol.assign(K, Eigen::VectorXd());
    for (std::size_t i = 0; i < K; ++i) {
      sol[i] = Eigen::VectorXd::Zero(rhs[i].size());
      set.push_back(request(BatchOp::SetPositions, i, &x[i]));
    }
    runOk(*batch, set);
    for (std::size_t i = 0; i < K; ++i) solves.push_back(request(BatchOp::Solve, i, &rhs[i], &sol[i], c));
    runOk(*batch, solves);
    return solves;
  };
  std::vector<Eigen::VectorXd> free;
  const std::vector<BatchRequest> uncapped = solveAll(grouped, 2000, free);
  std::vector<int> counts;
  for (const BatchRequest& r : uncapped) {
    ASSERT_TRUE(r.stats.converged);
    counts.push_back(r.stats.iterations);
  }
  std::sort(counts.begin(), counts.end());
  const int cap = counts[counts.size() / 2];  // some copies converge before, at or after it
  ASSERT_GE(cap, 3) << "the pack must run iterations before the cap's last";
  std::vector<Eigen::VectorXd> xa, xb;
  const unsigned long long lanesBefore = packPcgLaneCount();
  const std::vector<BatchRequest> a = solveAll(packed, cap, xa);
  EXPECT_GT(packPcgLaneCount(), lanesBefore) << "the copies ran in packs";
  const std::vector<BatchRequest> b = solveAll(grouped, cap, xb);
  int atCap = 0;
  for (std::size_t i = 0; i < K; ++i) {
    SCOPED_TRACE(ps[i].name + ", cap " + std::to_string(cap));
    expectSameSolve(a[i], b[i], xa[i], xb[i]);
    atCap += uncapped[i].stats.iterations == cap && b[i].stats.converged ? 1 : 0;
  }
  EXPECT_GE(atCap, 1) << "a body converges at the cap's last iteration";
}

TEST_P(OpenCLBatch, UnpackedBodyStoppedAtTheSetUpStaysStoppedBesidePacks) {
  // In a round with packs the host launches the set-up (product, reduce_finish) for the unpacked
  // bodies only, and pcg_iterate_pack marks its own lanes running. A body that reduce_finish stops
  // at the set-up (here the slab, warm-started at x0 with b = A x0, so r = 0) must stay stopped: a
  // first version uploaded the segment table after that set-up to restore the packed bodies' flags,
  // which revived the slab for an iteration (a review caught it). Every body as with packPcg = 0,
  // bit for bit.
  COROFEM_SKIP_IN_MORTON_REPEAT();
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  if (!context()->info().cpu) GTEST_SKIP() << "packs run where pcg_iterate_group runs: CPU devices";
  const std::vector<detail::Problem> ps = instances(11);
  const std::size_t K = ps.size();
  // The mesh's own numbering, so that the copies pack.
  const detail::OpenCLTuning packed = oneLaunchRounds(1, 0), grouped = oneLaunchRounds(0, 0);
  const detail::SystemCoeffs c{900.0, 30.0, 1.0};
  for (PreconditionerKind pc : {PreconditionerKind::Diagonal, PreconditionerKind::BlockDiagonal}) {
    SolverDesc s = solver();
    s.preconditioner = pc;
    auto run = [&](const detail::OpenCLTuning& o, std::vector<Eigen::VectorXd>& sol) {
      auto batch = batchOf(ps, s, o);
      std::vector<Eigen::VectorXd> x(K), rhs(K), x0(K);
      std::vector<BatchRequest> set, apply, solves;
      std::size_t slab = K;
      for (std::size_t i = 0; i < K; ++i) {
        x[i] = deformed(ps[i], 0.25 + 0.3 * static_cast<double>(i));
        set.push_back(request(BatchOp::SetPositions, i, &x[i]));
        if (ps[i].name == "slab") slab = i;
      }
      runOk(*batch, set);
      EXPECT_LT(slab, K);
      for (std::size_t i = 0; i < K; ++i) {
        x0[i] = Eigen::VectorXd::Zero(ps[i].dofCount());
        rhs[i] = randomVector(ps[i].dofCount(), 2100 + static_cast<unsigned>(i));
      }
      for (std::size_t d = 0; d < ps[slab].dofCount(); ++d) x0[slab][d] = ps[slab].constrained[d] ? 0.0 : 1e-3;
      apply.push_back(request(BatchOp::Apply, slab, &x0[slab], &rhs[slab], c));
      runOk(*batch, apply);
      sol = x0;
      for (std::size_t i = 0; i < K; ++i) solves.push_back(request(BatchOp::Solve, i, &rhs[i], &sol[i], c));
      runOk(*batch, solves);
      EXPECT_EQ(solves[slab].stats.iterations, 0) << "r = 0 at the set-up";
      EXPECT_TRUE(solves[slab].stats.converged);
      return solves;
    };
    std::vector<Eigen::VectorXd> xa, xb;
    const unsigned long long lanesBefore = packPcgLaneCount();
    const std::vector<BatchRequest> a = run(packed, xa);
    EXPECT_GT(packPcgLaneCount(), lanesBefore) << "the copies ran in packs";
    const std::vector<BatchRequest> b = run(grouped, xb);
    for (std::size_t i = 0; i < K; ++i) {
      SCOPED_TRACE(ps[i].name + ", preconditioner " + std::to_string(static_cast<int>(pc)));
      expectSameSolve(a[i], b[i], xa[i], xb[i]);
    }
  }
}

TEST_P(OpenCLBatch, CopiesOfOneMeshBatchedGiveEachAlonesBits) {
  // Copies of one mesh placed differently (rotated: their Morton orders differ) keep the device
  // numbering each gets alone, in every numbering, so a batched copy's solve is its own run's bit
  // for bit. (A review caught a version that gave every copy the first copy's order, to pack them.)
  COROFEM_SKIP_IN_MORTON_REPEAT();  // each order in turn
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const std::vector<detail::Problem> ps = instances(3);
  const detail::SystemCoeffs c{14400.0, 120.0, 1.0};
  for (PreconditionerKind pc : {PreconditionerKind::BlockDiagonal, PreconditionerKind::Amg})
  for (int order : {1, -1, 0}) {
    SolverDesc s = solver();
    s.preconditioner = pc;
    s.maxIterations = 10;
    detail::OpenCLTuning o;
    o.localityOrder = order;
    auto batch = batchOf(ps, s, o);
    auto singles = singlesOf(ps, s, o);
    std::vector<Eigen::VectorXd> x(ps.size()), b(ps.size()), sol(ps.size()), alone(ps.size());
    std::vector<BatchRequest> set, solves;
    for (std::size_t i = 0; i < ps.size(); ++i) {
      x[i] = deformed(ps[i], 0.3 * static_cast<double>(i));
      b[i] = randomVector(ps[i].dofCount(), 300 + static_cast<unsigned>(i));
      sol[i] = alone[i] = Eigen::VectorXd::Zero(ps[i].dofCount());
      set.push_back(request(BatchOp::SetPositions, i, &x[i]));
    }
    for (std::size_t i = 0; i < ps.size(); ++i) solves.push_back(request(BatchOp::Solve, i, &b[i], &sol[i], c));
    runOk(*batch, set);
    runOk(*batch, solves);
    for (std::size_t i = 0; i < ps.size(); ++i) {
      singles[i]->setPositions(x[i]);
      singles[i]->solve(c, b[i], alone[i]);
      EXPECT_TRUE(sameBits(sol[i], alone[i])) << "order " << order << ", " << ps[i].name << ", " << toString(pc)
                                              << ": max rel. difference " << maxRel(sol[i], alone[i]);
    }
  }
}

TEST_P(OpenCLBatch, PackRuleTakesPacksWhereTheyShortenTheRound) {
  // By default (OpenCLTuning::packPcg = -1) a round packs a mesh's bodies only where
  // ceil(bodies / cores) exceeds 2.5 x ceil(packs / cores) (SegmentEngine::kPackCost): cores + 1
  // copies stay in one work-group each (2 per core at most against a pack on one core), 8 x cores
  // copies take packs.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  if (!context()->info().cpu || context()->info().gpu) GTEST_SKIP() << "packs run on CPU devices only";
  const std::size_t cores = std::max<std::size_t>(1, context()->info().computeUnits);
  for (const auto& [count, packs] : {std::pair<std::size_t, bool>{cores + 1, false}, {8 * cores, true}}) {
    SCOPED_TRACE(std::to_string(count) + " copies on " + std::to_string(cores) + " compute units");
    // Copies only moved: one device numbering for all, the mesh's own or the Morton order alike.
    std::vector<detail::Problem> ps = instances(count, false);
    ps.erase(std::remove_if(ps.begin(), ps.end(), [](const detail::Problem& p) { return p.name == "slab"; }), ps.end());
    auto batch = batchOf(ps, solver());
    RoundPaths round(ps, 40);
    runOk(*batch, round.set);
    std::vector<std::size_t> all(ps.size());
    for (std::size_t i = 0; i < all.size(); ++i) all[i] = i;
    const unsigned long long before = packPcgLaunchCount();
    EXPECT_EQ(round.path(*batch, all), 1) << "one launch for the round";
    EXPECT_EQ(packPcgLaunchCount() > before, packs);
  }
}

TEST_P(OpenCLBatch, TeamsSolveRoundAfterRoundWithCountersLeftAtZero) {
  // pcg_iterate_team's counters are zeroed by the last group to leave: round after round on one
  // batch (and bodies that converge at different iterations, which ends the launch's loop early for
  // them, and a static frame whose harder systems some bodies end at the cap), each round must give
  // the launched iterations' bits. A counter left over would shift a later round's phases, skip
  // chunks and change the answer (or hang). Bodies alone and together (the block's node phases
  // span 5 chunks), teams of 2 and 5, with the claims' epochs wrapping on the way.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  if (!context()->info().cpu) GTEST_SKIP() << "teams run on CPU devices only";
  const std::vector<detail::Problem> ps = bodiesWithABlock();
  const std::size_t K = ps.size();
  detail::OpenCLTuning launched;
  launched.groupPcg = 0;
  for (std::size_t team : {2, 5}) {
    detail::OpenCLTuning teamed;
    teamed.groupPcg = 1;
    teamed.teamPcg = 1;
    teamed.teamPcgSize = team;
    // The claims' 32-bit epochs wrap within the first rounds (the host resets the claim words):
    // without the reset, every chunk would look claimed and the iterations would do nothing.
    auto a = batchOf(ps, solver(), teamed), b = batchOf(ps, solver(), launched);
    detail::SegmentEngineTestAccess::setTeamEpoch(a->engine(), 0xffffffffu - 20000u);  // a round advances 4 x (cap - 1) = 7,996
    const unsigned long long before = teamPcgLaunchCount();
    int rounds = 0;
    for (int frame = 0; frame < 3; ++frame) {
      for (const std::vector<std::size_t>& who : std::vector<std::vector<std::size_t>>{{0}, {1}, {2, 4}, {0, 1, 2, 3, 4, 5}}) {
        std::vector<Eigen::VectorXd> x(K), rhs(K), xa(K), xb(K);
        std::vector<BatchRequest> setA, setB, solveA, solveB;
        for (std::size_t i : who) {
          x[i] = deformed(ps[i], 0.1 * frame + 0.2 * static_cast<double>(i));
          rhs[i] = randomVector(ps[i].dofCount(), 700 + 10 * static_cast<unsigned>(frame) + static_cast<unsigned>(i));
          xa[i] = xb[i] = Eigen::VectorXd::Zero(rhs[i].size());
          setA.push_back(request(BatchOp::SetPositions, i, &x[i]));
          setB.push_back(request(BatchOp::SetPositions, i, &x[i]));
        }
        runOk(*a, setA);
        runOk(*b, setB);
        const detail::SystemCoeffs c{frame == 1 ? 0.0 : 3600.0, frame == 1 ? 0.0 : 60.0, 1.0};  // frame 1: static
        for (std::size_t i : who) {
          solveA.push_back(request(BatchOp::Solve, i, &rhs[i], &xa[i], c));
          solveB.push_back(request(BatchOp::Solve, i, &rhs[i], &xb[i], c));
        }
        runOk(*a, solveA);
        runOk(*b, solveB);
        ++rounds;
        for (std::size_t j = 0; j < who.size(); ++j) {
          const std::size_t i = who[j];
          SCOPED_TRACE("team " + std::to_string(team) + ", frame " + std::to_string(frame) + ", " + ps[i].name);
          expectSameSolve(solveA[j], solveB[j], xa[i], xb[i]);
        }
      }
    }
    EXPECT_EQ(teamPcgLaunchCount(), before + static_cast<unsigned long long>(rounds))
        << "every round's iterations ran in one team launch";
  }
}

TEST_P(OpenCLBatch, OneLaunchRuleLeavesLargeAndUnevenRoundsLaunched) {
  // Which solve rounds take pcg_iterate_group (segment_engine.cpp, groupRound), with the rule's
  // bounds set small enough for these bodies (beam 192 elements, slab 180, soup 37, bar 600):
  // every body small; or at least two bodies, none over the maximum and none over twice its share
  // of the round on the device's cores. A work-group per body runs on one core, so a large or
  // lopsided round is launched.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const std::vector<detail::Problem> ps = bodies();
  detail::OpenCLTuning o;
  o.workGroupSums = 0;  // per-item partials, as on CPUs: on a GPU too
  o.groupPcg = 1;
  o.teamPcg = 0;  // the team rule: TeamRuleTakesRoundsOfFewerBodiesThanCores
  o.groupPcgSmallElements = 100;
  o.groupPcgMinBodies = 2;
  o.groupPcgMaxElements = 500;
  auto batch = batchOf(ps, solver(), o);
  RoundPaths rounds(ps, 400);
  std::vector<BatchRequest>& set = rounds.set;
  runOk(*batch, set);
  auto oneLaunch = [&](const std::vector<std::size_t>& who) { return rounds.path(*batch, who) == 1; };
  const std::size_t cores = std::max<std::size_t>(1, context()->info().computeUnits);
  EXPECT_TRUE(oneLaunch({2})) << "the soup (37 elements) is small";
  EXPECT_FALSE(oneLaunch({0})) << "the beam alone is neither small nor a round of two";
  EXPECT_EQ(oneLaunch({0, 1}), 192 * cores <= 2 * (192 + 180)) << "beam and slab: two even bodies";
  EXPECT_FALSE(oneLaunch({0, 4})) << "the bar (600 elements) is over the maximum";
  o.groupPcgMaxElements = 1000;
  auto wide = batchOf(ps, solver(), o);
  batch = std::move(wide);
  runOk(*batch, set);
  EXPECT_EQ(oneLaunch({2, 4}), 600 * cores <= 2 * (600 + 37)) << "bar and soup: lopsided on more than 2 cores";
  EXPECT_EQ(oneLaunch({0, 1, 4}), 600 * cores <= 2 * (192 + 180 + 600));
}

TEST_P(OpenCLBatch, TeamRuleTakesRoundsOfFewerBodiesThanCores) {
  // Which solve rounds take pcg_iterate_team (segment_engine.cpp, groupTeam) with the bounds set
  // for these bodies (beam 192 elements, slab 180, soup 37, bar 600): fewer bodies than cores, none
  // over the maximum, and a team of at least 2 with at least the minimum of the largest body per
  // work-group; otherwise the one-group rule (small: 100) or the launched iterations.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  if (!context()->info().cpu) GTEST_SKIP() << "teams run on CPU devices only";
  const std::vector<detail::Problem> ps = bodies();
  detail::OpenCLTuning o;
  o.groupPcg = 1;
  o.teamPcg = 1;
  o.groupPcgSmallElements = 100;
  o.groupPcgMaxElements = 100;
  o.teamPcgMinElements = 90;
  o.teamPcgMaxElements = 500;
  auto batch = batchOf(ps, solver(), o);
  RoundPaths rounds(ps, 500);
  runOk(*batch, rounds.set);
  auto path = [&](const std::vector<std::size_t>& who) { return rounds.path(*batch, who); };
  const std::size_t cores = std::max<std::size_t>(1, context()->info().computeUnits);
  EXPECT_EQ(path({0}), cores >= 2 ? 2 : 0) << "the beam alone (192 = 2 x 96 elements)";
  EXPECT_EQ(path({2}), 1) << "the soup (37 elements) is small: one group";
  EXPECT_EQ(path({4}), 0) << "the bar (600 elements) is over the team's maximum and not small";
  EXPECT_EQ(path({0, 1}), cores >= 4 ? 2 : 0) << "beam and slab: a team each only with 4 cores or more";
  // An iteration cap whose 4 epochs per iteration would overflow the claims' 32 bits (a review hung
  // the second round of a team with 2^30 + 1): such rounds take the other paths, even when a team
  // size is forced, and converge.
  SolverDesc huge = solver();
  huge.maxIterations = (1 << 30) + 1;
  o.teamPcgSize = 2;
  auto capped = batchOf(ps, huge, o);
  runOk(*capped, rounds.set);
  for (int round = 0; round < 2; ++round) {
    rounds.sol[0] = Eigen::VectorXd::Zero(rounds.rhs[0].size());
    std::vector<BatchRequest> solve = {
        request(BatchOp::Solve, 0, &rounds.rhs[0], &rounds.sol[0], {900.0, 30.0, 1.0})};
    const unsigned long long team = teamPcgLaunchCount();
    runOk(*capped, solve);
    EXPECT_EQ(teamPcgLaunchCount(), team) << "round " << round << ": no team with a cap of 2^30 + 1";
    EXPECT_TRUE(solve[0].stats.converged) << "round " << round;
  }
}

TEST_P(OpenCLBatch, ByDefaultALoneBodyTakesATeamThenAProbeOfOneWorkGroupWithTheSameBits) {
  // Teams chosen by measurement (team_choice.hpp) on a fresh engine, whatever the timings: the first
  // round a team of two, the second one work-group (the probe), and both the same solution bits.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const std::size_t units = context()->info().computeUnits;
  if (!context()->info().cpu || units < 2 || detail::usableCpus() < units)
    GTEST_SKIP() << "teams run on CPU devices of 2 or more compute units, all usable by this process";
  const std::vector<detail::Problem> ps = bodies();
  const detail::Problem& beam = ps[0];
  detail::OpenCLTuning o;
  o.teamPcgMinElements = std::max<std::size_t>(1, beam.mesh.tetCount() / 2);  // a team of two members
  auto dev = test::openclOn(beam, solver(), context(), o);
  const Eigen::VectorXd x = deformed(beam, 0.3), rhs = randomVector(beam.dofCount(), 1234);
  dev->setPositions(x);
  auto counter = [&](const char* name) {
    for (const detail::DeviceCounter& c : dev->device().counters())
      if (c.name == name) return c.value;
    ADD_FAILURE() << "no counter " << name;
    return -1LL;
  };
  const detail::SystemCoeffs c{900.0, 30.0, 1.0};
  Eigen::VectorXd first = Eigen::VectorXd::Zero(rhs.size()), second = first;
  dev->solve(c, rhs, first);
  EXPECT_EQ(counter("pcg_team_launches"), 1);
  EXPECT_EQ(counter("pcg_group_launches"), 0);
  dev->solve(c, rhs, second);
  EXPECT_EQ(counter("pcg_team_launches"), 1);
  EXPECT_EQ(counter("pcg_group_launches"), 1) << "the second round probes one work-group";
  EXPECT_TRUE(sameBits(first, second));
}

TEST_P(OpenCLBatch, TeamsOfTwoHostThreadsAtOnceKeepTheirBits) {
  // Two batches solving at the same time from two host threads, both in teams (2 and 8 work-groups
  // per body), each with a context and queue of its own, so that their team kernels run on the
  // device at once and their work-groups compete for PoCL's workers: no hang, and every round the
  // launched iterations' bits and iteration counts.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  if (!context()->info().cpu) GTEST_SKIP() << "teams run on CPU devices only";
  const std::vector<detail::Problem> ps = bodiesWithABlock();
  const std::size_t K = ps.size();
  std::vector<const detail::Problem*> all;
  for (const detail::Problem& p : ps) all.push_back(&p);
  const SolverDesc s = solver();
  const detail::SystemCoeffs c{900.0, 30.0, 1.0};
  const std::vector<std::vector<std::size_t>> rounds = {{0}, {0, 1}, {1, 3}, {0, 5}};
  std::vector<Eigen::VectorXd> x(K), rhs(K);
  for (std::size_t i = 0; i < K; ++i) {
    x[i] = deformed(ps[i], 0.2 + 0.3 * static_cast<double>(i));
    rhs[i] = randomVector(ps[i].dofCount(), 900 + static_cast<unsigned>(i));
  }
  // Solves the rounds on `batch`; the solutions and iteration counts per round and body.
  struct Answers {
    std::vector<std::vector<Eigen::VectorXd>> x;
    std::vector<std::vector<int>> iterations;
    std::string error;
  };
  auto solveRounds = [&](test::DeviceBatch& batch) {
    Answers a{std::vector<std::vector<Eigen::VectorXd>>(rounds.size(), std::vector<Eigen::VectorXd>(K)),
              std::vector<std::vector<int>>(rounds.size(), std::vector<int>(K, -1)), ""};
    for (std::size_t r = 0; r < rounds.size(); ++r) {
      std::vector<BatchRequest> set, solve;
      for (std::size_t i : rounds[r]) {
        set.push_back(request(BatchOp::SetPositions, i, &x[i]));
        a.x[r][i] = Eigen::VectorXd::Zero(rhs[i].size());
      }
      for (std::size_t i : rounds[r]) solve.push_back(request(BatchOp::Solve, i, &rhs[i], &a.x[r][i], c));
      for (std::vector<BatchRequest>* list : {&set, &solve}) {
        std::vector<BatchRequest*> round;
        for (BatchRequest& q : *list) round.push_back(&q);
        batch.run(round);
        for (const BatchRequest& q : *list)
          if (q.error && a.error.empty()) try {
              std::rethrow_exception(q.error);
            } catch (const std::exception& e) {
              a.error = e.what();
            }
      }
      for (std::size_t j = 0; j < rounds[r].size(); ++j) a.iterations[r][rounds[r][j]] = solve[j].stats.iterations;
    }
    return a;
  };
  detail::OpenCLTuning launched;
  launched.groupPcg = 0;
  const Answers expected = solveRounds(*batchOn(all, s, context(), launched));
  ASSERT_TRUE(expected.error.empty()) << expected.error;
  const unsigned long long before = teamPcgLaunchCount();
  constexpr int kRepeats = 3;
  Answers got[2];
  auto worker = [&](int t) {
    detail::OpenCLTuning o;
    o.groupPcg = 1;
    o.teamPcg = 1;
    o.teamPcgSize = t == 0 ? 2 : 8;
    try {
      auto ctx = detail::cl::Context::create(std::to_string(GetParam().device));
      auto batch = batchOn(all, s, ctx, o);
      for (int k = 0; k < kRepeats; ++k) got[t] = solveRounds(*batch);
    } catch (const std::exception& e) {
      got[t].error = e.what();
    }
  };
  std::thread a(worker, 0), b(worker, 1);
  a.join();
  b.join();
  for (int t = 0; t < 2; ++t) {
    SCOPED_TRACE(t == 0 ? "teams of 2" : "teams of 8");
    ASSERT_TRUE(got[t].error.empty()) << got[t].error;
    for (std::size_t r = 0; r < rounds.size(); ++r)
      for (std::size_t i : rounds[r]) {
        EXPECT_EQ(got[t].iterations[r][i], expected.iterations[r][i]) << "round " << r << ", " << ps[i].name;
        EXPECT_TRUE(sameBits(got[t].x[r][i], expected.x[r][i])) << "round " << r << ", " << ps[i].name;
      }
  }
  EXPECT_EQ(teamPcgLaunchCount() - before, 2ull * kRepeats * rounds.size()) << "every round in teams";
}

/// The OpenCL tuning whose multigrid multiplies its coarse levels in sliced ELLPACK, a row per
/// work-item (work-group sums: GPUs), on whatever device is present; the default on a CPU device
/// multiplies them in dense blocks.
detail::OpenCLTuning ellpackCoarseLevels() {
  detail::OpenCLTuning o;
  o.workGroupSize = 32;
  o.elementsPerItem = 1;
  o.nodesPerItem = 1;
  o.workGroupSums = 1;
  return o;
}

TEST_P(OpenCLBatch, MultigridInBothCoarseLayoutsMatchesTheReference) {
  // Each body solved alone with "amg" from a deformed state, with the coarse levels in dense blocks
  // (the CPU layout: every coarse vertex in 6 rows, padded) and in sliced ELLPACK (the GPU one):
  // both within one iteration of the reference backend's multigrid and at its answer. A wrong
  // block, a padding row that is not zero, or a prolongation that is not added (x += P e) makes
  // the cycle another preconditioner, and the count moves.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::vector<detail::Problem> ps = bodies();
  {  // and a slender beam of 8,640 tets, whose hierarchy smooths a coarse level (three levels or more)
    detail::Problem p = test::makeProblem(test::cellBox(160, 3, 3, 1.0 / 160, 0.1 / 3, 0.1 / 3), 1e6, 0.3, 1000.0);
    p.name = "long beam";
    std::vector<Eigen::Index> free;
    for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
      for (int c = 0; c < 3; ++c) {
        p.constrained[3 * n + c] = p.mesh.nodes[3 * n] < 1e-9;
        if (!p.constrained[3 * n + c]) free.push_back(static_cast<Eigen::Index>(3 * n + c));
      }
    detail::WarpedAmg amg;
    amg.build(detail::restOperator(detail::restStiffness(p), p, free, 1e4, 1.0), free, p.restPositions, p.mesh.nodeCount());
    ASSERT_GE(amg.levels().size(), 3u) << "the long beam's coarse levels are not smoothed: x += P e goes untested";
    ps.push_back(std::move(p));
  }
  SolverDesc s = solver();
  s.preconditioner = PreconditionerKind::Amg;
  s.maxIterations = 300;
  const double tol = isDouble() ? 1e-8 : 1e-3;
  for (const bool ellpack : {false, true}) {
    SCOPED_TRACE(ellpack ? "sliced ELLPACK" : "dense blocks");
    auto singles = singlesOf(ps, s, ellpack ? ellpackCoarseLevels() : detail::OpenCLTuning{});
    std::size_t withLevels = 0;
    for (std::size_t i = 0; i < ps.size(); ++i) {
      auto ref = test::createReferenceBackend(ps[i], s);
      const Eigen::VectorXd x = deformed(ps[i], 0.5), b = randomVector(ps[i].dofCount(), 300 + static_cast<unsigned>(i));
      singles[i]->setPositions(x);
      ref->setPositions(x);
      Eigen::VectorXd got = Eigen::VectorXd::Zero(b.size()), want = Eigen::VectorXd::Zero(b.size());
      const detail::LinearSolveStats g = singles[i]->solve({1e4, 0.0, 1.0}, b, got);
      const detail::LinearSolveStats w = ref->solve({1e4, 0.0, 1.0}, b, want);
      ASSERT_TRUE(w.converged) << ps[i].name;
      EXPECT_TRUE(g.converged) << ps[i].name;
      EXPECT_LE(std::abs(g.iterations - w.iterations), isDouble() ? 1 : 2)
          << ps[i].name << ": " << g.iterations << " iterations against the reference's " << w.iterations;
      EXPECT_LE((got - want).norm(), tol * want.norm()) << ps[i].name;
      withLevels += w.iterations > 1;
    }
    EXPECT_GT(withLevels, 0u) << "no body needed more than one iteration: the cycle goes untested";
  }
}

TEST_P(OpenCLBatch, AMultigridBatchWithAFailedFirstBodyGivesTheOthersTheirBits) {
  // The multigrid's coarse products run over every body's rows: with the first body refused (a
  // non-finite b: it never runs, its scratch is left as it was) the others get the bits they get
  // alone, with the coarse levels in dense blocks (whose every column is a vertex of the block
  // row's own body) and in sliced ELLPACK (whose slices cross bodies, and whose padding, which
  // reads the first body's x, the kernel skips; this device's scratch is finite, so the test shows
  // the isolation, not that skip).
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  for (const bool ellpack : {false, true}) {
  SCOPED_TRACE(ellpack ? "sliced ELLPACK" : "dense blocks");
  const detail::OpenCLTuning o = ellpack ? ellpackCoarseLevels() : detail::OpenCLTuning{};
  const std::vector<detail::Problem> ps = bodies();
  const std::size_t K = 3;
  std::vector<detail::Problem> three(ps.begin(), ps.begin() + K);
  SolverDesc s = solver();
  s.preconditioner = PreconditionerKind::Amg;
  auto batch = batchOf(three, s, o);
  auto singles = singlesOf(three, s, o);
  std::vector<Eigen::VectorXd> x(K), b(K), sol(K);
  std::vector<BatchRequest> set, solves;
  for (std::size_t i = 0; i < K; ++i) {
    x[i] = deformed(three[i], 0.4);
    b[i] = randomVector(three[i].dofCount(), 70 + static_cast<unsigned>(i));
    sol[i] = Eigen::VectorXd::Zero(b[i].size());
    set.push_back(request(BatchOp::SetPositions, i, &x[i]));
    singles[i]->setPositions(x[i]);
  }
  const std::size_t freeDof = 3 * (three[0].mesh.nodeCount() - 1);  // the beam's last node: free
  ASSERT_FALSE(three[0].constrained[freeDof]);
  b[0][static_cast<Eigen::Index>(freeDof)] = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < K; ++i) solves.push_back(request(BatchOp::Solve, i, &b[i], &sol[i], {1e4, 0.0, 1.0}));
  runOk(*batch, set);
  std::vector<BatchRequest*> round;
  for (auto& r : solves) round.push_back(&r);
  batch->run(round);
  EXPECT_TRUE(solves[0].error);
  for (std::size_t i : {1u, 2u}) {
    EXPECT_FALSE(solves[i].error) << three[i].name;
    Eigen::VectorXd xs = Eigen::VectorXd::Zero(b[i].size());
    const detail::LinearSolveStats st = singles[i]->solve({1e4, 0.0, 1.0}, b[i], xs);
    EXPECT_TRUE(st.converged) << three[i].name;
    EXPECT_TRUE(sameBits(sol[i], xs)) << three[i].name << ": max rel. difference " << maxRel(sol[i], xs);
  }
  }
}

TEST_P(OpenCLBatch, ANonFiniteRightHandSideFailsOnlyThatRequest) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  const std::vector<detail::Problem> ps = bodies();
  const std::size_t K = 3;
  std::vector<detail::Problem> three(ps.begin(), ps.begin() + K);
  auto batch = batchOf(three, solver());
  auto singles = singlesOf(three, solver());
  std::vector<Eigen::VectorXd> x(K), b(K), sol(K);
  std::vector<BatchRequest> set, solves;
  for (std::size_t i = 0; i < K; ++i) {
    x[i] = deformed(three[i], 0.4);
    b[i] = randomVector(three[i].dofCount(), 50 + static_cast<unsigned>(i));
    sol[i] = Eigen::VectorXd::Zero(b[i].size());
    set.push_back(request(BatchOp::SetPositions, i, &x[i]));
    singles[i]->setPositions(x[i]);
  }
  b[1][11] = std::nan("");  // a free dof of the slab: that solve fails
  ASSERT_FALSE(three[1].constrained[11]);
  b[0][0] = std::nan("");  // a clamped dof of the beam: its row of b is ignored, the solve succeeds
  ASSERT_TRUE(three[0].constrained[0]);
  for (std::size_t i = 0; i < K; ++i) solves.push_back(request(BatchOp::Solve, i, &b[i], &sol[i], {1e4, 0.0, 1.0}));
  runOk(*batch, set);
  std::vector<BatchRequest*> round;
  for (auto& r : solves) round.push_back(&r);
  batch->run(round);
  ASSERT_TRUE(solves[1].error);
  try {
    std::rethrow_exception(solves[1].error);
  } catch (const detail::Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::SolveFailed);
    EXPECT_NE(std::string(e.what()).find("not finite"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(three[1].name), std::string::npos) << e.what();
  }
  for (std::size_t i : {0u, 2u}) {
    EXPECT_FALSE(solves[i].error) << three[i].name;
    Eigen::VectorXd xs = Eigen::VectorXd::Zero(b[i].size());
    singles[i]->solve({1e4, 0.0, 1.0}, b[i], xs);
    EXPECT_TRUE(sameBits(sol[i], xs)) << three[i].name;
  }
  // Two requests for one body in a round are an error of that request, not of the round.
  Eigen::VectorXd fa, fb;
  std::vector<BatchRequest> twice = {request(BatchOp::InternalForces, 0, nullptr, &fa),
                                     request(BatchOp::InternalForces, 0, nullptr, &fb)};
  std::vector<BatchRequest*> twiceRound = {&twice[0], &twice[1]};
  batch->run(twiceRound);
  EXPECT_FALSE(twice[0].error);
  EXPECT_TRUE(twice[1].error);
}

TEST_P(OpenCLBatch, AllocatedBytesAreTheBuffersAndStaticProblemsHaveNoMassBuffer) {
  // The expected sizes follow kernels/shared/corofem_layout.h with the CPU configuration fixed
  // here (work-group 64, 8 elements per work-item, 4 nodes per PCG work-item, per-item partials):
  // elements padded to 512 per body, nodes to 256.
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  detail::OpenCLTuning o;
  o.workGroupSize = 64;
  o.elementsPerItem = 8;
  o.nodesPerItem = 4;
  o.workGroupSums = 0;
  const std::vector<detail::Problem> ps = bodies();
  const std::size_t r = isDouble() ? 8 : 4;  // real; sum_real is the same outside mixed precision
  const bool group = !context()->info().gpu;  // pcg_iterate_group (per-item partials)
  // Teams by default on CPU devices where the process may use as many CPUs as compute units.
  const bool teamsByDefault = group && context()->info().cpu &&
                              detail::usableCpus() >= std::max<std::size_t>(1, context()->info().computeUnits);
  auto expected = [&](const std::vector<const detail::Problem*>& set, bool mass, PreconditionerKind pc,
                      bool quaternion, bool teams = false) {
    teams = teams || teamsByDefault;
    std::size_t S = 0, N = 0, E = 0, claims = 0;
    for (const detail::Problem* p : set) {
      const std::size_t s = (p->mesh.tetCount() + 511) / 512 * 512, n = (p->mesh.nodeCount() + 255) / 256 * 256;
      S += s;
      N += n;
      E += p->mesh.tetCount();
      claims += std::max<std::size_t>({1, s / 512, n / 256});  // a claim word per chunk of the larger phase
    }
    const std::size_t K = set.size();
    auto buf = [](std::size_t b) { return std::max<std::size_t>(b, 16); };  // the smallest buffer: 16 bytes
    std::size_t bytes = buf(4 * (S / 512)) + buf(4 * (N / 64));  // segment tables
    bytes += 4 * test::layout::kSegInfoCount * K + r * test::layout::kSegCoefCount * K;
    bytes += 4 * 4 * S + r * (10 + 9 + 12) * S;  // corners, geometry, a_i, element outputs
    if (quaternion) bytes += r * 9 * S + r * 4 * S;   // R (every pass writes it) and the quaternions
    bytes += 4 * (N + 1) + 4 * 4 * E;  // gather lists
    bytes += r * 3 * N * (1 + 1 + 7);  // positions, free mask, x b r u p w s
    if (mass) bytes += r * 3 * N;
    if (pc != PreconditionerKind::None)  // node blocks and inverse: 6 + 9 per node, or diagonals 3 + 3
      bytes += r * (pc == PreconditionerKind::BlockDiagonal ? 6 + 9 : 3 + 3) * N;
    // Two partial buffers (the first also holds element_forces' energy per element work-item:
    // S / 8 reals on CPUs), scalars.
    bytes += std::max(r * 3 * std::max(S / 512, N / 4), r * (S / 8)) + r * 3 * (N / 4) + r * 12 * K;
    if (teams) bytes += 4 * (16 * K + claims);  // pcg_iterate_team's state
    if (group) bytes += buf(4 * (K + 1));  // pcg_iterate_group's list of bodies and claim word
    return bytes;
  };
  SolverDesc s = solver();
  const detail::Problem& beam = ps[0];
  detail::Problem staticBeam = beam;
  staticBeam.lumpedMass.resize(0);  // how a static problem looks: no lumped mass
  detail::Problem zeroMass = beam;
  zeroMass.lumpedMass.setZero();
  auto ctx = context();
  const std::size_t dynamicBytes = test::openclOn(beam, s, ctx, o)->allocatedBytes();
  EXPECT_EQ(dynamicBytes, expected({&beam}, true, s.preconditioner, false));
  const std::size_t staticBytes = test::openclOn(staticBeam, s, ctx, o)->allocatedBytes();
  EXPECT_EQ(staticBytes, expected({&beam}, false, s.preconditioner, false));
  EXPECT_EQ(dynamicBytes - staticBytes, r * 3 * 256) << "exactly the mass buffer";
  EXPECT_EQ(test::openclOn(zeroMass, s, ctx, o)->allocatedBytes(), staticBytes);
  {
    // R is made when first read back (readRotations), and then it is the identity at rest.
    auto b = test::openclOn(beam, s, ctx, o);
    const std::vector<double> R = b->readRotations();
    EXPECT_EQ(b->allocatedBytes(), dynamicBytes + r * 9 * 512);
    ASSERT_EQ(R.size(), 9 * beam.mesh.tetCount());
    for (std::size_t i = 0; i < R.size(); ++i) ASSERT_EQ(R[i], i % 9 % 4 == 0 ? 1.0 : 0.0) << i;
  }
  {
    // The linear formulation rotates nothing: its kernels read the rest gradients of the geometry.
    detail::Problem linear = beam;
    linear.formulation = Formulation::Linear;
    EXPECT_EQ(test::openclOn(linear, s, ctx, o)->allocatedBytes(), dynamicBytes - r * 9 * 512);
  }
  if (group) {
    detail::OpenCLTuning teamed = o;
    teamed.teamPcg = 1;
    EXPECT_EQ(test::openclOn(beam, s, ctx, teamed)->allocatedBytes(),
              expected({&beam}, true, s.preconditioner, false, context()->info().cpu));
  }
  {
    SolverDesc q = s;
    q.rotation = RotationMethod::Quaternion;
    q.preconditioner = PreconditionerKind::None;
    EXPECT_EQ(test::openclOn(beam, q, ctx, o)->allocatedBytes(),
              expected({&beam}, true, PreconditionerKind::None, true));
  }
  {
    SolverDesc d = s;  // the diagonal preconditioner: diagonal blocks (3 per node), not 6
    d.preconditioner = PreconditionerKind::Diagonal;
    EXPECT_EQ(test::openclOn(beam, d, ctx, o)->allocatedBytes(),
              expected({&beam}, true, PreconditionerKind::Diagonal, false));
  }
  std::vector<const detail::Problem*> all;
  for (const auto& p : ps) all.push_back(&p);
  EXPECT_EQ(batchOf(ps, s, o)->allocatedBytes(), expected(all, true, s.preconditioner, false));
  {
    // Packs (pcg_iterate_pack): 11 copies of one mesh of 300 tets and 108 nodes take 2 slots of 8
    // lanes, each with rows for 304 elements and 112 nodes (padded to 8), and the mesh's corners
    // once: the slots' table (15 words a slot and the claim word), corners, a_i and volumes (10 rows per element), the
    // PCG vectors x r u p s w and b, the node sums (6 rows: the block preconditioner's blocks), free
    // mask, mass and block inverse (7 x 3, 6, 3, 3 and 9 rows per node) and 64 partial triples per
    // slot (the bodies' own count).
    const std::vector<detail::Problem> copies = instances(11, false);  // one numbering, Morton or not
    detail::OpenCLTuning packed = o, plain = o;
    packed.groupPcg = plain.groupPcg = 1;
    packed.packPcg = 1;
    plain.packPcg = 0;
    const std::size_t slots = 2, L = 8, E = 300, Ep = 304, Np = 112;
    const std::size_t packBytes = 4 * (15 * slots + 1) + 4 * 4 * E + r * L * slots * (Ep * 10 + Np * (7 * 3 + 6 + 3 + 3 + 9)) +
                                  r * 3 * L * 64 * slots;
    EXPECT_EQ(batchOf(copies, s, packed)->allocatedBytes(), batchOf(copies, s, plain)->allocatedBytes() + packBytes);
  }
  // The static problem still solves (a mass coefficient meets no mass) like one with zero mass.
  auto a = test::openclOn(staticBeam, s, ctx, o);
  auto z = test::openclOn(zeroMass, s, ctx, o);
  const Eigen::VectorXd x = deformed(beam, 0.1), b = randomVector(beam.dofCount(), 3);
  a->setPositions(x);
  z->setPositions(x);
  Eigen::VectorXd xa = Eigen::VectorXd::Zero(b.size()), xz = xa;
  EXPECT_TRUE(a->solve({100.0, 0.0, 1.0}, b, xa).converged);
  z->solve({100.0, 0.0, 1.0}, b, xz);
  EXPECT_TRUE(sameBits(xa, xz));
}

TEST_P(OpenCLBatch, UnsupportedFormulationIsBadInputNamingTheBody) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::vector<detail::Problem> ps = bodies();
  ps[2].formulation = Formulation::NeoHookean;
  try {
    batchOf(ps, solver());
    FAIL() << "expected BadInput";
  } catch (const detail::Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::BadInput);
    EXPECT_NE(std::string(e.what()).find("soup"), std::string::npos) << e.what();
  }
}

INSTANTIATE_TEST_SUITE_P(Devices, OpenCLBatch, ::testing::ValuesIn(test::deviceCases()), test::caseName);

}  // namespace
}  // namespace corofem
