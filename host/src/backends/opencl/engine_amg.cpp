// The "amg" preconditioner on the OpenCL engine (engine_amg.hpp).
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/engine_amg.hpp"

#include "backends/opencl/segment_engine.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <cmath>
#include <type_traits>

namespace corofem::detail {

namespace layout {
#include "../../../../kernels/shared/corofem_layout.h"
}  // namespace layout

namespace {

/// Chebyshev over [1/30, 1] of the scaled D^-1 A, degree 2 (WarpedAmg::kChebyshevDegree): 1 / theta,
/// and the coefficients of its one step, d = c1 d + c2 D^-1 res.
struct Chebyshev {
  double invTheta, c1, c2;
  Chebyshev() {
    static_assert(WarpedAmg::kChebyshevDegree == 2, "the device's cycle runs one Chebyshev step");
    const double hi = 1.0, lo = 1.0 / 30.0, theta = 0.5 * (hi + lo), delta = 0.5 * (hi - lo), sigma = theta / delta;
    const double rho = 1.0 / sigma, rhoNew = 1.0 / (2.0 * sigma - rho);
    invTheta = 1.0 / theta;
    c1 = rhoNew * rho;
    c2 = 2.0 * rhoNew / delta;
  }
};

}  // namespace

EngineAmg::EngineAmg(SegmentEngine& engine) : e_(engine), bodies_(engine.segs_.size()) {
  const std::size_t K = e_.segs_.size();
  freeDofs_.resize(K);
  positions_.resize(K);
  warpStale_.assign(K, 1);
  freeKnown_.assign(K, 0);
}

void EngineAmg::createKernels() {
  const cl_program program = e_.build_.program;
  kFineBegin_.create(program, "amg_fine_begin", e_.dev_);
  kFineStep_.create(program, "amg_fine_step", e_.dev_);
  kUnwarp_.create(program, "amg_fine_unwarp", e_.dev_);
  kWarpAdd_.create(program, "amg_fine_warp_add", e_.dev_);
  kSpmv_.create(program, "amg_spmv", e_.dev_);
  kSpmvSlices_.create(program, "amg_spmv_slices", e_.dev_);
  kCoarseBegin_.create(program, "amg_coarse_begin", e_.dev_);
  kCoarseStep_.create(program, "amg_coarse_step", e_.dev_);
  kCoarseAdd_.create(program, "amg_coarse_add", e_.dev_);
  kCoarsest_.create(program, "amg_coarsest", e_.dev_);
  const std::size_t fine = 3 * e_.nodeTotal_;
  res0_ = buffer(fine * e_.realSize_);
  d0_ = buffer(fine * e_.realSize_);
  ad0_ = buffer(fine * e_.realSize_);
  e0_ = buffer(fine * e_.realSize_);
}

std::unique_ptr<ClBuffer> EngineAmg::buffer(std::size_t bytes) {
  auto b = std::make_unique<ClBuffer>();
  b->create(e_.ctx_->context(), bytes, e_.dev_);
  return b;
}

std::unique_ptr<ClBuffer> EngineAmg::reals(const std::vector<double>& values) {
  auto b = buffer(values.size() * e_.realSize_);
  e_.upload(*b, values.data(), 0, values.size());
  return b;
}

void EngineAmg::positionsSet(const BodySet& bodies, const ConstVectors& x) {
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    positions_[bodies[i]] = *x[i];
    warpStale_[bodies[i]] = 1;
  }
}

void EngineAmg::invalidate(std::size_t s) {
  bodies_[s].clear();
  freeKnown_[s] = 0;
  dirty_ = true;
}

void EngineAmg::constraintsChanged(std::size_t s) { freeKnown_[s] = 0; }

long long EngineAmg::builds() const {
  long long n = 0;
  for (const BodyAmg& b : bodies_) n += b.builds();
  return n;
}

void EngineAmg::prepare(const BodySet& running) {
  for (std::size_t s : running) {
    const BodySegment& sg = e_.segs_[s];
    const Problem& p = *sg.problem;
    if (!freeKnown_[s]) {  // the free dofs in the problem's numbering (the segment keeps its mask in the device's)
      std::vector<std::uint8_t> constrained(sg.dofs());
      for (std::size_t d = 0; d < sg.dofs(); ++d) constrained[sg.hostDof(d)] = sg.constrained[d];
      freeDofs_[s].clear();
      for (std::size_t d = 0; d < constrained.size(); ++d)
        if (!constrained[d]) freeDofs_[s].push_back(static_cast<Eigen::Index>(d));
      freeKnown_[s] = 1;
    }
    const double* coef = &e_.segCoef_[layout::kSegCoefCount * s];
    if (bodies_[s].ensure(p, freeDofs_[s], e_.operatorMass_[s], coef[layout::kCoefStiff]) != BodyAmg::Made::Kept) {
      dirty_ = true;
      warpStale_[s] = 1;
    }
  }
  if (dirty_) upload();
  uploadWarp(running);
}

void EngineAmg::setRows(Csr& out, const AmgMatrix& m, bool csr, bool doubleValues) {
  // m is row-major with the device's row and column numbering already: CSR for the coarsest
  // inverse (amg_coarsest), sliced ELLPACK (amg_spmv) for the others.
  const std::size_t rows = static_cast<std::size_t>(m.rows());
  std::vector<cl_uint> start, cols;
  std::vector<double> values;
  if (csr) {
    start.resize(rows + 1);
    for (std::size_t i = 0; i <= rows; ++i) start[i] = static_cast<cl_uint>(m.outerIndexPtr()[i]);
    cols.assign(m.innerIndexPtr(), m.innerIndexPtr() + m.nonZeros());
    values.assign(m.valuePtr(), m.valuePtr() + m.nonZeros());
  } else {
    const std::size_t slices = (rows + kSlice - 1) / kSlice;
    start.assign(slices + 1, 0);
    for (std::size_t s = 0; s < slices; ++s) {
      std::size_t width = 0;
      for (std::size_t i = kSlice * s; i < std::min(rows, kSlice * (s + 1)); ++i)
        width = std::max<std::size_t>(width, static_cast<std::size_t>(m.outerIndexPtr()[i + 1] - m.outerIndexPtr()[i]));
      start[s + 1] = static_cast<cl_uint>(start[s] + kSlice * width);
    }
    cols.assign(start[slices], 0);
    values.assign(start[slices], 0.0);
    for (std::size_t i = 0; i < rows; ++i) {
      const std::size_t s = i / kSlice, lane = i % kSlice;
      for (int j = m.outerIndexPtr()[i], k = 0; j < m.outerIndexPtr()[i + 1]; ++j, ++k) {
        cols[start[s] + kSlice * static_cast<std::size_t>(k) + lane] = static_cast<cl_uint>(m.innerIndexPtr()[j]);
        values[start[s] + kSlice * static_cast<std::size_t>(k) + lane] = m.valuePtr()[j];
      }
    }
  }
  out.rows = rows;
  out.start = buffer(start.size() * sizeof(cl_uint));
  e_.uploadRaw(*out.start, start);
  out.cols = buffer(std::max<std::size_t>(cols.size(), 1) * sizeof(cl_uint));
  if (!cols.empty()) e_.uploadRaw(*out.cols, cols);
  if (values.empty()) values.push_back(0.0);
  if (doubleValues) {
    out.values = buffer(values.size() * sizeof(double));
    e_.uploadRaw(*out.values, values);
  } else {
    out.values = reals(values);
  }
}

void EngineAmg::upload() {
  // Every body's levels end to end: body s's rows of device level k from offset[k][s]. Level 0 is
  // the device's dof numbering (3 per node, padding and constrained dofs included).
  const std::size_t K = e_.segs_.size();
  std::size_t depth = 1;
  for (const BodyAmg& b : bodies_) depth = std::max(depth, b.amg().levels().size());
  std::vector<std::vector<std::size_t>> offset(depth, std::vector<std::size_t>(K, 0));
  std::vector<std::size_t> rows(depth, 0);
  rows[0] = 3 * e_.nodeTotal_;
  for (std::size_t k = 1; k < depth; ++k)
    for (std::size_t s = 0; s < K; ++s) {
      offset[k][s] = rows[k];
      const auto& levels = bodies_[s].amg().levels();
      if (k < levels.size()) rows[k] += static_cast<std::size_t>(levels[k].A.rows());
    }
  // Body s's level-0 row i (the i-th free dof its hierarchy was built on) is device dof dofBegin +
  // device dof of that dof.
  std::vector<std::vector<std::size_t>> fineRow(K);
  for (std::size_t s = 0; s < K; ++s) {
    const BodySegment& sg = e_.segs_[s];
    std::vector<std::size_t> deviceDof(sg.dofs());
    for (std::size_t d = 0; d < sg.dofs(); ++d) deviceDof[sg.hostDof(d)] = d;
    for (Eigen::Index dof : bodies_[s].amg().builtFreeDofs())
      fineRow[s].push_back(sg.dofBegin() + deviceDof[static_cast<std::size_t>(dof)]);
  }
  using Triplets = std::vector<Eigen::Triplet<double, int>>;
  // row(k, s, i): the device row of body s's row i on level k.
  auto row = [&](std::size_t k, std::size_t s, Eigen::Index i) {
    return static_cast<int>(k == 0 ? fineRow[s][static_cast<std::size_t>(i)] : offset[k][s] + static_cast<std::size_t>(i));
  };
  auto add = [&](Triplets& t, const AmgMatrix& m, std::size_t rk, std::size_t ck, std::size_t s) {
    for (Eigen::Index i = 0; i < m.outerSize(); ++i)
      for (AmgMatrix::InnerIterator it(m, i); it; ++it) t.emplace_back(row(rk, s, i), row(ck, s, it.col()), it.value());
  };
  auto matrix = [&](const Triplets& t, std::size_t r, std::size_t c) {
    AmgMatrix m(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c));
    m.setFromTriplets(t.begin(), t.end());
    return m;
  };
  levels_.clear();
  levels_.resize(depth - 1);
  {
    Triplets p, pt;
    for (std::size_t s = 0; s < K; ++s) {
      const auto& levels = bodies_[s].amg().levels();
      if (levels.size() < 2) continue;
      add(p, levels[0].P, 0, 1, s);
      add(pt, levels[0].Pt, 1, 0, s);
    }
    setRows(P0_, matrix(p, rows[0], depth > 1 ? rows[1] : 0));
    setRows(Pt0_, matrix(pt, depth > 1 ? rows[1] : 0, rows[0]));
  }
  for (std::size_t k = 1; k < depth; ++k) {
    Level& L = levels_[k - 1];
    L.rows = rows[k];
    Triplets a, p, pt, inv;
    std::vector<double> dinv(rows[k], 0.0);
    for (std::size_t s = 0; s < K; ++s) {
      const auto& levels = bodies_[s].amg().levels();
      if (k >= levels.size()) continue;
      if (k + 1 == levels.size()) {  // the body's coarsest: its dense inverse, no smoothing
        const Eigen::MatrixXd M = bodies_[s].amg().coarsestInverse();
        for (Eigen::Index i = 0; i < M.rows(); ++i)
          for (Eigen::Index j = 0; j < M.cols(); ++j) inv.emplace_back(row(k, s, i), row(k, s, j), M(i, j));
        continue;
      }
      const AmgLevel& level = levels[k];
      add(a, level.A, k, k, s);
      add(p, level.P, k, k + 1, s);
      add(pt, level.Pt, k + 1, k, s);
      for (Eigen::Index i = 0; i < level.A.rows(); ++i)
        dinv[static_cast<std::size_t>(row(k, s, i))] = level.diagInv[i] / level.lambdaMax;
    }
    const std::size_t next = k + 1 < depth ? rows[k + 1] : 0;
    setRows(L.A, matrix(a, rows[k], rows[k]));
    setRows(L.P, matrix(p, rows[k], next));
    setRows(L.Pt, matrix(pt, next, rows[k]));
    setRows(L.inverse, matrix(inv, rows[k], rows[k]), true, e_.ctx_->info().fp64);
    L.inverseEntries = inv.size();
    L.smooths = !a.empty();
    L.dinv = reals(dinv);
    for (auto* v : {&L.b, &L.x, &L.res, &L.d, &L.t}) *v = buffer(std::max<std::size_t>(rows[k], 1) * e_.realSize_);
  }
  // The fine level's 1 / lambda_max per segment; the warp's node table.
  std::vector<double> scale(K, 1.0);
  std::vector<cl_int> nodeAggregate(e_.nodeTotal_, -1);
  aggregateBegin_.assign(K + 1, 0);
  for (std::size_t s = 0; s < K; ++s) {
    const BodySegment& sg = e_.segs_[s];
    const WarpedAmg& amg = bodies_[s].amg();
    if (amg.built()) scale[s] = 1.0 / amg.fineLambdaMax();
    aggregateBegin_[s + 1] = aggregateBegin_[s] + amg.aggregateCount();
    if (!sg.corotational || amg.levels().empty()) continue;  // linear bodies do not turn: no warp
    const std::vector<int> of = amg.nodeAggregates();
    for (std::size_t d = 0; d < sg.nodes; ++d) {
      const int a = of[sg.hostDof(3 * d) / 3];
      if (a >= 0) nodeAggregate[sg.nodeBegin + d] = static_cast<cl_int>(aggregateBegin_[s] + static_cast<std::size_t>(a));
    }
  }
  scale_ = reals(scale);
  nodeAggregate_ = buffer(nodeAggregate.size() * sizeof(cl_int));
  e_.uploadRaw(*nodeAggregate_, nodeAggregate);
  // Every aggregate at I until its body's positions give its rotation (a solve before any
  // setPositions, or a body handed over by a failover without positions, runs unwarped).
  std::vector<double> identity(std::max<std::size_t>(9 * aggregateBegin_[K], 9), 0.0);
  for (std::size_t a = 0; 9 * a < identity.size(); ++a) identity[9 * a] = identity[9 * a + 4] = identity[9 * a + 8] = 1.0;
  rotations_ = reals(identity);
  std::fill(warpStale_.begin(), warpStale_.end(), 1);
  dirty_ = false;
}

void EngineAmg::uploadWarp(const BodySet& running) {
  for (std::size_t s : running) {
    if (!warpStale_[s] || !e_.segs_[s].corotational || positions_[s].size() == 0) continue;
    WarpedAmg& amg = bodies_[s].amg();
    amg.setPositions(positions_[s]);
    const std::vector<Mat3>& R = amg.aggregateRotations();
    std::vector<double> values(9 * R.size());
    for (std::size_t a = 0; a < R.size(); ++a)
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) values[9 * a + static_cast<std::size_t>(3 * i + j)] = R[a](i, j);
    std::vector<unsigned char> bytes(values.size() * e_.realSize_);
    withReals(bytes.data(), e_.double_, 0, [&](auto* out) {
      for (std::size_t i = 0; i < values.size(); ++i) out[i] = static_cast<std::remove_pointer_t<decltype(out)>>(values[i]);
    });
    e_.enqueueWrite(*rotations_, 9 * aggregateBegin_[s] * e_.realSize_, std::move(bytes));
    warpStale_[s] = 0;
  }
}

void EngineAmg::spmv(const Csr& m, const ClBuffer& x, const ClBuffer* b, cl_uint mode, const ClBuffer& y) {
  if (m.rows == 0) return;
  static const ClBuffer none;
  // A work-item per slice on CPUs (vector code), per row on GPUs (engine: work-group trees).
  const bool perSlice = !e_.treeReduce_;
  const std::size_t items = perSlice ? (m.rows + kSlice - 1) / kSlice : m.rows;
  const std::size_t wg = perSlice ? kSlice : e_.wg_, global = (items + wg - 1) / wg * wg;
  e_.launchRange(perSlice ? kSpmvSlices_ : kSpmv_, 0, global, wg, cl_uint(m.rows), *m.start, *m.cols, *m.values, x, b ? *b : none, mode, y);
}

void EngineAmg::coarse(std::size_t k) {
  // The V-cycle on device level k (>= 1) for L.b into L.x.
  static const Chebyshev ch;
  Level& L = levels_[k - 1];
  const std::size_t wg = e_.wg_, global = (L.rows + wg - 1) / wg * wg;
  const bool deeper = k < levels_.size();
  using R = SegmentEngine::RealArg;
  if (!L.smooths) {  // every body's coarsest level: its exact solve alone
    e_.launchRange(kCoarsest_, 0, global, wg, cl_uint(L.rows), *L.inverse.start, *L.inverse.cols, *L.inverse.values,
                   *L.b, *L.x);
    return;
  }
  // Pre-smoothing from 0.
  e_.launchRange(kCoarseBegin_, 0, global, wg, cl_uint(L.rows), *L.dinv, *L.b, *L.b, cl_uint(1), R{ch.invTheta}, *L.res,
                 *L.d, *L.x);
  spmv(L.A, *L.d, nullptr, 0, *L.t);
  e_.launchRange(kCoarseStep_, 0, global, wg, cl_uint(L.rows), *L.dinv, *L.t, R{ch.c1}, R{ch.c2}, *L.res, *L.d, *L.x);
  if (deeper) {
    Level& N = levels_[k];
    spmv(L.A, *L.x, L.b.get(), 1, *L.t);  // t = b - A x
    spmv(L.Pt, *L.t, nullptr, 0, *N.b);
    coarse(k + 1);
    spmv(L.P, *N.x, nullptr, 0, *L.t);
    e_.launchRange(kCoarseAdd_, 0, global, wg, cl_uint(L.rows), *L.t, *L.x);
  }
  // Post-smoothing.
  spmv(L.A, *L.x, nullptr, 0, *L.t);
  e_.launchRange(kCoarseBegin_, 0, global, wg, cl_uint(L.rows), *L.dinv, *L.b, *L.t, cl_uint(0), R{ch.invTheta}, *L.res,
                 *L.d, *L.x);
  spmv(L.A, *L.d, nullptr, 0, *L.t);
  e_.launchRange(kCoarseStep_, 0, global, wg, cl_uint(L.rows), *L.dinv, *L.t, R{ch.c1}, R{ch.c2}, *L.res, *L.d, *L.x);
  // The bodies whose coarsest level this is: x = A^-1 b (only their rows).
  if (L.inverseEntries > 0)
    e_.launchRange(kCoarsest_, 0, global, wg, cl_uint(L.rows), *L.inverse.start, *L.inverse.cols, *L.inverse.values,
                   *L.b, *L.x);
}

void EngineAmg::cycle(bool setup) {
  using Span = SegmentEngine::Span;
  using R = SegmentEngine::RealArg;
  static const Chebyshev ch;
  static const ClBuffer none;
  SegmentEngine& e = e_;
  // Level 0: z = M^-1 r with the current operator (projected products into ad0).
  e.launch(kFineBegin_, Span::Nodes, e.nodeSeg_, e.segInfoBuf_, *scale_, e.minv_, e.r_, e.r_, cl_uint(1),
           R{ch.invTheta}, *res0_, *d0_, e.z_);
  e.product(*d0_, *ad0_, true, e.partialsW_);
  e.launch(kFineStep_, Span::NodeChunks, e.nodeSeg_, e.segInfoBuf_, *scale_, e.minv_, *ad0_, R{ch.c1}, R{ch.c2}, *res0_,
           *d0_, e.z_, cl_uint(0), none, none, none, none);
  if (!levels_.empty()) {
    e.product(e.z_, *ad0_, true, e.partialsW_);
    e.launch(kUnwarp_, Span::Nodes, e.nodeSeg_, e.segInfoBuf_, *nodeAggregate_, *rotations_, e.r_, *ad0_, *e0_);
    spmv(Pt0_, *e0_, nullptr, 0, *levels_[0].b);
    coarse(1);
    spmv(P0_, *levels_[0].x, nullptr, 0, *e0_);
    e.launch(kWarpAdd_, Span::Nodes, e.nodeSeg_, e.segInfoBuf_, *nodeAggregate_, *rotations_, *e0_, e.free_, e.z_);
  }
  e.product(e.z_, *ad0_, true, e.partialsW_);
  e.launch(kFineBegin_, Span::Nodes, e.nodeSeg_, e.segInfoBuf_, *scale_, e.minv_, e.r_, *ad0_, cl_uint(0),
           R{ch.invTheta}, *res0_, *d0_, e.z_);
  e.product(*d0_, *ad0_, true, e.partialsW_);
  e.launch(kFineStep_, Span::NodeChunks, e.nodeSeg_, e.segInfoBuf_, *scale_, e.minv_, *ad0_, R{ch.c1}, R{ch.c2}, *res0_,
           *d0_, e.z_, cl_uint(1), e.r_, setup ? e.b_ : none, e.free_, e.partials_);
}

std::vector<DeviceBuffer> EngineAmg::buffers() const {
  std::vector<DeviceBuffer> out;
  auto put = [&](const char* name, const std::unique_ptr<ClBuffer>& b) {
    if (b) out.push_back({name, b->bytes()});
  };
  auto csr = [&](const char* name, const Csr& m) {
    if (!m.start) return;
    out.push_back({name, m.start->bytes() + m.cols->bytes() + m.values->bytes()});
  };
  put("amg level-0 vectors", res0_);
  put("amg level-0 vectors", d0_);
  put("amg level-0 vectors", ad0_);
  put("amg level-0 vectors", e0_);
  put("amg warp", nodeAggregate_);
  put("amg warp", rotations_);
  csr("amg prolongation", P0_);
  csr("amg restriction", Pt0_);
  for (const Level& L : levels_) {
    csr("amg coarse operator", L.A);
    csr("amg prolongation", L.P);
    csr("amg restriction", L.Pt);
    csr("amg coarsest inverse", L.inverse);
    for (auto* v : {&L.dinv, &L.b, &L.x, &L.res, &L.d, &L.t}) put("amg coarse vectors", *v);
  }
  return out;
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
