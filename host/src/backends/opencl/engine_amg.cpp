// The "amg" preconditioner on the OpenCL engine (engine_amg.hpp).
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/engine_amg.hpp"

#include "backends/opencl/segment_engine.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <cmath>

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

EngineAmg::EngineAmg(SegmentEngine& engine) : e_(engine), host_(engine.segs_) {}

void EngineAmg::createKernels() {
  const cl_program program = e_.build_.program;
  kFineBegin_.create(program, "amg_fine_begin", e_.dev_);
  kFinePass_.create(program, "amg_fine_pass", e_.dev_);
  kUnwarp_.create(program, "amg_fine_unwarp", e_.dev_);
  kWarpAdd_.create(program, "amg_fine_warp_add", e_.dev_);
  kSpmv_.create(program, "amg_spmv", e_.dev_);
  kCoarseBegin_.create(program, "amg_coarse_begin", e_.dev_);
  kCoarseStep_.create(program, "amg_coarse_step", e_.dev_);
  kBlocks3x6_.create(program, "amg_blocks_3x6", e_.dev_);
  kBlocks6x3_.create(program, "amg_blocks_6x3", e_.dev_);
  kBlocks6x6_.create(program, "amg_blocks_6x6", e_.dev_);
  kCoarsest_.create(program, "amg_coarsest", e_.dev_);
  const std::size_t fine = 3 * e_.nodeTotal_;
  res0_ = buffer(fine * e_.realSize_);
  d0_ = buffer(fine * e_.realSize_);
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

void EngineAmg::positionsSet(const BodySet& bodies, const ConstVectors& x) { host_.positionsSet(bodies, x); }

void EngineAmg::invalidate(std::size_t s) { host_.invalidate(s); }

void EngineAmg::constraintsChanged(std::size_t s) { host_.constraintsChanged(s); }

long long EngineAmg::builds() const { return host_.builds(); }

void EngineAmg::prepare(const BodySet& running) {
  std::vector<std::pair<double, double>> coefficients;
  for (std::size_t s : running)
    coefficients.emplace_back(e_.operatorMass_[s], e_.segCoef_[layout::kSegCoefCount * s + layout::kCoefStiff]);
  if (host_.prepare(running, coefficients)) upload();
  uploadWarp(running);
}

std::size_t EngineAmg::block() const {
  // Per-work-item sums (CPU devices): the coarse vertices in blocks of 6 rows (an aggregate's
  // rigid modes), read by amg_blocks_*, vector multiply-adds of whole block columns instead of a
  // gather per entry. Work-group sums (GPUs): a row per work-item, whose loads coalesce.
  return e_.treeReduce_ ? 0 : 6;
}

void EngineAmg::putRows(Csr& out, const std::vector<cl_uint>& start, const std::vector<cl_uint>& cols,
                        std::vector<double> values, bool doubleValues) {
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

void EngineAmg::setRows(Csr& out, const AmgMatrix& m, std::size_t rowBlock, std::size_t colBlock) {
  // m is row-major with the device's row and column numbering already.
  out.rows = static_cast<std::size_t>(m.rows());
  out.rowBlock = out.colBlock = 0;
  if (rowBlock > 0 && colBlock > 0) {
    // The kernels load a block column as a vector of 4 or 8 reals: 8 past the last block.
    BlockRows blocks = blockRows(m, rowBlock, colBlock, 8);
    out.rowBlock = rowBlock;
    out.colBlock = colBlock;
    putRows(out, blocks.start, blocks.cols, std::move(blocks.values), false);
    return;
  }
  SlicedEll ell = slicedEll(m, kSlice);
  putRows(out, ell.start, ell.cols, std::move(ell.values), false);
}

void EngineAmg::setCsr(Csr& out, const AmgMatrix& m, bool doubleValues) {
  out.rows = static_cast<std::size_t>(m.rows());
  out.rowBlock = out.colBlock = 0;
  const std::vector<cl_uint> start(m.outerIndexPtr(), m.outerIndexPtr() + m.rows() + 1),
      cols(m.innerIndexPtr(), m.innerIndexPtr() + m.nonZeros());
  putRows(out, start, cols, std::vector<double>(m.valuePtr(), m.valuePtr() + m.nonZeros()), doubleValues);
}

void EngineAmg::upload() {
  const std::size_t B = block();
  const DeviceAmgLayout layout = host_.layout(e_.nodeTotal_, B);
  setRows(P0_, layout.P0, B ? 3 : 0, B);
  setRows(Pt0_, layout.Pt0, B, B ? 3 : 0);
  levels_.clear();
  levels_.resize(layout.levels.size());
  for (std::size_t k = 0; k < layout.levels.size(); ++k) {
    const DeviceAmgLevel& from = layout.levels[k];
    Level& L = levels_[k];
    L.rows = from.rows;
    setRows(L.A, from.A, B, B);
    setRows(L.P, from.P, B, B);
    setRows(L.Pt, from.Pt, B, B);
    setCsr(L.inverse, from.inverse, e_.ctx_->info().fp64);
    L.inverseEntries = from.inverseEntries;
    L.smooths = from.smooths;
    L.dinv = reals(from.dinv);
    // Zeros to begin with: a blocked layout's padding rows are read (times zero) and only the
    // smoothing writes them, which a body's coarsest level does not run.
    const std::vector<double> zeros(std::max<std::size_t>(from.rows, 1), 0.0);
    for (auto* v : {&L.b, &L.x, &L.res, &L.d, &L.t}) *v = reals(zeros);
  }
  scale_ = reals(layout.scale);
  std::vector<cl_int> nodeAggregate(layout.nodeAggregate.begin(), layout.nodeAggregate.end());
  nodeAggregate_ = buffer(nodeAggregate.size() * sizeof(cl_int));
  e_.uploadRaw(*nodeAggregate_, nodeAggregate);
  // Every aggregate at I until its body's positions give its rotation (a solve before any
  // setPositions, or a body handed over by a failover without positions, runs unwarped).
  std::vector<double> identity(std::max<std::size_t>(9 * layout.aggregates, 9), 0.0);
  for (std::size_t a = 0; 9 * a < identity.size(); ++a) identity[9 * a] = identity[9 * a + 4] = identity[9 * a + 8] = 1.0;
  rotations_ = reals(identity);
  host_.layoutUploaded();
}

void EngineAmg::uploadWarp(const BodySet& running) {
  host_.warps(running, [&](std::size_t first, const std::vector<double>& values) {
    e_.enqueueWrite(*rotations_, 9 * first * e_.realSize_, realBytes(values, e_.double_));
  });
}

void EngineAmg::spmv(const Csr& m, const ClBuffer& x, const ClBuffer* b, cl_uint mode, const ClBuffer& y) {
  if (m.rows == 0) return;
  static const ClBuffer none;
  if (m.rowBlock > 0) {
    const ClKernel& k = m.rowBlock == 3 ? kBlocks3x6_ : m.colBlock == 3 ? kBlocks6x3_ : kBlocks6x6_;
    const std::size_t items = m.rows / m.rowBlock, global = (items + kBlockGroup - 1) / kBlockGroup * kBlockGroup;
    e_.launchRange(k, 0, global, kBlockGroup, cl_uint(items), *m.start, *m.cols, *m.values, x, b ? *b : none, mode, y);
    return;
  }
  // GPUs: a row per work-item (the engine's work-group size).
  const std::size_t global = (m.rows + e_.wg_ - 1) / e_.wg_ * e_.wg_;
  e_.launchRange(kSpmv_, 0, global, e_.wg_, cl_uint(m.rows), *m.start, *m.cols, *m.values, x, b ? *b : none, mode, y);
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
    spmv(L.P, *N.x, nullptr, 2, *L.x);  // x += P e
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
  // Level 0: z = M^-1 r with the current operator. Each product's gather is the first part of the
  // pass that reads it (amg.cl: A u is never stored).
  auto gathered = [&](const ClKernel& k, const ClBuffer& u, auto&&... args) {
    e.elementProduct(u);
    e.launch(k, Span::NodeChunks, e.nodeSeg_, e.segInfoBuf_, e.segCoefBuf_, e.nodeStart_, e.nodeEntries_, e.elemOut_,
             e.mass_, e.free_, args...);
  };
  e.launch(kFineBegin_, Span::Nodes, e.nodeSeg_, e.segInfoBuf_, *scale_, e.minv_, e.r_, R{ch.invTheta}, *res0_, *d0_,
           e.z_);
  gathered(kFinePass_, *d0_, *scale_, e.minv_, *d0_, *res0_, R{ch.c1}, R{ch.c2}, *res0_, *d0_, e.z_, cl_uint(0), none, none,
           none);
  if (!levels_.empty()) {
    gathered(kUnwarp_, e.z_, e.z_, *nodeAggregate_, *rotations_, e.r_, *e0_);
    spmv(Pt0_, *e0_, nullptr, 0, *levels_[0].b);
    coarse(1);
    spmv(P0_, *levels_[0].x, nullptr, 0, *e0_);
    e.launch(kWarpAdd_, Span::Nodes, e.nodeSeg_, e.segInfoBuf_, *nodeAggregate_, *rotations_, *e0_, e.free_, e.z_);
  }
  gathered(kFinePass_, e.z_, *scale_, e.minv_, e.z_, e.r_, R{0.0}, R{ch.invTheta}, *res0_, *d0_, e.z_, cl_uint(0), none,
           none, none);
  gathered(kFinePass_, *d0_, *scale_, e.minv_, *d0_, *res0_, R{ch.c1}, R{ch.c2}, *res0_, *d0_, e.z_, cl_uint(1), e.r_,
           setup ? e.b_ : none, e.partials_);
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
