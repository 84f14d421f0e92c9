// A probe for issue 29's second preconditioner, the warped precomputed Cholesky of SOFA's
// PrecomputedWarpPreconditioner and Courtecuisse et al. 2010: the rest system A_0 = m M + K_0 on
// the free dofs factored once (Eigen's SimplicialLDLT, AMD ordering), applied each PCG iteration
// turned by per-node rotations, z = W A_0^-1 W^T r, W = blockdiag(R_n), R_n the polar rotation of
// the sum of the rotations of the elements around node n. Written first as a probe, to choose by
// measurement what the library builds next; the library's "warped_cholesky" (precond/
// warped_cholesky.hpp) now applies it here, against the same Jacobi and "amg".
//
// The body is issue 29's 12,960-tet beam (1 x 0.1 x 0.1 m, 60 x 6 x 6 cells of 6 tets, E = 1e6 Pa,
// nu = 0.3, rho = 1000, clamped at x = 0), curled about y so that its end turns by 0, 0.3 or
// 1 rad, with 0.1 mm of noise; the system is backward Euler's at 1/60 s (3600 M + K_t, K_t the
// co-rotational tangent assembled from the element rotations); b is random. Each benchmark runs a
// host PCG (double) to a relative residual of 1e-6 from zero, with Jacobi, the library's "amg"
// (its host V-cycle, as the reference backend applies it), the rest Cholesky or the warped one:
//   probeSolve/<preconditioner>/turn_<millirad>   iterations and the time of a solve
//   probeFactor                                   the factorisation of A_0 (Eigen's, minimum degree)
//   probeBuild                                    the library's factor (WarpedCholesky::build)
//   probeAmgSetup                                 the multigrid's set-up (BodyAmg::ensure)
//   probeTriangular/<eigen|double|float>          one application of A_0^-1 (the permutation, the
//                                                 two triangular solves, D^-1) on one thread: Eigen's
//                                                 solve, and a loop over the factor's columns in
//                                                 double and in float, as one work-item of a CPU
//                                                 device would run it
//   probeTriangular/supernodal                    the same factor (minimum degree order) in the
//                                                 library's supernodal solves, on the host's threads
//   probeTriangular/library                       the library's: WarpedCholesky unwarped (nested
//                                                 dissection order, supernodal solves)
//
//   build/bench/bench_warped_cholesky --benchmark_repetitions=5 --benchmark_enable_random_interleaving=true \
//       --benchmark_report_aggregates_only=true
#include "common/random_vector.hpp"
#include "common/textbook_pcg.hpp"
#include "model/element.hpp"
#include "precond/amg.hpp"
#include "precond/supernodal_ldlt.hpp"
#include "precond/warped_cholesky.hpp"
#include "reference/small_meshes.hpp"

#include <benchmark/benchmark.h>

#include <Eigen/SparseCholesky>

#include <cmath>
#include <functional>
#include <memory>
#include <random>
#include <string>

namespace {

using namespace corofem;
using namespace corofem::detail;

constexpr double kMass = 3600.0;  // 1 / h^2 at h = 1/60 s, the stiffness coefficient 1

struct Beam {
  Problem p;
  std::vector<Eigen::Index> free;
  std::vector<int> index;  // per dof: its free index, or -1
  AmgMatrix A0;
  Beam() : p(test::makeProblem(test::boxMesh(60, 6, 6, 1.0, 0.1, 0.1), 1e6, 0.3, 1000.0)) {
    for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
      if (p.mesh.nodes[3 * n] < 1e-12)
        for (int c = 0; c < 3; ++c) p.constrained[3 * n + c] = 1;
    index.assign(p.dofCount(), -1);
    for (std::size_t d = 0; d < p.dofCount(); ++d)
      if (!p.constrained[d]) {
        index[d] = static_cast<int>(free.size());
        free.push_back(static_cast<Eigen::Index>(d));
      }
    A0 = restOperator(restStiffness(p), p, free, kMass, 1.0);
  }
};

const Beam& beam() {
  static const Beam b;
  return b;
}

/// The curled beam's system A_t and per-node rotations.
struct State {
  AmgMatrix A;
  std::vector<Mat3> nodeRotation;
  Eigen::VectorXd b, x;  // the right-hand side on the free dofs; the positions (3N)
};

State curled(const Beam& beam, double turn) {
  const Problem& p = beam.p;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd x = p.restPositions;
  for (std::size_t n = 0; n < p.mesh.nodeCount() && turn > 0.0; ++n) {
    const double s = p.mesh.nodes[3 * n] * turn, radius = 1.0 / turn - p.mesh.nodes[3 * n + 2];
    x[3 * n] = radius * std::sin(s);
    x[3 * n + 2] = 1.0 / turn - radius * std::cos(s);
  }
  for (Eigen::Index i = 0; i < x.size(); ++i) x[i] += 1e-4 * u(rng);
  State st;
  st.x = x;
  std::vector<Eigen::Triplet<double, int>> t;
  std::vector<Mat3> rotations(p.elements.size());
  for (std::size_t e = 0; e < p.elements.size(); ++e) {
    std::array<Vec3d, 4> xe;
    for (int a = 0; a < 4; ++a) xe[a] = x.segment<3>(3 * p.mesh.tets[4 * e + a]);
    const Mat3 R = polarRotation(deformationGradient(p.elements[e], xe));
    rotations[e] = R;
    const Mat12 K = rotateStiffness(linearStiffness(p.elements[e], p.lame), R);
    for (int a = 0; a < 12; ++a)
      for (int c = 0; c < 12; ++c) {
        const int i = beam.index[3 * p.mesh.tets[4 * e + a / 3] + a % 3];
        const int j = beam.index[3 * p.mesh.tets[4 * e + c / 3] + c % 3];
        if (i >= 0 && j >= 0) t.emplace_back(i, j, K(a, c));
      }
  }
  for (std::size_t i = 0; i < beam.free.size(); ++i)
    t.emplace_back(static_cast<int>(i), static_cast<int>(i), kMass * p.lumpedMass[static_cast<std::size_t>(beam.free[i])]);
  const Eigen::Index n = static_cast<Eigen::Index>(beam.free.size());
  st.A = AmgMatrix(n, n);
  st.A.setFromTriplets(t.begin(), t.end());
  st.nodeRotation = nodeRotations(p.mesh, rotations);  // the library's warp
  st.b.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) st.b[i] = u(rng);
  return st;
}

using Ldlt = Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>;

const Ldlt& factor() {
  static const std::unique_ptr<Ldlt> f = std::make_unique<Ldlt>(Eigen::SparseMatrix<double>(beam().A0));
  return *f;
}

/// The library's warped factor of the same A_0 (made once: every probeSolve sets its own warp).
WarpedCholesky& warpedFactor() {
  static WarpedCholesky w = [] {
    WarpedCholesky made;
    made.build(beam().A0, beam().free, beam().p.restPositions, "beam");
    return made;
  }();
  return w;
}

void probeFactor(benchmark::State& state) {
  const Eigen::SparseMatrix<double> A = beam().A0;
  for (auto _ : state) {
    Ldlt f(A);
    if (f.info() != Eigen::Success) state.SkipWithError("the rest system is not positive definite");
    benchmark::DoNotOptimize(f.info());
  }
  state.counters["nnz_A"] = static_cast<double>(A.nonZeros());  // both triangles
  state.counters["nnz_L"] = static_cast<double>(Ldlt(A).matrixL().nestedExpression().nonZeros());  // strictly lower
}

/// The library's factor of the same system (WarpedCholesky::build: the rigid-motion check, the
/// nested dissection order, the supernodal factorisation in that order).
void probeBuild(benchmark::State& state) {
  const Beam& b = beam();
  for (auto _ : state) {
    WarpedCholesky w;
    w.build(b.A0, b.free, b.p.restPositions, "beam");
    benchmark::DoNotOptimize(w.factorEntries());
  }
}

/// The library's multigrid set-up for the same system, as the reference backend makes it
/// (BodyAmg::ensure: K_0 assembled, the hierarchy, its bounds).
void probeAmgSetup(benchmark::State& state) {
  const Beam& b = beam();
  for (auto _ : state) {
    BodyAmg body;
    body.ensure(b.p, b.free, kMass, 1.0);
    benchmark::DoNotOptimize(body.amg().levels().size());
  }
}

/// z = A_0^-1 r by the factor's columns: P, L y = P r (L unit lower, by columns), y /= D,
/// L^T x = y (by rows of L^T, the same columns), P^T; the values in T.
template <class T>
void probeTriangular(benchmark::State& state) {
  const Ldlt& f = factor();
  const Eigen::SparseMatrix<double>& L = f.matrixL().nestedExpression();
  const auto n = static_cast<int>(L.rows());
  const std::vector<int> start(L.outerIndexPtr(), L.outerIndexPtr() + n + 1);
  const std::vector<int> row(L.innerIndexPtr(), L.innerIndexPtr() + L.nonZeros());
  std::vector<T> value(static_cast<std::size_t>(L.nonZeros())), dinv(static_cast<std::size_t>(n));
  for (Eigen::Index k = 0; k < L.nonZeros(); ++k) value[static_cast<std::size_t>(k)] = static_cast<T>(L.valuePtr()[k]);
  for (int i = 0; i < n; ++i) dinv[static_cast<std::size_t>(i)] = static_cast<T>(1.0 / f.vectorD()[i]);
  const Eigen::VectorXi perm = f.permutationP().indices();  // (P r)[perm[i]] = r[i]
  const Eigen::VectorXd r = test::randomVector(static_cast<std::size_t>(n), 5);
  const Eigen::VectorXd expected = f.solve(r);
  std::vector<T> y(static_cast<std::size_t>(n));
  Eigen::VectorXd z(n);
  for (auto _ : state) {
    for (int i = 0; i < n; ++i) y[static_cast<std::size_t>(perm[i])] = static_cast<T>(r[i]);
    for (int j = 0; j < n; ++j) {  // L y = b, column by column
      const T yj = y[static_cast<std::size_t>(j)];
      for (int k = start[static_cast<std::size_t>(j)]; k < start[static_cast<std::size_t>(j) + 1]; ++k)
        y[static_cast<std::size_t>(row[static_cast<std::size_t>(k)])] -= value[static_cast<std::size_t>(k)] * yj;
    }
    for (int i = 0; i < n; ++i) y[static_cast<std::size_t>(i)] *= dinv[static_cast<std::size_t>(i)];
    for (int j = n - 1; j >= 0; --j) {  // L^T x = y: row j of L^T is column j of L
      T sum = y[static_cast<std::size_t>(j)];
      for (int k = start[static_cast<std::size_t>(j)]; k < start[static_cast<std::size_t>(j) + 1]; ++k)
        sum -= value[static_cast<std::size_t>(k)] * y[static_cast<std::size_t>(row[static_cast<std::size_t>(k)])];
      y[static_cast<std::size_t>(j)] = sum;
    }
    for (int i = 0; i < n; ++i) z[i] = static_cast<double>(y[static_cast<std::size_t>(perm[i])]);
    benchmark::DoNotOptimize(z.data());
  }
  state.counters["relative_error"] = (z - expected).norm() / expected.norm();
  state.counters["factor_MB"] = static_cast<double>(L.nonZeros()) * (sizeof(T) + sizeof(int)) / 1e6;
}

void probeEigenSolve(benchmark::State& state) {
  const Ldlt& f = factor();
  const Eigen::VectorXd r = test::randomVector(static_cast<std::size_t>(f.rows()), 5);
  for (auto _ : state) benchmark::DoNotOptimize(f.solve(r).eval().data());
}

void probeSupernodal(benchmark::State& state) {
  const Ldlt& f = factor();
  SupernodalLdlt s;
  if (!s.factor(Eigen::SparseMatrix<double>(beam().A0), f.permutationP().indices())) {
    state.SkipWithError("the beam's rest operator did not factor");
    return;
  }
  const Eigen::VectorXd r = test::randomVector(static_cast<std::size_t>(f.rows()), 5);
  const Eigen::VectorXd expected = f.solve(r);
  Eigen::VectorXd z;
  for (auto _ : state) {
    s.solve(r, z);
    benchmark::DoNotOptimize(z.data());
  }
  state.counters["relative_error"] = (z - expected).norm() / expected.norm();
  state.counters["supernodes"] = static_cast<double>(s.supernodeCount());
  state.counters["top_columns"] = static_cast<double>(s.topColumns());
  state.counters["stored_values"] = static_cast<double>(s.storedValues());
}

/// The library's application of A_0^-1 (WarpedCholesky unwarped: its nested dissection order and
/// supernodal solves on the host's threads).
void probeLibrary(benchmark::State& state) {
  WarpedCholesky& w = warpedFactor();
  w.setNodeRotations({});
  const Eigen::VectorXd r = test::randomVector(beam().free.size(), 5);
  const Eigen::VectorXd expected = factor().solve(r);
  Eigen::VectorXd z;
  for (auto _ : state) {
    w.apply(r, z);
    benchmark::DoNotOptimize(z.data());
  }
  state.counters["relative_error"] = (z - expected).norm() / expected.norm();
  state.counters["factor_entries"] = static_cast<double>(w.factorEntries());
}

void probeSolve(benchmark::State& state, const std::string& kind, double turn) {
  const Beam& b = beam();
  const State st = curled(b, turn);
  const Ldlt& f = factor();
  if (f.info() != Eigen::Success) {
    state.SkipWithError("the rest system is not positive definite");
    return;
  }
  const Eigen::VectorXd dinv = st.A.diagonal().cwiseInverse();
  std::function<Eigen::VectorXd(const Eigen::VectorXd&)> M;
  if (kind == "jacobi") M = [&](const Eigen::VectorXd& r) { return Eigen::VectorXd(dinv.cwiseProduct(r)); };
  // The library's factor of A_0, unwarped (W = I) or warped by the curled beam's node rotations.
  WarpedCholesky& w = warpedFactor();
  if (kind == "rest_cholesky" || kind == "warped_cholesky") {
    w.setNodeRotations(kind == "warped_cholesky" ? st.nodeRotation : std::vector<Mat3>{});
    M = [&](const Eigen::VectorXd& r) {
      Eigen::VectorXd z;
      w.apply(r, z);
      return z;
    };
  }
  // The library's multigrid (precond/amg.hpp) on the same system, as the reference backend runs it:
  // made from A_0, warped by its aggregates' rotations from the positions, smoothed with A_t.
  BodyAmg body;
  AmgFineOperator fine;
  AmgMatrix blocksInverse;
  if (kind == "amg") {
    body.ensure(b.p, b.free, kMass, 1.0);
    WarpedAmg& amg = body.amg();
    amg.setPositions(st.x);
    blocksInverse = nodeBlocks(st.A, b.free).second;
    fine.apply = [&](const Eigen::VectorXd& v, Eigen::VectorXd& y) { y = st.A * v; };
    fine.blockInverse = [&](const Eigen::VectorXd& r, Eigen::VectorXd& z) { z = blocksInverse * r; };
    M = [&](const Eigen::VectorXd& r) {
      Eigen::VectorXd z;
      body.amg().apply(fine, r, z);
      return z;
    };
  }
  int iterations = 0;
  for (auto _ : state) iterations = test::textbookPcgIterations(st.A, st.b, M, 1e-6);
  state.counters["iterations"] = iterations;
}

const int registered = [] {
  benchmark::RegisterBenchmark("probeFactor", probeFactor)->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("probeBuild", probeBuild)->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("probeAmgSetup", probeAmgSetup)->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("probeTriangular/eigen", probeEigenSolve)->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("probeTriangular/double", probeTriangular<double>)->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("probeTriangular/float", probeTriangular<float>)->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("probeTriangular/supernodal", probeSupernodal)->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("probeTriangular/library", probeLibrary)->Unit(benchmark::kMillisecond);
  for (const char* kind : {"jacobi", "amg", "rest_cholesky", "warped_cholesky"})
    for (double turn : {0.0, 0.3, 1.0})
      benchmark::RegisterBenchmark(("probeSolve/" + std::string(kind) + "/turn_" + std::to_string(int(std::lround(1000 * turn)))).c_str(),
                                   probeSolve, std::string(kind), turn)
          ->Unit(benchmark::kMillisecond);
  return 0;
}();

}  // namespace

BENCHMARK_MAIN();
