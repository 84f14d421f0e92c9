// The "amg" preconditioner's host side on a device backend (device_amg.hpp).
#include "device/device_amg.hpp"

#include "util/error.hpp"

#include <algorithm>

namespace corofem::detail {

SlicedEll slicedEll(const AmgMatrix& m, std::size_t slice) {
  SlicedEll out;
  const std::size_t rows = static_cast<std::size_t>(m.rows());
  const std::size_t slices = (rows + slice - 1) / slice;
  out.rows = rows;
  out.start.assign(slices + 1, 0);
  for (std::size_t s = 0; s < slices; ++s) {
    std::size_t width = 0;
    for (std::size_t i = slice * s; i < std::min(rows, slice * (s + 1)); ++i)
      width = std::max<std::size_t>(width, static_cast<std::size_t>(m.outerIndexPtr()[i + 1] - m.outerIndexPtr()[i]));
    out.start[s + 1] = static_cast<std::uint32_t>(out.start[s] + slice * width);
  }
  out.cols.assign(out.start[slices], 0);
  out.values.assign(out.start[slices], 0.0);
  for (std::size_t i = 0; i < rows; ++i) {
    const std::size_t s = i / slice, lane = i % slice;
    for (int j = m.outerIndexPtr()[i], k = 0; j < m.outerIndexPtr()[i + 1]; ++j, ++k) {
      const std::size_t at = out.start[s] + slice * static_cast<std::size_t>(k) + lane;
      out.cols[at] = static_cast<std::uint32_t>(m.innerIndexPtr()[j]);
      out.values[at] = m.valuePtr()[j];
    }
  }
  return out;
}

BlockRows blockRows(const AmgMatrix& m, std::size_t rowBlock, std::size_t colBlock, std::size_t pad) {
  if (rowBlock == 0 || colBlock == 0 || static_cast<std::size_t>(m.rows()) % rowBlock != 0 ||
      static_cast<std::size_t>(m.cols()) % colBlock != 0)
    fail(ErrorCode::Internal, "amg: a ", m.rows(), " x ", m.cols(), " matrix is not made of ", rowBlock, " x ", colBlock,
         " blocks");
  BlockRows out;
  out.rowBlock = rowBlock;
  out.colBlock = colBlock;
  out.blockRows = static_cast<std::size_t>(m.rows()) / rowBlock;
  out.start.assign(1, 0);
  const std::size_t area = rowBlock * colBlock;
  std::vector<std::uint32_t> blockCols;
  // seen[c]: the last block row that met block column c, + 1 (each block column listed once).
  std::vector<std::size_t> seen(static_cast<std::size_t>(m.cols()) / colBlock, 0);
  for (std::size_t i = 0; i < out.blockRows; ++i) {
    blockCols.clear();  // the block row's block columns, ascending
    for (std::size_t r = 0; r < rowBlock; ++r)
      for (AmgMatrix::InnerIterator it(m, static_cast<Eigen::Index>(rowBlock * i + r)); it; ++it) {
        const std::size_t c = static_cast<std::size_t>(it.col()) / colBlock;
        if (seen[c] == i + 1) continue;
        seen[c] = i + 1;
        blockCols.push_back(static_cast<std::uint32_t>(c));
      }
    std::sort(blockCols.begin(), blockCols.end());
    const std::size_t first = out.cols.size();
    out.cols.insert(out.cols.end(), blockCols.begin(), blockCols.end());
    out.values.resize(out.cols.size() * area, 0.0);
    for (std::size_t r = 0; r < rowBlock; ++r) {
      std::size_t j = first;  // a row's columns ascend, and so do the block columns
      for (AmgMatrix::InnerIterator it(m, static_cast<Eigen::Index>(rowBlock * i + r)); it; ++it) {
        const std::size_t col = static_cast<std::size_t>(it.col());
        while (j < out.cols.size() && out.cols[j] != col / colBlock) ++j;
        if (j == out.cols.size()) fail(ErrorCode::Internal, "amg: row ", rowBlock * i + r, " has columns out of order");
        out.values[area * j + rowBlock * (col % colBlock) + r] = it.value();
      }
    }
    out.start.push_back(static_cast<std::uint32_t>(out.cols.size()));
  }
  out.values.resize(out.values.size() + pad, 0.0);
  return out;
}

DeviceAmg::DeviceAmg(const std::vector<BodySegment>& segments)
    : segs_(segments),
      bodies_(segments.size()),
      freeDofs_(segments.size()),
      freeKnown_(segments.size(), 0),
      positions_(segments.size()),
      warpStale_(segments.size(), 1),
      aggregateBegin_(segments.size() + 1, 0) {}

void DeviceAmg::positionsSet(const BodySet& bodies, const ConstVectors& x) {
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    positions_[bodies[i]] = *x[i];
    warpStale_[bodies[i]] = 1;
  }
}

void DeviceAmg::invalidate(std::size_t s) {
  bodies_[s].clear();
  freeKnown_[s] = 0;
  dirty_ = true;
}

void DeviceAmg::constraintsChanged(std::size_t s) { freeKnown_[s] = 0; }

long long DeviceAmg::builds() const {
  long long n = 0;
  for (const BodyAmg& b : bodies_) n += b.builds();
  return n;
}

bool DeviceAmg::prepare(const BodySet& running, const std::vector<std::pair<double, double>>& coefficients) {
  if (coefficients.size() != running.size())
    fail(ErrorCode::Internal, "amg: ", coefficients.size(), " coefficients for ", running.size(), " bodies");
  for (std::size_t i = 0; i < running.size(); ++i) {
    const std::size_t s = running[i];
    const BodySegment& sg = segs_[s];
    if (!freeKnown_[s]) {
      freeDofs_[s] = segmentFreeDofs(sg);
      freeKnown_[s] = 1;
    }
    if (bodies_[s].ensure(*sg.problem, freeDofs_[s], coefficients[i].first, coefficients[i].second) !=
        BodyAmg::Made::Kept) {
      dirty_ = true;
      warpStale_[s] = 1;
    }
  }
  return dirty_;
}

DeviceAmgLayout DeviceAmg::layout(std::size_t nodeTotal, std::size_t block) {
  // Body s's level-k row i (k >= 1) at device row coarseRow[k][s][i], the bodies in turn.
  const std::size_t K = segs_.size();
  std::size_t depth = 1;
  for (const BodyAmg& b : bodies_) depth = std::max(depth, b.amg().levels().size());
  std::vector<std::vector<std::vector<std::size_t>>> coarseRow(depth, std::vector<std::vector<std::size_t>>(K));
  std::vector<std::size_t> rows(depth, 0);
  rows[0] = 3 * nodeTotal;
  for (std::size_t k = 1; k < depth; ++k)
    for (std::size_t s = 0; s < K; ++s) {
      const auto& levels = bodies_[s].amg().levels();
      if (k >= levels.size()) continue;
      std::vector<std::size_t>& at = coarseRow[k][s];
      const std::vector<int>& vs = levels[k].vertexStart;
      if (block == 0) {
        for (Eigen::Index i = 0; i < levels[k].A.rows(); ++i) at.push_back(rows[k] + static_cast<std::size_t>(i));
        rows[k] += static_cast<std::size_t>(levels[k].A.rows());
        continue;
      }
      if (vs.empty() || static_cast<Eigen::Index>(vs.back()) != levels[k].A.rows())
        fail(ErrorCode::Internal, "amg: level ", k, " of body ", s, " has no vertex blocks for its rows");
      for (std::size_t v = 0; v + 1 < vs.size(); ++v) {
        const int size = vs[v + 1] - vs[v];
        if (size < 0 || static_cast<std::size_t>(size) > block)
          fail(ErrorCode::Internal, "amg: a vertex of ", size, " rows on level ", k, " of body ", s, " (blocks of ", block, ")");
        for (int r = 0; r < size; ++r) at.push_back(rows[k] + block * v + static_cast<std::size_t>(r));
      }
      rows[k] += block * (vs.size() - 1);
    }
  // Body s's level-0 row i (the i-th free dof its hierarchy was built on) is device dof dofBegin +
  // device dof of that dof.
  std::vector<std::vector<std::size_t>> fineRow(K);
  for (std::size_t s = 0; s < K; ++s) {
    const BodySegment& sg = segs_[s];
    std::vector<std::size_t> deviceDof(sg.dofs());
    for (std::size_t d = 0; d < sg.dofs(); ++d) deviceDof[sg.hostDof(d)] = d;
    for (Eigen::Index dof : bodies_[s].amg().builtFreeDofs())
      fineRow[s].push_back(sg.dofBegin() + deviceDof[static_cast<std::size_t>(dof)]);
  }
  auto transposed = [](const AmgMatrix& m) { return AmgMatrix(m.transpose()); };  // P^T, as each body's Pt
  DeviceAmgLayout out;
  out.block = block;
  out.levels.resize(depth - 1);
  {
    std::vector<MatrixBlock> p;
    for (std::size_t s = 0; s < K; ++s) {
      const auto& levels = bodies_[s].amg().levels();
      if (levels.size() < 2) continue;
      MatrixBlock b;
      b.sparse = &levels[0].P;
      b.rowMap = &fineRow[s];
      b.colMap = &coarseRow[1][s];
      p.push_back(b);
    }
    out.P0 = joined(rows[0], depth > 1 ? rows[1] : 0, p);
    out.Pt0 = transposed(out.P0);
  }
  std::vector<Eigen::MatrixXd> inverses(K);
  for (std::size_t k = 1; k < depth; ++k) {
    DeviceAmgLevel& L = out.levels[k - 1];
    L.rows = rows[k];
    L.dinv.assign(rows[k], 0.0);
    std::vector<MatrixBlock> a, p, inv;
    for (std::size_t s = 0; s < K; ++s) {
      const auto& levels = bodies_[s].amg().levels();
      if (k >= levels.size()) continue;
      MatrixBlock b;
      b.rowMap = b.colMap = &coarseRow[k][s];
      if (k + 1 == levels.size()) {  // the body's coarsest: its dense inverse, no smoothing
        inverses[s] = bodies_[s].amg().coarsestInverse();
        b.dense = &inverses[s];
        inv.push_back(b);
        continue;
      }
      const AmgLevel& level = levels[k];
      b.sparse = &level.A;
      a.push_back(b);
      b.sparse = &level.P;
      b.colMap = &coarseRow[k + 1][s];
      p.push_back(b);
      for (Eigen::Index i = 0; i < level.A.rows(); ++i)
        L.dinv[coarseRow[k][s][static_cast<std::size_t>(i)]] = level.diagInv[i] / level.lambdaMax;
    }
    const std::size_t next = k + 1 < depth ? rows[k + 1] : 0;
    L.A = joined(rows[k], rows[k], a);
    L.P = joined(rows[k], next, p);
    L.Pt = transposed(L.P);
    L.inverse = joined(rows[k], rows[k], inv);
    L.inverseEntries = static_cast<std::size_t>(L.inverse.nonZeros());
    L.smooths = !a.empty();
  }
  // Level 0's 1 / lambda_max per segment; the warp's node table.
  out.scale.assign(K, 1.0);
  out.nodeAggregate.assign(nodeTotal, -1);
  aggregateBegin_.assign(K + 1, 0);
  for (std::size_t s = 0; s < K; ++s) {
    const BodySegment& sg = segs_[s];
    const WarpedAmg& amg = bodies_[s].amg();
    if (amg.built()) out.scale[s] = 1.0 / amg.fineLambdaMax();
    aggregateBegin_[s + 1] = aggregateBegin_[s] + amg.aggregateCount();
    if (!sg.corotational || amg.levels().empty()) continue;  // linear bodies do not turn: no warp
    const std::vector<int> of = amg.nodeAggregates();
    for (std::size_t d = 0; d < sg.nodes; ++d) {
      const int a = of[sg.hostDof(3 * d) / 3];
      if (a >= 0) out.nodeAggregate[sg.nodeBegin + d] = static_cast<std::int32_t>(aggregateBegin_[s] + static_cast<std::size_t>(a));
    }
  }
  out.aggregates = aggregateBegin_[K];
  return out;
}

void DeviceAmg::layoutUploaded() {
  std::fill(warpStale_.begin(), warpStale_.end(), 1);
  dirty_ = false;
}

void DeviceAmg::warps(const BodySet& running, const std::function<void(std::size_t, const std::vector<double>&)>& fn) {
  for (std::size_t s : running) {
    if (!warpStale_[s] || !segs_[s].corotational || positions_[s].size() == 0) continue;
    WarpedAmg& amg = bodies_[s].amg();
    amg.setPositions(positions_[s]);
    const std::vector<Mat3>& R = amg.aggregateRotations();
    std::vector<double> values(9 * R.size());
    for (std::size_t a = 0; a < R.size(); ++a)
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) values[9 * a + static_cast<std::size_t>(3 * i + j)] = R[a](i, j);
    if (!values.empty()) fn(aggregateBegin_[s], values);
    warpStale_[s] = 0;
  }
}

}  // namespace corofem::detail
