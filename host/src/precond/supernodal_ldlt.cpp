// The supernodal factorisation and triangular solves of precond/supernodal_ldlt.hpp.
#include "precond/supernodal_ldlt.hpp"

#include "util/error.hpp"
#include "util/parallel.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <exception>
#include <array>
#include <numeric>
#include <queue>
#include <utility>

namespace corofem::detail {

namespace {

/// A factor of fewer panel values than this solves on the calling thread: waking the pool for its
/// tasks would cost more than they take (the bits are the same either way).
constexpr std::size_t kSerialValues = std::size_t{1} << 15;

/// sum_k a[k] b[k] for k < w, in eight running sums (lanes a vector unit runs side by side) added
/// up in a fixed order: the same bits on every call.
inline double dot(const double* a, const double* b, std::size_t w) {
  double lane[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  std::size_t k = 0;
  for (; k + 8 <= w; k += 8)
    for (std::size_t l = 0; l < 8; ++l) lane[l] += a[k + l] * b[k + l];
  for (std::size_t l = 0; k < w; ++k, ++l) lane[l] += a[k] * b[k];
  return ((lane[0] + lane[1]) + (lane[2] + lane[3])) + ((lane[4] + lane[5]) + (lane[6] + lane[7]));
}

/// The narrow runs (most of them a node's three dofs): their rows below with the width fixed at
/// compile time, so that a row is a few multiplies in registers and no loop. The generic loops in
/// forward() and backward() take the wider runs.
constexpr std::size_t kFixedWidths = 12;

/// L y' = y's updates from a run of width W: y[below[r]] -= R_r . ys for the `direct` rows,
/// top[topIndex[below[r]]] += R_r . ys for the rest.
template <std::size_t W>
void rowsDown(const double* R, const int* below, std::size_t direct, std::size_t h, const double* ys, double* y,
              double* top, const int* topIndex) {
  double v[W];
  for (std::size_t k = 0; k < W; ++k) v[k] = ys[k];
  const auto rowDot = [&](std::size_t r) {
    double t = 0.0;
    for (std::size_t k = 0; k < W; ++k) t += R[r * W + k] * v[k];
    return t;
  };
  for (std::size_t r = 0; r < direct; ++r) y[below[r]] -= rowDot(r);
  for (std::size_t r = direct; r < h; ++r) top[topIndex[below[r]]] += rowDot(r);
}

/// L^T x = y's gathers into a run of width W: acc[k] = sum_r R(r, k) y[below[r]].
template <std::size_t W>
void rowsUp(const double* R, const int* below, std::size_t h, const double* y, double* acc) {
  double a[W] = {};
  for (std::size_t r = 0; r < h; ++r) {
    const double yr = y[below[r]];
    for (std::size_t k = 0; k < W; ++k) a[k] += R[r * W + k] * yr;
  }
  for (std::size_t k = 0; k < W; ++k) acc[k] = a[k];
}

using RowsDown = void (*)(const double*, const int*, std::size_t, std::size_t, const double*, double*, double*,
                          const int*);
using RowsUp = void (*)(const double*, const int*, std::size_t, const double*, double*);

template <std::size_t... W>
constexpr std::array<RowsDown, sizeof...(W)> downTable(std::index_sequence<W...>) {
  return {&rowsDown<W + 1>...};
}
template <std::size_t... W>
constexpr std::array<RowsUp, sizeof...(W)> upTable(std::index_sequence<W...>) {
  return {&rowsUp<W + 1>...};
}
constexpr auto kRowsDown = downTable(std::make_index_sequence<kFixedWidths>());  // [w - 1]
constexpr auto kRowsUp = upTable(std::make_index_sequence<kFixedWidths>());

}  // namespace

bool SupernodalLdlt::factor(const Eigen::SparseMatrix<double>& A, const Eigen::VectorXi& perm) {
  const auto n = static_cast<int>(A.cols());
  if (A.rows() != n || (perm.size() != 0 && perm.size() != n))
    fail(ErrorCode::Internal, "SupernodalLdlt: a matrix of ", A.rows(), " x ", A.cols(), " and a permutation of ",
         perm.size());
  std::vector<int> to(static_cast<std::size_t>(n));  // row i of A is row to[i] of C = P A P^T
  std::vector<char> seen(static_cast<std::size_t>(n), 0);
  for (int i = 0; i < n; ++i) {
    const int p = perm.size() == 0 ? i : perm[i];
    if (p < 0 || p >= n || seen[static_cast<std::size_t>(p)])
      fail(ErrorCode::Internal, "SupernodalLdlt: the permutation is not one of 0..", n - 1);
    seen[static_cast<std::size_t>(p)] = 1;
    to[static_cast<std::size_t>(i)] = p;
  }

  // C's entries on and below its diagonal, by columns, each column's rows ascending.
  std::vector<std::size_t> Cp(static_cast<std::size_t>(n) + 1, 0);
  for (int j = 0; j < n; ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(A, j); it; ++it) {
      const int r = to[static_cast<std::size_t>(it.row())], c = to[static_cast<std::size_t>(j)];
      if (r >= c) ++Cp[static_cast<std::size_t>(c) + 1];
    }
  for (int j = 0; j < n; ++j) Cp[static_cast<std::size_t>(j) + 1] += Cp[static_cast<std::size_t>(j)];
  std::vector<int> Ci(Cp.back());
  std::vector<double> Cx(Cp.back());
  {
    std::vector<std::size_t> next(Cp.begin(), Cp.end() - 1);
    for (int j = 0; j < n; ++j)
      for (Eigen::SparseMatrix<double>::InnerIterator it(A, j); it; ++it) {
        const int r = to[static_cast<std::size_t>(it.row())], c = to[static_cast<std::size_t>(j)];
        if (r < c) continue;
        const std::size_t at = next[static_cast<std::size_t>(c)]++;
        Ci[at] = r;
        Cx[at] = it.value();
      }
    std::vector<std::pair<int, double>> column;
    for (int j = 0; j < n; ++j) {
      const std::size_t b = Cp[static_cast<std::size_t>(j)], e = Cp[static_cast<std::size_t>(j) + 1];
      column.clear();
      for (std::size_t k = b; k < e; ++k) column.emplace_back(Ci[k], Cx[k]);
      std::sort(column.begin(), column.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
      for (std::size_t k = b; k < e; ++k) {
        Ci[k] = column[k - b].first;
        Cx[k] = column[k - b].second;
      }
    }
  }

  SupernodalLdlt made;  // a refused factor leaves this one as it was
  const std::vector<int> of = made.symbolic(n, Cp, Ci);
  made.partition(of);
  if (!made.numeric(Cp, Ci, Cx, of)) return false;
  made.perm_ = perm.size() == 0 ? std::vector<int>() : std::vector<int>(perm.data(), perm.data() + perm.size());
  made.work_.acc.assign((kTasks + 1) * made.widest_, 0.0);
  made.work_.updates.assign(kTasks * made.topColumns_.size(), 0.0);
  made.work_.y.resize(n);
  *this = std::move(made);
  return true;
}

std::vector<int> SupernodalLdlt::symbolic(int n, const std::vector<std::size_t>& Cp, const std::vector<int>& Ci) {
  // Column j's rows below the diagonal (its pattern) are C's and its children's in the elimination
  // tree, less j itself; its parent is the first of them. A child comes before its parent, so a
  // column's pattern is complete before its parent reads it. The patterns are kept by supernode,
  // not by column: a child of j is either j - 1, the open run's last column, whose pattern is the
  // run's rows below, or the last column of a closed supernode, whose pattern is that supernode's
  // rows below (a column inside a run has the next column as its parent).
  first_.clear();
  rows_.clear();
  rowStart_.assign(1, 0);
  std::vector<int> of(static_cast<std::size_t>(n));
  std::vector<std::vector<int>> children(static_cast<std::size_t>(n));
  std::vector<int> mark(static_cast<std::size_t>(n), -1);
  std::vector<int> U, P;  // the open run [c0, j)'s rows below j - 1 (ascending); column j's pattern
  int c0 = 0;
  entries_ = 0;
  const auto close = [&](int end) {
    const auto w = static_cast<std::size_t>(end - c0);
    entries_ += w * (w - 1) / 2 + w * U.size();
    first_.push_back(c0);
    rows_.insert(rows_.end(), U.begin(), U.end());
    rowStart_.push_back(rows_.size());
    c0 = end;
  };
  for (int j = 0; j < n; ++j) {
    P.clear();
    mark[static_cast<std::size_t>(j)] = j;
    const auto add = [&](int r) {
      if (mark[static_cast<std::size_t>(r)] == j) return;
      mark[static_cast<std::size_t>(r)] = j;
      P.push_back(r);
    };
    for (std::size_t k = Cp[static_cast<std::size_t>(j)]; k < Cp[static_cast<std::size_t>(j) + 1]; ++k) add(Ci[k]);
    for (const int c : children[static_cast<std::size_t>(j)]) {
      if (c == j - 1) {
        for (const int r : U) add(r);
        continue;
      }
      const auto sc = static_cast<std::size_t>(of[static_cast<std::size_t>(c)]);
      const int end = sc + 1 < first_.size() ? first_[sc + 1] : c0;
      if (sc >= first_.size() || end != c + 1)
        fail(ErrorCode::Internal, "SupernodalLdlt: column ", c, ", a child of ", j, ", is not the last of a supernode");
      for (std::size_t k = rowStart_[sc]; k < rowStart_[sc + 1]; ++k) add(rows_[k]);
    }
    std::sort(P.begin(), P.end());
    if (!P.empty()) children[static_cast<std::size_t>(P.front())].push_back(j);
    if (j > c0 && !U.empty() && U.front() == j && std::equal(U.begin() + 1, U.end(), P.begin(), P.end())) {
      U.erase(U.begin());
    } else {
      if (j > 0) close(j);
      U.swap(P);
    }
    of[static_cast<std::size_t>(j)] = static_cast<int>(first_.size());  // the open run's index
  }
  if (n > 0) close(n);
  first_.push_back(n);
  const std::size_t S = first_.size() - 1;
  widest_ = 0;
  for (std::size_t s = 0; s < S; ++s) widest_ = std::max(widest_, static_cast<std::size_t>(first_[s + 1] - first_[s]));
  // A Cholesky factor's pattern: the rows below a supernode that are not its parent's columns (the
  // parent holds its first row below) are among its parent's rows below, so every row below a
  // supernode is an ancestor's (by induction from the roots), which the numeric pass's updates and
  // the split into tasks need. An internal check of the symbolic pass above.
  for (std::size_t s = 0; s < S; ++s) {
    if (rowStart_[s + 1] == rowStart_[s]) continue;
    const auto parent = static_cast<std::size_t>(of[static_cast<std::size_t>(rows_[rowStart_[s]])]);
    const int* rest = rows_.data() + rowStart_[s];
    const int* end = rows_.data() + rowStart_[s + 1];
    while (rest != end && *rest < first_[parent + 1]) ++rest;
    if (!std::includes(rows_.data() + rowStart_[parent], rows_.data() + rowStart_[parent + 1], rest, end))
      fail(ErrorCode::Internal, "SupernodalLdlt: the factor's column ", first_[s],
           " has a row below that is not an ancestor's in its elimination tree");
  }

  // The panels: the run's w x w triangle (row-major), then its h rows below, w values each.
  panelStart_.assign(S + 1, 0);
  for (std::size_t s = 0; s < S; ++s) {
    const auto w = static_cast<std::size_t>(first_[s + 1] - first_[s]);
    panelStart_[s + 1] = panelStart_[s] + w * w + (rowStart_[s + 1] - rowStart_[s]) * w;
  }
  values_.assign(panelStart_[S], 0.0);
  dinv_.setZero(n);  // its size is rows(): the factor's
  return of;
}

bool SupernodalLdlt::numeric(const std::vector<std::size_t>& Cp, const std::vector<int>& Ci,
                             const std::vector<double>& Cx, const std::vector<int>& of) {
  using Block = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  using Map = Eigen::Map<Block>;
  const auto n = static_cast<std::size_t>(of.size());
  const std::size_t S = supernodeCount();
  // where[r]: row r's place among the rows below the supernode being filled or updated (-1: none).
  std::vector<int> where(n, -1);
  // C's entries into the panels: the triangle's lower half with its diagonal, and the rows below.
  for (std::size_t s = 0; s < S; ++s) {
    const Panel p = panel(static_cast<int>(s));
    for (std::size_t r = 0; r < p.h; ++r) where[static_cast<std::size_t>(p.below[r])] = static_cast<int>(r);
    double* T = values_.data() + panelStart_[s];
    double* R = T + p.w * p.w;
    for (int c = p.first; c < p.first + static_cast<int>(p.w); ++c) {
      const auto k = static_cast<std::size_t>(c - p.first);
      for (std::size_t e = Cp[static_cast<std::size_t>(c)]; e < Cp[static_cast<std::size_t>(c) + 1]; ++e) {
        const int r = Ci[e];
        if (r < p.first + static_cast<int>(p.w)) T[static_cast<std::size_t>(r - p.first) * p.w + k] = Cx[e];
        else R[static_cast<std::size_t>(where[static_cast<std::size_t>(r)]) * p.w + k] = Cx[e];
      }
    }
    for (std::size_t r = 0; r < p.h; ++r) where[static_cast<std::size_t>(p.below[r])] = -1;
  }

  // Supernode s's triangle factored, T = L_c L_c^T (its lower half, updated by the descendants),
  // then its rows below solved, W = R L_c^-T; false at a pivot that is not positive and finite.
  const auto pivots = [&](std::size_t s) {
    const Panel p = panel(static_cast<int>(s));
    Map T(values_.data() + panelStart_[s], static_cast<Eigen::Index>(p.w), static_cast<Eigen::Index>(p.w));
    Map R(values_.data() + panelStart_[s] + p.w * p.w, static_cast<Eigen::Index>(p.h), static_cast<Eigen::Index>(p.w));
    {
      Eigen::LLT<Eigen::Ref<Block>, Eigen::Lower> llt(T);
      if (llt.info() != Eigen::Success) return false;
    }
    for (Eigen::Index k = 0; k < T.rows(); ++k)
      if (!(std::isfinite(T(k, k)) && T(k, k) > 0.0)) return false;
    if (p.h > 0) T.triangularView<Eigen::Lower>().transpose().solveInPlace<Eigen::OnTheRight>(R);
    return true;
  };
  // W W^T's blocks subtracted from the ancestors' panels, for the rows below from q0 to qEnd grouped
  // by the ancestor whose columns they are (scratch, place: the caller's, kept between calls).
  // False where a row below is not among its ancestor's (not a Cholesky factor's pattern: an
  // internal error).
  const auto updates = [&](std::size_t s, std::size_t q0, std::size_t qEnd, std::vector<double>& scratch,
                           std::vector<int>& place) {
    const Panel p = panel(static_cast<int>(s));
    const std::size_t w = p.w, h = p.h;
    const Map R(values_.data() + panelStart_[s] + w * w, static_cast<Eigen::Index>(h), static_cast<Eigen::Index>(w));
    while (q0 < qEnd) {
      const auto t = static_cast<std::size_t>(of[static_cast<std::size_t>(p.below[q0])]);
      const Panel a = panel(static_cast<int>(t));
      const int end = a.first + static_cast<int>(a.w);
      std::size_t q1 = q0;
      while (q1 < h && p.below[q1] < end) ++q1;
      // Rows q0.. of W go to a's triangle (those among its columns, -1 - their row there) or to its
      // rows below (an ancestor's rows below hold every row below its descendants past its columns).
      place.resize(h - q0);
      std::size_t at = 0;
      for (std::size_t r = q0; r < h; ++r) {
        const int row = p.below[r];
        if (row < end) {
          place[r - q0] = -1 - (row - a.first);
          continue;
        }
        while (at < a.h && a.below[at] < row) ++at;
        if (at == a.h || a.below[at] != row) return false;
        place[r - q0] = static_cast<int>(at);
      }
      // U = W_q0.. W_group^T: its top square (the group's own rows) symmetric, only its lower half
      // formed (a rank update); the rows below it a general product.
      const auto rows = static_cast<Eigen::Index>(h - q0), cols = static_cast<Eigen::Index>(q1 - q0);
      const auto group = R.middleRows(static_cast<Eigen::Index>(q0), cols);
      if (scratch.size() < static_cast<std::size_t>(rows * cols)) scratch.resize(static_cast<std::size_t>(rows * cols));
      Map U(scratch.data(), rows, cols);
      U.topRows(cols).setZero();
      U.topRows(cols).selfadjointView<Eigen::Lower>().rankUpdate(group);
      if (rows > cols)
        U.bottomRows(rows - cols).noalias() =
            R.middleRows(static_cast<Eigen::Index>(q1), rows - cols) * group.transpose();
      double* aT = values_.data() + panelStart_[t];
      double* aR = aT + a.w * a.w;
      for (Eigen::Index r = 0; r < rows; ++r) {
        const int to = place[static_cast<std::size_t>(r)];
        double* row = to < 0 ? aT + static_cast<std::size_t>(-1 - to) * a.w : aR + static_cast<std::size_t>(to) * a.w;
        for (Eigen::Index c = 0; c < std::min(cols, r + 1); ++c)
          row[p.below[q0 + static_cast<std::size_t>(c)] - a.first] -= U(r, c);
      }
      q0 = q1;
    }
    return true;
  };
  // L = L_c diag(L_c)^-1 and D = diag(L_c)^2: the triangle's strict lower half and the rows below
  // scaled by their column's pivot; the triangle's diagonal and upper half stored as 0.
  const auto finish = [&](std::size_t s) {
    const Panel p = panel(static_cast<int>(s));
    Map T(values_.data() + panelStart_[s], static_cast<Eigen::Index>(p.w), static_cast<Eigen::Index>(p.w));
    Map R(values_.data() + panelStart_[s] + p.w * p.w, static_cast<Eigen::Index>(p.h), static_cast<Eigen::Index>(p.w));
    for (Eigen::Index k = 0; k < T.rows(); ++k) {
      const double pivot = T(k, k);
      dinv_[p.first + k] = 1.0 / (pivot * pivot);
      for (Eigen::Index i = k + 1; i < T.rows(); ++i) T(i, k) /= pivot;
      R.col(k) /= pivot;
      for (Eigen::Index i = 0; i <= k; ++i) T(i, k) = 0.0;
    }
  };
  const auto notBelow = [&](std::size_t s) {
    fail(ErrorCode::Internal, "SupernodalLdlt: a row below column ", first_[s], " is not below its ancestor");
  };

  // The tasks' subtrees side by side, each supernode's updates of its own subtree (its first
  // direct_[s] rows below); then, in supernode order, the updates of the top from the tasks'
  // supernodes and the top's own supernodes. Each panel entry takes its updates in supernode order,
  // as one thread going through the supernodes in order would: the bits do not depend on the
  // threads.
  std::vector<int> failed(kTasks, 0);  // 1: a pivot, 2: a row below
  std::vector<std::size_t> at(kTasks, 0);  // the supernode that failed
  std::vector<std::exception_ptr> thrown(kTasks);
  forTasks([&](std::size_t t) {
    try {
      std::vector<double> scratch;
      std::vector<int> place;
      for (const int s : tasks_[t]) {
        const auto k = static_cast<std::size_t>(s);
        at[t] = k;
        if (!pivots(k)) {
          failed[t] = 1;
          return;
        }
        if (!updates(k, 0, direct_[k], scratch, place)) {
          failed[t] = 2;
          return;
        }
      }
    } catch (...) {
      thrown[t] = std::current_exception();
    }
  });
  for (std::size_t t = 0; t < kTasks; ++t)
    if (thrown[t]) std::rethrow_exception(thrown[t]);
  for (std::size_t t = 0; t < kTasks; ++t)
    if (failed[t] == 2) notBelow(at[t]);
  if (std::find(failed.begin(), failed.end(), 1) != failed.end()) return false;
  std::vector<double> scratch;
  std::vector<int> place;
  for (std::size_t s = 0; s < S; ++s) {
    const Panel p = panel(static_cast<int>(s));
    const bool top = topIndex_[static_cast<std::size_t>(p.first)] >= 0;
    if (top && !pivots(s)) return false;
    if (!updates(s, top ? 0 : direct_[s], p.h, scratch, place)) notBelow(s);
    finish(s);
  }
  return true;
}

void SupernodalLdlt::partition(const std::vector<int>& of) {
  const std::size_t S = supernodeCount();
  const auto n = static_cast<std::size_t>(rows());
  // The elimination tree of the supernodes: a supernode's parent holds its first row below.
  std::vector<std::vector<int>> children(S);
  std::vector<int> roots;
  std::vector<double> work(S, 0.0);  // the subtree's panel values, read once a sweep
  for (std::size_t s = 0; s < S; ++s) {
    work[s] += static_cast<double>(panelStart_[s + 1] - panelStart_[s]);
    if (rowStart_[s + 1] == rowStart_[s]) {
      roots.push_back(static_cast<int>(s));
      continue;
    }
    const int parent = of[static_cast<std::size_t>(rows_[rowStart_[s]])];
    children[static_cast<std::size_t>(parent)].push_back(static_cast<int>(s));
    work[static_cast<std::size_t>(parent)] += work[s];  // a parent comes after its children
  }
  const double total = std::accumulate(roots.begin(), roots.end(), 0.0,
                                       [&](double sum, int r) { return sum + work[static_cast<std::size_t>(r)]; });
  // Split the largest subtree (of equals the lowest index) into its children until none that has
  // children holds more than 1/kTasks of the factor; a leaf stays whole.
  std::priority_queue<std::pair<double, int>> largest;  // (work, -index): the largest, then the lowest index
  for (const int r : roots) largest.emplace(work[static_cast<std::size_t>(r)], -r);
  std::vector<int> subtrees;
  std::vector<char> inTop(S, 0);
  while (!largest.empty()) {
    const auto [w, negative] = largest.top();
    const auto s = static_cast<std::size_t>(-negative);
    if (w <= total / kTasks) break;  // and so are the rest
    largest.pop();
    if (children[s].empty()) {
      subtrees.push_back(static_cast<int>(s));
      continue;
    }
    inTop[s] = 1;
    for (const int c : children[s]) largest.emplace(work[static_cast<std::size_t>(c)], -c);
  }
  for (; !largest.empty(); largest.pop()) subtrees.push_back(-largest.top().second);
  // Deal the subtrees, the largest first, each to the task with the least work so far.
  std::sort(subtrees.begin(), subtrees.end(), [&](int a, int b) {
    const double wa = work[static_cast<std::size_t>(a)], wb = work[static_cast<std::size_t>(b)];
    return wa != wb ? wa > wb : a < b;
  });
  std::vector<int> task(S, -1);
  std::vector<double> load(kTasks, 0.0);
  for (const int root : subtrees) {
    const auto t = static_cast<int>(std::min_element(load.begin(), load.end()) - load.begin());
    load[static_cast<std::size_t>(t)] += work[static_cast<std::size_t>(root)];
    task[static_cast<std::size_t>(root)] = t;
  }
  // A supernode below a subtree's root joins its task (a child comes before its parent, so going
  // down from the roots: the supernodes in descending order).
  for (std::size_t s = S; s-- > 0;)
    if (!inTop[s] && task[s] < 0) {
      const int parent = of[static_cast<std::size_t>(rows_[rowStart_[s]])];  // not a root: it has rows below
      task[s] = task[static_cast<std::size_t>(parent)];
    }
  tasks_.assign(kTasks, {});
  top_.clear();
  topColumns_.clear();
  topIndex_.assign(n, -1);
  direct_.assign(S, 0);
  for (std::size_t s = 0; s < S; ++s) {
    if (inTop[s]) {
      top_.push_back(static_cast<int>(s));
      for (int c = first_[s]; c < first_[s + 1]; ++c) {
        topIndex_[static_cast<std::size_t>(c)] = static_cast<int>(topColumns_.size());
        topColumns_.push_back(c);
      }
      direct_[s] = rowStart_[s + 1] - rowStart_[s];
    } else {
      tasks_[static_cast<std::size_t>(task[s])].push_back(static_cast<int>(s));
    }
  }
  // A task's supernode: its ancestors in its subtree come before those in the top (each ancestor's
  // index is above its descendants', and the top's ancestors of a subtree are above its root).
  for (std::size_t s = 0; s < S; ++s)
    if (!inTop[s]) {
      std::size_t k = rowStart_[s];
      while (k < rowStart_[s + 1] && topIndex_[static_cast<std::size_t>(rows_[k])] < 0) ++k;
      direct_[s] = k - rowStart_[s];
    }
}

SupernodalLdlt::Panel SupernodalLdlt::panel(int s) const {
  const auto k = static_cast<std::size_t>(s);
  Panel p;
  p.first = first_[k];
  p.w = static_cast<std::size_t>(first_[k + 1] - p.first);
  p.T = values_.data() + panelStart_[k];
  p.R = p.T + p.w * p.w;
  p.below = rows_.data() + rowStart_[k];
  p.h = rowStart_[k + 1] - rowStart_[k];
  return p;
}

void SupernodalLdlt::forward(int s, double* y, double* topUpdates) const {
  const auto [a, w, T, R, below, h] = panel(s);
  double* ys = y + a;
  for (std::size_t i = 1; i < w; ++i) ys[i] -= dot(T + i * w, ys, i);
  const std::size_t direct = direct_[static_cast<std::size_t>(s)];
  if (w <= kFixedWidths) {
    kRowsDown[w - 1](R, below, direct, h, ys, y, topUpdates, topIndex_.data());
    return;
  }
  for (std::size_t r = 0; r < direct; ++r) y[below[r]] -= dot(R + r * w, ys, w);
  for (std::size_t r = direct; r < h; ++r)
    topUpdates[topIndex_[static_cast<std::size_t>(below[r])]] += dot(R + r * w, ys, w);
}

void SupernodalLdlt::backward(int s, double* y, double* acc) const {
  const auto [a, w, T, R, below, h] = panel(s);
  double* ys = y + a;
  if (w <= kFixedWidths) {
    kRowsUp[w - 1](R, below, h, y, acc);
  } else {
    std::fill(acc, acc + w, 0.0);
    for (std::size_t r = 0; r < h; ++r) {
      const double* row = R + r * w;
      const double yr = y[below[r]];
      for (std::size_t k = 0; k < w; ++k) acc[k] += row[k] * yr;
    }
  }
  for (std::size_t k = 0; k < w; ++k) ys[k] -= acc[k];
  // Row k of the triangle, from the last: ys[k] is final when it is reached.
  for (std::size_t k = w; k-- > 1;) {
    const double yk = ys[k];
    const double* row = T + k * w;
    for (std::size_t i = 0; i < k; ++i) ys[i] -= row[i] * yk;
  }
}

template <class Fn>
void SupernodalLdlt::forTasks(const Fn& fn) const {
  if (values_.size() < kSerialValues) {
    for (std::size_t t = 0; t < kTasks; ++t) fn(t);
    return;
  }
  parallelChunks(kTasks, 1, [&fn](std::size_t t, std::size_t, std::size_t) { fn(t); });
}

void SupernodalLdlt::solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const {
  const Eigen::Index n = rows();
  if (b.size() != n) fail(ErrorCode::Internal, "SupernodalLdlt: solve of ", b.size(), " entries with a factor of ", n);
  Eigen::VectorXd& y = work_.y;
  if (perm_.empty()) y = b;
  else
    for (Eigen::Index i = 0; i < n; ++i) y[perm_[static_cast<std::size_t>(i)]] = b[i];
  double* yp = y.data();
  // L y' = y: the tasks' subtrees, the top's rows taking their updates in task order, then the top.
  const std::size_t m = topColumns_.size();
  double* updates = work_.updates.data();
  std::fill(work_.updates.begin(), work_.updates.end(), 0.0);
  forTasks([&](std::size_t t) {
    for (const int s : tasks_[t]) forward(s, yp, updates + t * m);
  });
  for (std::size_t t = 0; t < kTasks; ++t)
    for (std::size_t i = 0; i < m; ++i) yp[topColumns_[i]] -= updates[t * m + i];
  for (const int s : top_) forward(s, yp, nullptr);
  y.array() *= dinv_.array();
  // L^T x = y': the top from its last supernode, then the tasks' subtrees (each reads its own rows
  // and the top's, final by then).
  double* acc = work_.acc.data();
  for (auto it = top_.rbegin(); it != top_.rend(); ++it) backward(*it, yp, acc + kTasks * widest_);
  forTasks([&](std::size_t t) {
    for (auto it = tasks_[t].rbegin(); it != tasks_[t].rend(); ++it) backward(*it, yp, acc + t * widest_);
  });
  if (perm_.empty()) {
    x = y;
    return;
  }
  x.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) x[i] = y[perm_[static_cast<std::size_t>(i)]];
}

}  // namespace corofem::detail
