// The sparse LDL^T factor of the warped Cholesky's rest operator and its triangular solves
// (z = A_0^-1 t, precond/warped_cholesky.hpp), by supernodes.
//
// A factor of a finite-element operator has runs of consecutive columns whose rows below the run
// are the same: the three dofs of a node, and the wide separators near the root of the elimination
// tree. Such a run is a supernode. Stored as a dense panel (its unit lower triangle, then the rows
// below it, row by row, each as wide as the run) with one row index per panel row, a solve reads one
// index per row of a panel instead of one per entry, and its inner loops run over the panel's width,
// which a CPU vectorises; a column-by-column solve chains each entry's update through memory
// instead (docs/performance.md, "The warped factor's solves by supernodes").
//
// The factorisation works on the same panels (factor()): the symbolic pass finds the elimination
// tree and each column's rows (a column's rows are its own entries' and its children's, less
// itself), the runs are grown greedily (column j joins the run ending at j - 1 where it is the
// run's first row below and its rows below are the run's others), and the numeric pass goes through
// the supernodes in order (children first): a panel's triangle is factored densely (T = L_c L_c^T),
// its rows below solved against it (W = R L_c^-T), and W W^T, the run's contribution to the rows
// below, subtracted from its ancestors' panels block by block (right-looking). The wide separators
// near the root, where most of the arithmetic is, become dense matrix products.
//
// The factorisation and the solves run on the host's threads (util/parallel.hpp). In a Cholesky
// factor's pattern a supernode's rows below are its ancestors in the elimination tree, so disjoint
// subtrees factor and solve apart: factor() splits the tree from its roots, the largest subtree
// first, until none that can be split holds more than 1/kTasks of the panels' values, and deals the
// subtrees to kTasks tasks; the supernodes split off (the top of the tree) are done on one thread.
// - Factorisation: the tasks side by side, each supernode updating the rest of its own task; then,
//   on one thread in supernode order, the tasks' updates of the top and the top's own supernodes.
//   Every panel entry takes its updates in supernode order, as one thread going through the
//   supernodes in order would.
// - Solves: the tasks going down (L) before the top, and coming up (L^T) after it; a task's
//   updates of the top's rows are kept in its own buffer and subtracted in task order.
// The tasks and the order of every sum follow from the matrix and the order (and, inside the dense
// kernels, from Eigen's blocking for the CPU), so the bits do not depend on the number of threads
// or on who runs the tasks.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <cstddef>
#include <vector>

namespace corofem::detail {

class SupernodalLdlt {
 public:
  /// The tasks the subtrees are dealt to (each runs on one thread at a time).
  static constexpr std::size_t kTasks = 4;

  /// Factors A = P^T L D L^T P, L unit lower triangular, D diagonal: `A` symmetric n x n with
  /// both triangles stored (entry (i, j) is read where perm[i] >= perm[j]), `perm` P's indices
  /// ((P b)[perm[i]] = b[i]; empty: P = I). Returns false, the factor left as it was, where a pivot
  /// is not positive and finite (A is not positive definite, to rounding). Throws Error(Internal)
  /// for a matrix that is not square or a permutation that is not one of 0..n-1.
  bool factor(const Eigen::SparseMatrix<double>& A, const Eigen::VectorXi& perm);

  /// x = A^-1 b (x is resized; it may be b). Before a factor(), A is the 0 x 0 matrix. Not to be
  /// called on one object from two threads at once: it keeps its work vectors between calls.
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const;

  Eigen::Index rows() const { return static_cast<Eigen::Index>(dinv_.size()); }
  std::size_t supernodeCount() const { return first_.empty() ? 0 : first_.size() - 1; }
  /// Columns in the top of the tree (solved on one thread).
  std::size_t topColumns() const { return topColumns_.size(); }
  /// Values stored in the panels: the factor's entries, any zeros of the runs, and the triangles'
  /// diagonals and upper halves (kept as zeros for a square layout).
  std::size_t storedValues() const { return values_.size(); }
  /// Entries of L below its diagonal.
  std::size_t factorEntries() const { return entries_; }

 private:
  /// The symbolic factorisation of C (its entries on and below the diagonal, by columns: `Cp`,
  /// `Ci`): the runs, their rows below, L's entries and the panels (zero). Returns each column's
  /// supernode.
  std::vector<int> symbolic(int n, const std::vector<std::size_t>& Cp, const std::vector<int>& Ci);
  /// The panels from the entries of C = P A P^T on and below the diagonal (`Cp`, `Ci`, `Cx` by
  /// columns), factored; false at a pivot that is not positive and finite.
  bool numeric(const std::vector<std::size_t>& Cp, const std::vector<int>& Ci, const std::vector<double>& Cx,
               const std::vector<int>& of);
  /// The tasks and the top from the elimination tree (factor()); `of`: each column's supernode.
  void partition(const std::vector<int>& of);
  /// fn(t) for every task t: on the host's threads, or on the caller where the factor is small.
  template <class Fn>
  void forTasks(const Fn& fn) const;
  /// Supernode s's columns [first, first + w), its w x w triangle T, its h rows below `below` and
  /// their values R (h x w, row by row).
  struct Panel {
    int first;
    std::size_t w;
    const double* T;
    const double* R;
    const int* below;
    std::size_t h;
  };
  Panel panel(int s) const;
  /// Supernode s's share of L y' = y: its triangle, then its rows below (a top row's update added
  /// to topUpdates at its index in topColumns_).
  void forward(int s, double* y, double* topUpdates) const;
  /// Supernode s's share of L^T x = y' (acc: scratch of the widest supernode's width).
  void backward(int s, double* y, double* acc) const;

  std::vector<int> first_;                 ///< supernode s: columns [first_[s], first_[s + 1])
  std::vector<std::size_t> rowStart_;      ///< its rows below the run: rows_[rowStart_[s] ..]
  std::vector<int> rows_;                  ///< ascending within a supernode
  std::vector<std::size_t> panelStart_;    ///< its panel: values_[panelStart_[s] ..], w x w then h x w
  std::vector<double> values_;
  std::size_t widest_ = 0;                 ///< the widest supernode's columns
  std::size_t entries_ = 0;                ///< L's entries below the diagonal
  /// Per supernode in a task: its rows below in that task's subtree, the first `direct_[s]` of them
  /// (the rest are in the top); all of them for a supernode of the top.
  std::vector<std::size_t> direct_;
  std::vector<std::vector<int>> tasks_ = std::vector<std::vector<int>>(kTasks);  ///< their supernodes, ascending
  std::vector<int> top_;                   ///< the top's supernodes, ascending
  std::vector<int> topColumns_;            ///< the top's columns, ascending
  std::vector<int> topIndex_;              ///< per column: its index in topColumns_, or -1
  Eigen::VectorXd dinv_;                   ///< 1 / D
  std::vector<int> perm_;                  ///< empty: no permutation
  /// solve()'s work vectors, kept between calls so that a solve does not allocate them: the
  /// permuted vector, each task's updates of the top's rows, and kTasks + 1 scratch rows of the
  /// widest supernode's width (one a task, the last the top's).
  struct Work {
    Eigen::VectorXd y;
    std::vector<double> updates;
    std::vector<double> acc;
  };
  mutable Work work_;
};

}  // namespace corofem::detail
