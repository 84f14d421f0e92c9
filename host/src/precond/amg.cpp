// The warped smoothed-aggregation multigrid of precond/amg.hpp.
#include "precond/amg.hpp"

#include "util/error.hpp"
#include "util/parallel.hpp"

#include <Eigen/LU>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <exception>
#include <functional>

namespace corofem::detail {

namespace {

/// Levels stop coarsening at this many dofs (the coarsest is factored, and a device applies its
/// dense inverse) ...
constexpr Eigen::Index kCoarsestDofs = 500;
/// ... or when a level keeps more than this fraction of its finer level's dofs (aggregation stalls
/// on the dense graphs of the coarsest levels) and has at most kMaxCoarsestDofs, or after this many
/// levels. A body of at most kDirectDofs free dofs is not coarsened: its rest operator is the
/// coarsest level (aggregating such small bodies gave far weaker cycles: 17 iterations instead of 2
/// on the conformance suite's linear cube, and an indefinite one on its slab in float).
constexpr double kStallRatio = 0.8;
constexpr Eigen::Index kMaxCoarsestDofs = 2000;
constexpr Eigen::Index kDirectDofs = kCoarsestDofs;
constexpr std::size_t kMaxLevels = 12;
/// Chebyshev smoothing targets the eigenvalues of D^-1 A in [lambda_max / kChebyshevRange, lambda_max].
constexpr double kChebyshevRange = 30.0;
/// The power iteration's estimate of lambda_max is raised by this factor: Chebyshev amplifies any
/// eigenvalue above its interval, and the current operator's spectrum differs a little from the
/// rest operator's it is estimated on.
constexpr double kLambdaMargin = 1.1;
constexpr int kPowerIterations = 20;
/// A QR column of an aggregate's near-null space is kept when |R_jj| exceeds this times the largest
/// (an aggregate of one or two nodes spans fewer than six rigid modes).
constexpr double kRankThreshold = 1e-8;

Eigen::VectorXd inverseDiagonal(const AmgMatrix& A) {
  Eigen::VectorXd d = A.diagonal();
  for (Eigen::Index i = 0; i < d.size(); ++i) d[i] = d[i] != 0.0 ? 1.0 / d[i] : 1.0;
  return d;
}

/// lambda_max(D^-1 A) by power iteration on the similar D^-1/2 A D^-1/2, from a fixed start vector
/// (the set-up is deterministic), times kLambdaMargin.
double estimateLambdaMax(const AmgMatrix& A, const Eigen::VectorXd& diagInv) {
  const Eigen::Index n = A.rows();
  if (n == 0) return 1.0;
  const Eigen::VectorXd s = diagInv.cwiseAbs().cwiseSqrt();
  Eigen::VectorXd v(n);
  for (Eigen::Index i = 0; i < n; ++i) v[i] = std::fmod(0.6180339887 * double(i + 1), 1.0) - 0.5;
  v.normalize();
  double lambda = 1.0;
  for (int k = 0; k < kPowerIterations; ++k) {
    const Eigen::VectorXd w = s.cwiseProduct(amgProduct(A, s.cwiseProduct(v)));
    lambda = v.dot(w);
    const double norm = w.norm();
    if (!(norm > 0.0) || !std::isfinite(norm)) break;
    v = w / norm;
  }
  return std::isfinite(lambda) && lambda > 0.0 ? kLambdaMargin * lambda : 1.0;
}

/// lambda_max(B^-1 A) for the symmetric positive definite block diagonal B of A's node blocks
/// (Binv its inverse): power steps v <- B^-1 A v from a fixed start, the estimate the generalised
/// Rayleigh quotient v.Av / v.Bv, times kLambdaMargin.
double estimateBlockLambdaMax(const AmgMatrix& A, const AmgMatrix& B, const AmgMatrix& Binv) {
  const Eigen::Index n = A.rows();
  if (n == 0) return 1.0;
  Eigen::VectorXd v(n);
  for (Eigen::Index i = 0; i < n; ++i) v[i] = std::fmod(0.6180339887 * double(i + 1), 1.0) - 0.5;
  double lambda = 1.0;
  for (int k = 0; k < kPowerIterations; ++k) {
    const Eigen::VectorXd w = amgProduct(A, v), z = Binv * w;
    lambda = v.dot(w) / std::max(v.dot(B * v), 1e-300);
    const double norm = z.norm();
    if (!(norm > 0.0) || !std::isfinite(norm)) break;
    v = z / norm;
  }
  return std::isfinite(lambda) && lambda > 0.0 ? kLambdaMargin * lambda : 1.0;
}

/// Chebyshev smoothing of A x = b with the inverse Dinv (diagonal or node blocks) over
/// [lambdaMax / kChebyshevRange, lambdaMax]: kChebyshevDegree applications of Dinv (one product
/// fewer from a zero start).
template <class Apply, class Inverse>
void chebyshev(const Apply& apply, const Inverse& inverse, double lambdaMax, const Eigen::VectorXd& b,
               Eigen::VectorXd& x, bool zeroStart) {
  const double hi = lambdaMax, lo = lambdaMax / kChebyshevRange;
  const double theta = 0.5 * (hi + lo), delta = 0.5 * (hi - lo), sigma = theta / delta;
  double rho = 1.0 / sigma;
  Eigen::VectorXd r, ad;
  if (zeroStart) {
    x.setZero(b.size());
    r = b;
  } else {
    apply(x, ad);
    r = b - ad;
  }
  Eigen::VectorXd z;
  inverse(r, z);
  Eigen::VectorXd d = z / theta;
  for (int k = 1;; ++k) {
    x += d;
    if (k == WarpedAmg::kChebyshevDegree) break;
    apply(d, ad);
    r -= ad;
    const double rhoNew = 1.0 / (2.0 * sigma - rho);
    inverse(r, z);
    d = (rhoNew * rho) * d + (2.0 * rhoNew / delta) * z;
    rho = rhoNew;
  }
}

/// Greedy aggregation of a graph (CSR: neighbours of vertex v in adj[start[v] .. start[v+1]]):
/// each vertex whose neighbours are all free founds an aggregate with them; the vertices left join
/// the aggregate most of their neighbours are in; isolated ones form their own. Returns the
/// aggregate of each vertex and sets `count`.
std::vector<int> aggregate(const std::vector<int>& start, const std::vector<int>& adj, int& count) {
  const int n = static_cast<int>(start.size()) - 1;
  std::vector<int> agg(static_cast<std::size_t>(n), -1);
  count = 0;
  for (int v = 0; v < n; ++v) {
    if (agg[v] >= 0) continue;
    bool free = true;
    for (int k = start[v]; k < start[v + 1] && free; ++k) free = agg[adj[k]] < 0;
    if (!free) continue;
    agg[v] = count;
    for (int k = start[v]; k < start[v + 1]; ++k) agg[adj[k]] = count;
    ++count;
  }
  const std::vector<int> first = agg;  // the joins below look at the first pass's aggregates only
  std::vector<int> votes;
  for (int v = 0; v < n; ++v) {
    if (first[v] >= 0) continue;
    int best = -1, bestVotes = 0;
    votes.clear();
    for (int k = start[v]; k < start[v + 1]; ++k)
      if (first[adj[k]] >= 0) votes.push_back(first[adj[k]]);
    std::sort(votes.begin(), votes.end());
    for (std::size_t i = 0; i < votes.size();) {
      std::size_t j = i;
      while (j < votes.size() && votes[j] == votes[i]) ++j;
      if (static_cast<int>(j - i) > bestVotes) {
        bestVotes = static_cast<int>(j - i);
        best = votes[i];
      }
      i = j;
    }
    agg[v] = best >= 0 ? best : count++;
  }
  return agg;
}

}  // namespace

namespace {

template <class Matrix>
std::pair<AmgMatrix, AmgMatrix> nodeBlocksOf(const Matrix& A, const std::vector<Eigen::Index>& freeDofs) {
  const Eigen::Index n = A.rows();
  std::vector<Eigen::Triplet<double, int>> blocks, inverses;
  for (Eigen::Index i = 0; i < n;) {
    Eigen::Index j = i;
    while (j < n && freeDofs[static_cast<std::size_t>(j)] / 3 == freeDofs[static_cast<std::size_t>(i)] / 3) ++j;
    const Eigen::Index m = j - i;  // the node's free dofs [i, j)
    Eigen::Matrix3d Bn = Eigen::Matrix3d::Identity();
    for (Eigen::Index a = 0; a < m; ++a)
      for (Eigen::Index b = 0; b < m; ++b) Bn(a, b) = A.coeff(i + a, i + b);
    // As the device forms it (kernels/opencl/precond.cl, node_preconditioner): the inverse where
    // the determinant and the diagonal are positive, else the diagonal's (1 where not positive);
    // B is then the block that is inverted.
    Eigen::Matrix3d inv;
    if (Bn.determinant() > 0.0 && Bn.diagonal().minCoeff() > 0.0) {
      inv = Bn.inverse();
      inv = 0.5 * (inv + inv.transpose());
    } else {
      for (int k = 0; k < 3; ++k) Bn(k, k) = Bn(k, k) > 0.0 ? Bn(k, k) : 1.0;
      Bn = Eigen::Matrix3d(Bn.diagonal().asDiagonal());
      inv = Eigen::Matrix3d(Bn.diagonal().cwiseInverse().asDiagonal());
    }
    for (Eigen::Index a = 0; a < m; ++a)
      for (Eigen::Index b = 0; b < m; ++b) {
        blocks.emplace_back(static_cast<int>(i + a), static_cast<int>(i + b), Bn(a, b));
        inverses.emplace_back(static_cast<int>(i + a), static_cast<int>(i + b), inv(a, b));
      }
    i = j;
  }
  AmgMatrix B(n, n), Binv(n, n);
  B.setFromTriplets(blocks.begin(), blocks.end());
  Binv.setFromTriplets(inverses.begin(), inverses.end());
  return {std::move(B), std::move(Binv)};
}

}  // namespace

std::pair<AmgMatrix, AmgMatrix> nodeBlocks(const AmgMatrix& A, const std::vector<Eigen::Index>& freeDofs) {
  return nodeBlocksOf(A, freeDofs);
}

std::pair<AmgMatrix, AmgMatrix> nodeBlocks(const Eigen::SparseMatrix<double>& A, const std::vector<Eigen::Index>& freeDofs) {
  return nodeBlocksOf(A, freeDofs);
}

AmgMatrix sparseProduct(const AmgMatrix& A, const AmgMatrix& B) {
  const std::size_t rows = static_cast<std::size_t>(A.rows());
  if (rows <= kProductRows) return AmgMatrix(A * B);
  std::vector<AmgMatrix> parts(chunkCount(rows, kProductRows));
  std::vector<std::exception_ptr> failed(parts.size());
  parallelChunks(rows, kProductRows, [&](std::size_t c, std::size_t begin, std::size_t end) {
    try {
      parts[c] = A.middleRows(static_cast<Eigen::Index>(begin), static_cast<Eigen::Index>(end - begin)) * B;
      parts[c].makeCompressed();
    } catch (...) {
      failed[c] = std::current_exception();  // parallelChunks' tasks must not throw
    }
  });
  for (const std::exception_ptr& f : failed)
    if (f) std::rethrow_exception(f);
  std::vector<MatrixBlock> slices(parts.size());  // the slices' rows one after another
  for (std::size_t c = 0; c < parts.size(); ++c) {
    slices[c].sparse = &parts[c];
    slices[c].rowOffset = c * kProductRows;
  }
  return joined(rows, static_cast<std::size_t>(B.cols()), slices);
}

Eigen::VectorXd amgProduct(const AmgMatrix& A, const Eigen::VectorXd& x) {
  Eigen::VectorXd y(A.rows());
  parallelChunks(static_cast<std::size_t>(A.rows()), kProductRows, [&](std::size_t, std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) {
      double sum = 0.0;
      for (AmgMatrix::InnerIterator it(A, static_cast<Eigen::Index>(i)); it; ++it) sum += it.value() * x[it.index()];
      y[static_cast<Eigen::Index>(i)] = sum;
    }
  });
  return y;
}

AmgMatrix joined(std::size_t rows, std::size_t cols, const std::vector<MatrixBlock>& blocks) {
  for (const MatrixBlock& b : blocks)
    if (b.sparse && !b.sparse->isCompressed()) fail(ErrorCode::Internal, "joined: an uncompressed matrix");
  std::vector<int> start(rows + 1, 0);  // entries of each row, then where each row starts
  for (const MatrixBlock& b : blocks)
    for (Eigen::Index i = 0; i < b.rows(); ++i)
      start[b.row(i) + 1] = static_cast<int>(b.sparse ? b.sparse->outerIndexPtr()[i + 1] - b.sparse->outerIndexPtr()[i]
                                                      : b.dense->cols());
  for (std::size_t r = 0; r < rows; ++r) start[r + 1] += start[r];
  AmgMatrix out(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(cols));
  out.resizeNonZeros(start[rows]);
  std::copy(start.begin(), start.end(), out.outerIndexPtr());
  for (const MatrixBlock& b : blocks)
    for (Eigen::Index i = 0; i < b.rows(); ++i) {
      int at = start[b.row(i)];
      if (b.sparse) {
        for (AmgMatrix::InnerIterator it(*b.sparse, i); it; ++it, ++at) {
          out.innerIndexPtr()[at] = static_cast<int>(b.col(it.col()));
          out.valuePtr()[at] = it.value();
        }
      } else {
        for (Eigen::Index j = 0; j < b.dense->cols(); ++j, ++at) {
          out.innerIndexPtr()[at] = static_cast<int>(b.col(j));
          out.valuePtr()[at] = (*b.dense)(i, j);
        }
      }
    }
  return out;
}

void WarpedAmg::clear() {
  made_ = false;
  levels_.clear();
  aggregateNodes_.clear();
  aggregateRotations_.clear();
  nodeAggregate_.clear();
  freeDofs_.clear();
}

void WarpedAmg::build(const AmgMatrix& A0, const std::vector<Eigen::Index>& freeDofs, const Eigen::VectorXd& rest,
                      std::size_t nodeCount, const AmgMatrix* bound) {
  make(A0, freeDofs, rest, nodeCount, bound, nullptr);
}

void WarpedAmg::build(const AmgMatrix& A0, const std::vector<Eigen::Index>& freeDofs, const Eigen::VectorXd& rest,
                      std::size_t nodeCount, const Bounds& bounds) {
  make(A0, freeDofs, rest, nodeCount, nullptr, &bounds);
}

WarpedAmg::Bounds WarpedAmg::bounds() const {
  Bounds b;
  b.fine = fineLambdaMax_;
  if (!levels_.empty()) b.level0 = levels_[0].lambdaMax;
  return b;
}

void WarpedAmg::make(const AmgMatrix& A0, const std::vector<Eigen::Index>& freeDofs, const Eigen::VectorXd& rest,
                     std::size_t nodeCount, const AmgMatrix* bound, const Bounds* given) {
  clear();
  const Eigen::Index nf = static_cast<Eigen::Index>(freeDofs.size());
  if (A0.rows() != nf || A0.cols() != nf || static_cast<std::size_t>(rest.size()) != 3 * nodeCount)
    fail(ErrorCode::Internal, "WarpedAmg::build: an operator of ", A0.rows(), " x ", A0.cols(), " for ", nf,
         " free dofs and ", rest.size(), " rest coordinates of ", nodeCount, " nodes");
  freeDofs_ = freeDofs;
  rest_ = rest;
  made_ = true;
  if (nf == 0) return;

  // Level 0's vertices are the nodes with a free dof; `vertexStart` ranges their dofs (free indices
  // are ascending in dof order, so a node's free dofs are consecutive).
  std::vector<int> vertexStart{0};
  for (Eigen::Index i = 1; i < nf; ++i)
    if (freeDofs[i] / 3 != freeDofs[i - 1] / 3) vertexStart.push_back(static_cast<int>(i));
  vertexStart.push_back(static_cast<int>(nf));

  // The rigid-body modes about the rest bounding box's centre.
  Eigen::Vector3d lo = rest.segment<3>(0), hi = lo;
  for (std::size_t n = 1; n < nodeCount; ++n) {
    lo = lo.cwiseMin(rest.segment<3>(3 * n));
    hi = hi.cwiseMax(rest.segment<3>(3 * n));
  }
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(nf, 6);
  for (Eigen::Index i = 0; i < nf; ++i) {
    const Eigen::Index dof = freeDofs[i];
    const int c = static_cast<int>(dof % 3);
    const Eigen::Vector3d d = rest.segment<3>(3 * (dof / 3)) - centre;
    B(i, c) = 1.0;
    // Column 3 + k: the displacement e_k x d, component c: e_x x d = (0, -d_z, d_y),
    // e_y x d = (d_z, 0, -d_x), e_z x d = (-d_y, d_x, 0).
    const double rot[3][3] = {{0.0, -d[2], d[1]}, {d[2], 0.0, -d[0]}, {-d[1], d[0], 0.0}};
    for (int k = 0; k < 3; ++k) B(i, 3 + k) = rot[k][c];
  }

  if (given) {
    fineLambdaMax_ = given->fine;
  } else {
    const AmgMatrix& Ab = bound ? *bound : A0;
    const auto [B0, B0inv] = nodeBlocks(Ab, freeDofs);
    fineLambdaMax_ = estimateBlockLambdaMax(Ab, B0, B0inv);
  }
  AmgLevel level;
  level.A = A0;
  for (;;) {
    level.diagInv = inverseDiagonal(level.A);
    level.lambdaMax = given && levels_.empty() ? given->level0 : estimateLambdaMax(level.A, level.diagInv);
    const Eigen::Index n = level.A.rows();
    // A body small enough to be solved directly (or one whose level 0 does not coarsen) still gets
    // one smoothed level above its direct solve (P = I), so that every body runs the same cycle:
    // smoothing with the current operator, the rest operator's exact solve in the rotated frame.
    auto directBelow = [&] {
      aggregateNodes_.assign(1, {});  // the whole body turns as one
      for (std::size_t v = 0; v + 1 < vertexStart.size(); ++v)
        aggregateNodes_[0].push_back(static_cast<std::uint32_t>(freeDofs[vertexStart[v]] / 3));
      AmgMatrix identity(n, n);
      identity.setIdentity();
      level.P = identity;
      level.Pt = identity;
      AmgMatrix copy = level.A;
      level.vertexStart = vertexStart;
      levels_.push_back(std::move(level));
      level = AmgLevel{};
      level.A = std::move(copy);
    };
    if (levels_.empty() && n <= kDirectDofs) {
      directBelow();
      break;
    }
    if (!levels_.empty() && (n <= kCoarsestDofs || levels_.size() + 1 >= kMaxLevels)) break;

    // The vertex graph of the level's operator.
    const int nv = static_cast<int>(vertexStart.size()) - 1;
    const VertexGraph graph = vertexGraph(level.A, vertexStart);
    int aggregates = 0;
    const std::vector<int> agg = aggregate(graph.start, graph.adj, aggregates);
    if (levels_.empty()) {  // level 0: the warp's aggregates of nodes
      aggregateNodes_.assign(static_cast<std::size_t>(aggregates), {});
      for (int v = 0; v < nv; ++v)
        aggregateNodes_[agg[v]].push_back(static_cast<std::uint32_t>(freeDofs[vertexStart[v]] / 3));
    }

    // Tentative prolongator and the next level's near-null space, aggregate by aggregate.
    std::vector<std::vector<int>> members(static_cast<std::size_t>(aggregates));
    for (int v = 0; v < nv; ++v) members[agg[v]].push_back(v);
    std::vector<Eigen::Triplet<double, int>> triplets;
    std::vector<Eigen::MatrixXd> coarseB;
    std::vector<int> coarseVertexStart{0};
    int coarseDofs = 0;
    for (int a = 0; a < aggregates; ++a) {
      std::vector<int> rows;
      for (int v : members[a])
        for (int i = vertexStart[v]; i < vertexStart[v + 1]; ++i) rows.push_back(i);
      Eigen::MatrixXd Ba(static_cast<Eigen::Index>(rows.size()), B.cols());
      for (std::size_t k = 0; k < rows.size(); ++k) Ba.row(static_cast<Eigen::Index>(k)) = B.row(rows[k]);
      Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Ba);
      const Eigen::VectorXd rdiag = qr.matrixR().diagonal().cwiseAbs();
      const double top = rdiag.size() > 0 ? rdiag.maxCoeff() : 0.0;
      Eigen::Index rank = 0;
      while (rank < rdiag.size() && rdiag[rank] > kRankThreshold * top && top > 0.0) ++rank;
      if (rank == 0) continue;  // nothing of the near-null space lives here
      const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(Ba.rows(), rank);
      for (std::size_t k = 0; k < rows.size(); ++k)
        for (Eigen::Index j = 0; j < rank; ++j)
          triplets.emplace_back(rows[k], coarseDofs + static_cast<int>(j), Q(static_cast<Eigen::Index>(k), j));
      coarseB.push_back(Q.transpose() * Ba);
      coarseDofs += static_cast<int>(rank);
      coarseVertexStart.push_back(coarseDofs);
    }
    const bool stalled = coarseDofs == 0 || (coarseDofs > kStallRatio * double(n) && n <= kMaxCoarsestDofs);
    if (stalled) {
      if (levels_.empty()) directBelow();
      break;
    }
    AmgMatrix tentative(n, coarseDofs);
    tentative.setFromTriplets(triplets.begin(), triplets.end());

    // P = (I - omega D^-1 A) P_t.
    const double omega = 4.0 / (3.0 * level.lambdaMax);
    AmgMatrix AP = sparseProduct(level.A, tentative);
    AmgMatrix P = tentative - AmgMatrix((omega * level.diagInv).asDiagonal() * AP);
    P.prune(0.0);
    AmgMatrix Pt = P.transpose();
    AmgMatrix coarse = sparseProduct(Pt, sparseProduct(level.A, P));
    coarse = AmgMatrix(0.5 * (coarse + AmgMatrix(coarse.transpose())));
    coarse.prune(0.0);

    level.P = std::move(P);
    level.Pt = std::move(Pt);
    level.vertexStart = vertexStart;
    levels_.push_back(std::move(level));
    level = AmgLevel{};
    level.A = std::move(coarse);
    B.resize(coarseDofs, 6);
    for (std::size_t a = 0, at = 0; a < coarseB.size(); ++a) {
      B.middleRows(static_cast<Eigen::Index>(at), coarseB[a].rows()) = coarseB[a];
      at += static_cast<std::size_t>(coarseB[a].rows());
    }
    vertexStart = std::move(coarseVertexStart);
  }
  // The coarsest level, factored; a relative shift keeps a singular one (a free-floating body in
  // statics) from dividing by zero.
  Eigen::SparseMatrix<double> coarsest = level.A;
  const double shift = 1e-12 * (coarsest.rows() > 0 ? coarsest.diagonal().cwiseAbs().maxCoeff() : 0.0);
  for (Eigen::Index i = 0; i < coarsest.rows(); ++i) coarsest.coeffRef(i, i) += shift;
  coarsest_.compute(coarsest);
  if (coarsest_.info() != Eigen::Success) {
    // Not positive definite (a NaN material, or a coarsest level with a zero pivot): its diagonal
    // instead, so that the cycle stays a symmetric positive operator (a weaker one).
    Eigen::SparseMatrix<double> diagonal(coarsest.rows(), coarsest.cols());
    diagonal.setIdentity();
    for (Eigen::Index i = 0; i < coarsest.rows(); ++i) {
      const double d = coarsest.coeff(i, i);
      diagonal.coeffRef(i, i) = std::isfinite(d) && d > 0.0 ? d : 1.0;
    }
    coarsest_.compute(diagonal);
  }
  level.vertexStart = vertexStart;
  levels_.push_back(std::move(level));
  nodeAggregate_ = nodeAggregates();
}

void WarpedAmg::setPositions(const Eigen::VectorXd& x) {
  aggregateRotations_.resize(aggregateNodes_.size());
  for (std::size_t a = 0; a < aggregateNodes_.size(); ++a) {
    const std::vector<std::uint32_t>& nodes = aggregateNodes_[a];
    Eigen::Vector3d cx = Eigen::Vector3d::Zero(), cX = Eigen::Vector3d::Zero();
    for (std::uint32_t n : nodes) {
      cx += x.segment<3>(3 * n);
      cX += rest_.segment<3>(3 * n);
    }
    cx /= double(nodes.size());
    cX /= double(nodes.size());
    Mat3 A = Mat3::Zero();
    for (std::uint32_t n : nodes) A += (x.segment<3>(3 * n) - cx) * (rest_.segment<3>(3 * n) - cX).transpose();
    aggregateRotations_[a] = A.isZero(0.0) ? Mat3::Identity() : polarRotation(A);
  }
}

std::vector<int> WarpedAmg::nodeAggregates() const {
  std::vector<int> of(static_cast<std::size_t>(rest_.size() / 3), -1);
  for (std::size_t a = 0; a < aggregateNodes_.size(); ++a)
    for (std::uint32_t n : aggregateNodes_[a]) of[n] = static_cast<int>(a);
  return of;
}

Eigen::MatrixXd WarpedAmg::coarsestInverse() const {
  if (levels_.empty()) return {};
  const Eigen::Index n = levels_.back().A.rows();
  const Eigen::MatrixXd inverse = coarsest_.solve(Eigen::MatrixXd::Identity(n, n));
  return 0.5 * (inverse + inverse.transpose());  // symmetric to the last bit, as the cycle needs
}

std::vector<Eigen::Index> WarpedAmg::levelSizes() const {
  std::vector<Eigen::Index> sizes;
  for (const AmgLevel& l : levels_) sizes.push_back(l.A.rows());
  return sizes;
}

void WarpedAmg::warp(const Eigen::VectorXd& v, Eigen::VectorXd& out, bool transpose) const {
  out = v;
  if (aggregateRotations_.empty()) return;
  const Eigen::Index nf = static_cast<Eigen::Index>(freeDofs_.size());
  for (Eigen::Index i = 0; i < nf;) {
    // The free dofs of one node: rotate its 3-vector (constrained components 0), keep the free ones.
    const Eigen::Index node = freeDofs_[i] / 3;
    Eigen::Index j = i;
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    while (j < nf && freeDofs_[j] / 3 == node) {
      u[freeDofs_[j] % 3] = v[j];
      ++j;
    }
    const int a = nodeAggregate_[static_cast<std::size_t>(node)];
    if (a >= 0) {
      const Mat3& R = aggregateRotations_[static_cast<std::size_t>(a)];
      const Eigen::Vector3d w = transpose ? Eigen::Vector3d(R.transpose() * u) : Eigen::Vector3d(R * u);
      for (Eigen::Index k = i; k < j; ++k) out[k] = w[freeDofs_[k] % 3];
    }
    i = j;
  }
}

void WarpedAmg::cycle(std::size_t l, const Eigen::VectorXd& b, Eigen::VectorXd& x, const AmgFineOperator* fine) const {
  const AmgLevel& level = levels_[l];
  if (l + 1 == levels_.size()) {
    x = coarsest_.solve(b);
    return;
  }
  auto apply = [&](const Eigen::VectorXd& v, Eigen::VectorXd& y) {
    if (fine)
      fine->apply(v, y);
    else
      y = amgProduct(level.A, v);
  };
  auto inverse = [&](const Eigen::VectorXd& r, Eigen::VectorXd& z) {
    if (fine)
      fine->blockInverse(r, z);
    else
      z = level.diagInv.cwiseProduct(r);
  };
  const double lambdaMax = fine ? fineLambdaMax_ : level.lambdaMax;
  chebyshev(apply, inverse, lambdaMax, b, x, true);
  Eigen::VectorXd r;
  apply(x, r);
  r = b - r;
  Eigen::VectorXd coarseB, coarseX, e;
  if (fine) {
    Eigen::VectorXd rr;
    warp(r, rr, true);
    coarseB = amgProduct(level.Pt, rr);
  } else {
    coarseB = amgProduct(level.Pt, r);
  }
  cycle(l + 1, coarseB, coarseX, nullptr);
  if (fine) {
    warp(amgProduct(level.P, coarseX), e, false);
    x += e;
  } else {
    x += amgProduct(level.P, coarseX);
  }
  chebyshev(apply, inverse, lambdaMax, b, x, false);
}

void WarpedAmg::apply(const AmgFineOperator& fine, const Eigen::VectorXd& r, Eigen::VectorXd& z) const {
  if (levels_.empty()) {
    z = r;
    return;
  }
  cycle(0, r, z, &fine);
}

BodyAmg::Made BodyAmg::ensure(const Problem& p, const std::vector<Eigen::Index>& freeDofs, double massScale,
                              double stiffScale) {
  const double ratio = restRatio(massScale, stiffScale);
  const Made found = pair_.find(ratio, freeDofs);
  if (found != Made::Built) return found;
  bool remade = false;
  const AmgMatrix& stiffness = stiffness_.of(p, remade);
  if (remade) pair_.clear();  // neither hierarchy's bounds are of this stiffness
  // Level 0's Chebyshev bound comes from the operator with half the mass coefficient: the bound of
  // the whole window of ratios this hierarchy serves (lambda_max(B^-1 A) does not grow with the
  // mass; see below). A hierarchy made for more free dofs (a hard grab or a pin: the one just
  // replaced) at a ratio r0 with r0 <= r < 2 r0 gives its two bounds instead (WarpedAmg::build with
  // Bounds; docs/performance.md has what that spares a grab): both hold for the fewer dofs, and
  // neither grows with the ratio. With M lumped (diagonal, so the blocks' and the diagonal's mass
  // part is M itself), a Rayleigh quotient of B^-1 (r M + K) is (r m + k) / (r m + b) for
  // m = v.M v, k = v.K v, b = v.B_K v: it moves towards 1 as r grows, so the largest (at least 1)
  // does not grow. r0 is taken less a relative 1e-9: the same time step's ratio comes back with
  // its last bits changed.
  const WarpedAmg* wider = nullptr;
  for (const auto& [a, made] : {std::pair<const WarpedAmg*, double>{&pair_.spare(), pair_.spareRatio()}, {&pair_.now(), pair_.nowRatio()}})
    if (!wider && a->built() && !a->levels().empty() && std::isfinite(made) && std::isfinite(ratio) &&
        ratio >= made * (1.0 - 1e-9) && ratio < 2.0 * made &&
        std::includes(a->builtFreeDofs().begin(), a->builtFreeDofs().end(), freeDofs.begin(), freeDofs.end()))
      wider = a;
  const AmgMatrix A0 = restOperator(stiffness, p, freeDofs, massScale, stiffScale);
  if (wider) {
    const WarpedAmg::Bounds bounds = wider->bounds();
    pair_.now().build(A0, freeDofs, p.restPositions, p.mesh.nodeCount(), bounds);
  } else {
    const AmgMatrix bound = restOperator(stiffness, p, freeDofs, 0.5 * massScale, stiffScale);
    pair_.now().build(A0, freeDofs, p.restPositions, p.mesh.nodeCount(), &bound);
  }
  pair_.made(ratio);
  ++builds_;
  return Made::Built;
}

}  // namespace corofem::detail
