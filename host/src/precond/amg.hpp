// Smoothed-aggregation algebraic multigrid for the co-rotational system, warped by node rotations
// (the "amg" preconditioner of SolverDesc).
//
// Jacobi needs hundreds of PCG iterations on a slender body because the smooth, long-wave modes of
// A = m M + s K_t (bending of the whole body) are barely touched by a diagonal. Multigrid corrects
// them on coarser levels. The hierarchy is made once from the REST operator
// A_0 = m M + s K_0 (K_0 = sum of the linear element stiffnesses), the way SOFA's and Courtecuisse
// et al.'s warped preconditioners reuse a rest factorisation:
//
//   - aggregation: the nodes (level 0) or the aggregates (coarser levels) are grouped greedily, each
//     aggregate a vertex and its unaggregated neighbours in the operator's graph;
//   - near-null space B: the six rigid-body modes of the free dofs (three translations, three
//     rotations about the body's rest bounding-box centre); the tentative prolongator P_t holds, per
//     aggregate, an orthonormal basis of B restricted to the aggregate's dofs (QR), and the coarse
//     level's B is R of that QR;
//   - smoothing of the prolongator: P = (I - omega D^-1 A) P_t, omega = 4 / (3 lambda_max(D^-1 A));
//   - Galerkin coarse operators A_{l+1} = P_l^T A_l P_l, down to a few hundred dofs solved exactly
//     (a sparse LDL^T on the host, its dense inverse on a device).
//
// Each solve applies one symmetric V-cycle: on level 0 Chebyshev smoothing with the CURRENT
// operator (the device's own product) and its 3x3 node blocks B_t (block Jacobi: unlike a point
// diagonal, the blocks turn with the nodes, so the rest bound on the spectrum of B^-1 A holds for
// the turned body), the coarser levels with their point diagonals; the residual restricted through the rest
// hierarchy in each node's rotated frame, r_c = P_0^T W^T r, and the correction prolonged back,
// e = W P_0 e_c, where W = blockdiag(R_n) holds per-node rotations: the rotation of the node's
// level-0 aggregate, by shape matching of its nodes (the rotation of the aggregate's current rigid
// modes: P_t's columns turned with the aggregate). For A_t close to W A_0 W^T (the co-rotational
// assumption) the coarse correction is the rest one seen rotated. (The polar mean of the element
// rotations around each node gave 3 % fewer iterations on the beams of bench_precond; the
// aggregates' need only the positions, a few hundred 3x3 polar decompositions and no element data.)
// The cycle is a fixed symmetric operator within a solve (same Chebyshev polynomial before and
// after, exact coarsest solve), positive definite while the Chebyshev bounds hold, as PCG requires.
#pragma once

#include "model/element.hpp"
#include "model/problem.hpp"
#include "precond/rest_system.hpp"

#include <Eigen/Core>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <utility>
#include <vector>

namespace corofem::detail {

/// One level of the hierarchy below the finest (whose operator is the current one).
struct AmgLevel {
  AmgMatrix A;               ///< the level's rest operator (level 0: A_0 on the free dofs)
  Eigen::VectorXd diagInv;   ///< 1 / diag(A) (1 where the diagonal is 0)
  double lambdaMax = 1.0;    ///< the largest eigenvalue of D^-1 A by 20 power steps, raised by 10 %
  AmgMatrix P;               ///< prolongation from the next level (rows: this level's dofs)
  AmgMatrix Pt;              ///< P^T
  /// The level's rows by vertex: vertex v (level 0: a node with a free dof; coarser: an aggregate
  /// of the level above, one row per near-null-space mode it kept, at most 6; the level solved
  /// directly below a body's level 0 keeps level 0's nodes) holds rows
  /// [vertexStart[v], vertexStart[v + 1]). A device lays the coarse levels out in blocks by it.
  std::vector<int> vertexStart;
};

/// The fine operator of a V-cycle: y = A x on the free dofs, and z = B^-1 r with B the node blocks
/// of A (each node's free dofs; nodeBlocks).
struct AmgFineOperator {
  std::function<void(const Eigen::VectorXd& x, Eigen::VectorXd& y)> apply;
  std::function<void(const Eigen::VectorXd& r, Eigen::VectorXd& z)> blockInverse;
};

/// The node blocks B of A on the free dofs `freeDofs` (each node's free dofs, consecutive) and their
/// inverses; a block whose determinant or diagonal is not positive is replaced by its diagonal
/// (1 where not positive), as the OpenCL device forms them.
std::pair<AmgMatrix, AmgMatrix> nodeBlocks(const AmgMatrix& A, const std::vector<Eigen::Index>& freeDofs);
/// The same of a column-major matrix (the reference backend's assembled one), without a copy.
std::pair<AmgMatrix, AmgMatrix> nodeBlocks(const Eigen::SparseMatrix<double>& A, const std::vector<Eigen::Index>& freeDofs);

class WarpedAmg {
 public:
  /// Builds the hierarchy from the rest operator `A0` on the free dofs `freeDofs` (ascending dof
  /// indices 3 n + c of a body with `nodeCount` nodes at rest positions `rest`, 3N entries);
  /// level 0's Chebyshev bound from `bound` where given (an operator whose spectrum against its
  /// node blocks bounds those the hierarchy will serve), else from A0. Throws Error(Internal) for
  /// inconsistent sizes.
  void build(const AmgMatrix& A0, const std::vector<Eigen::Index>& freeDofs, const Eigen::VectorXd& rest,
             std::size_t nodeCount, const AmgMatrix* bound = nullptr);
  /// Level 0's two spectral bounds, as build() estimates them (each by 20 power steps).
  struct Bounds {
    double fine = 1.0;    ///< the Chebyshev bound on B^-1 A (fineLambdaMax)
    double level0 = 1.0;  ///< lambda_max(D^-1 A_0) (levels()[0].lambdaMax: the prolongator's smoothing)
  };
  /// build() with level 0's bounds given instead of estimated: those of a hierarchy made from the
  /// same operators on a superset of `freeDofs` (taken over by BodyAmg::ensure). They hold here:
  /// A_0 on fewer dofs is a principal submatrix of the larger one, and so are its node blocks and
  /// diagonal, so each Rayleigh quotient v.A v / v.B v it has is one the larger operator has (the
  /// vector with zeros on the dofs dropped), and its largest is at most the larger one's.
  void build(const AmgMatrix& A0, const std::vector<Eigen::Index>& freeDofs, const Eigen::VectorXd& rest,
             std::size_t nodeCount, const Bounds& bounds);
  /// Level 0's bounds as built (the defaults before a build with free dofs).
  Bounds bounds() const;
  /// Whether build() ran since construction or clear() (a body without free dofs has no levels).
  bool built() const { return made_; }
  void clear();

  /// The free dofs it was built on (its level 0's rows).
  const std::vector<Eigen::Index>& builtFreeDofs() const { return freeDofs_; }

  /// The warp from the positions x (3N): each level-0 aggregate's rotation by shape matching
  /// (the rotation nearest to sum_n (x_n - c) (X_n - C)^T over its nodes, c and C their centroids
  /// now and at rest), given to its nodes. Without a call no warp: W = I.
  void setPositions(const Eigen::VectorXd& x);

  /// The level-0 aggregate of each node (-1: none, all its dofs constrained) and each aggregate's
  /// rotation as the last setPositions found it (empty before).
  std::vector<int> nodeAggregates() const;
  const std::vector<Mat3>& aggregateRotations() const { return aggregateRotations_; }
  std::size_t aggregateCount() const { return aggregateNodes_.size(); }
  /// The inverse of the coarsest level's operator as the cycle solves it (dense).
  Eigen::MatrixXd coarsestInverse() const;

  /// z = M^-1 r on the free dofs: one V-cycle with `fine` as level 0's operator.
  void apply(const AmgFineOperator& fine, const Eigen::VectorXd& r, Eigen::VectorXd& z) const;

  /// Level 0's Chebyshev bound on the spectrum of B^-1 A (B the node blocks).
  double fineLambdaMax() const { return fineLambdaMax_; }
  /// The levels' sizes (dofs), finest first, the coarsest (solved directly) last.
  std::vector<Eigen::Index> levelSizes() const;
  const std::vector<AmgLevel>& levels() const { return levels_; }

  /// The Chebyshev polynomial's degree on every level (the number of D^-1 A applications of one
  /// smoothing): 2, the fewest products per converged solve on the beams of bench/bench_precond.
  static constexpr int kChebyshevDegree = 2;

 private:
  void make(const AmgMatrix& A0, const std::vector<Eigen::Index>& freeDofs, const Eigen::VectorXd& rest,
            std::size_t nodeCount, const AmgMatrix* bound, const Bounds* given);
  void cycle(std::size_t level, const Eigen::VectorXd& b, Eigen::VectorXd& x, const AmgFineOperator* fine) const;
  void warp(const Eigen::VectorXd& v, Eigen::VectorXd& out, bool transpose) const;

  bool made_ = false;
  /// lambda_max(B^-1 A) of the rest operator with half its mass coefficient, times 1.1: level 0's
  /// Chebyshev bound. The node blocks turn with their node (B_t = R B_0 R^T where the elements
  /// around it share its rotation), so the current operator's spectrum against its own blocks stays
  /// the rest one's; a point diagonal does not turn, and on a bent slender bar D_t^-1 A_t outgrew
  /// the rest bound, made the cycle indefinite and broke PCG down.
  double fineLambdaMax_ = 1.0;
  std::vector<AmgLevel> levels_;  ///< levels_[0]: rest A_0; the last one is solved directly
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> coarsest_;
  std::vector<Eigen::Index> freeDofs_;
  std::vector<std::vector<std::uint32_t>> aggregateNodes_;  ///< the nodes of each level-0 aggregate
  std::vector<int> nodeAggregate_;        ///< per node: its aggregate, or -1
  std::vector<Mat3> aggregateRotations_;  ///< per aggregate, or empty: no warp
  Eigen::VectorXd rest_;
};

/// A part of a matrix that joined() puts together: a matrix (sparse, or dense with every entry
/// kept), its row i at (*rowMap)[i] where given, else at rowOffset + i, its column j at
/// (*colMap)[j] where given (strictly ascending), else at colOffset + j.
struct MatrixBlock {
  const AmgMatrix* sparse = nullptr;
  const Eigen::MatrixXd* dense = nullptr;
  const std::vector<std::size_t>* rowMap = nullptr;
  const std::vector<std::size_t>* colMap = nullptr;
  std::size_t rowOffset = 0, colOffset = 0;
  Eigen::Index rows() const { return sparse ? sparse->rows() : dense->rows(); }
  std::size_t row(Eigen::Index i) const {
    return rowMap ? (*rowMap)[static_cast<std::size_t>(i)] : rowOffset + static_cast<std::size_t>(i);
  }
  std::size_t col(Eigen::Index j) const {
    return colMap ? (*colMap)[static_cast<std::size_t>(j)] : colOffset + static_cast<std::size_t>(j);
  }
};

/// The `rows` x `cols` matrix of the blocks, as setFromTriplets of their entries would make it
/// (no two blocks share a row, and a block's columns keep their order: every row comes sorted from
/// its one source row), in O(entries) instead of a sort of them. Throws Error(Internal) for an
/// uncompressed sparse block.
AmgMatrix joined(std::size_t rows, std::size_t cols, const std::vector<MatrixBlock>& blocks);

/// A B for row-major A and B, in slices of kProductRows rows of A on the host's threads
/// (parallelChunks): each row is Eigen's product of that row, so the bits do not depend on the
/// slicing or the threads. The Galerkin products of a set-up (about 33 ms of a grab's on the
/// 12,960-tet beam, on one thread).
AmgMatrix sparseProduct(const AmgMatrix& A, const AmgMatrix& B);
constexpr std::size_t kProductRows = 2048;
/// A x in slices of kProductRows rows on the host's threads, each row summed in entry order from 0
/// as Eigen's row-major product sums it: the bits of A * x on any number of threads. The set-up's
/// power iterations (about 17 ms of each build of the 12,960-tet beam's hierarchy, on one thread)
/// and the host V-cycle's products.
Eigen::VectorXd amgProduct(const AmgMatrix& A, const Eigen::VectorXd& x);

/// A body's hierarchy with the coefficients it was made for (precond/rest_system.hpp: made again
/// where the ratio m / s of a solve's operator left the factor-2 window of the one it was made
/// with, or for other free dofs, or after clear(): the material changed; the one it replaces kept
/// as a spare). A set-up after the first assembles nothing (K_0 kept: the assembly was about 60 ms
/// of a grab's 140 on the 12,960-tet beam, docs/performance.md), and a grab's or a pin's hierarchy
/// takes level 0's spectral bounds from the one made for more free dofs at the same time step
/// (ensure). (Keeping the hierarchy of before for a grab, its cycle restricted to the fewer free
/// dofs, was tried: 40 PCG iterations a step instead of 18 on the 12,960-tet beam with its tip
/// held, twice the step time, where the set-up then cost about four steps, now under three;
/// bench_precond's precondGrab.)
class BodyAmg {
 public:
  using Made = detail::Made;
  /// Makes the hierarchy where needed, or takes back the spare. A caller that keeps data derived
  /// from amg() (a device's copies, the warp) refreshes it unless Kept.
  Made ensure(const Problem& p, const std::vector<Eigen::Index>& freeDofs, double massScale, double stiffScale);
  void clear() { pair_.clear(); }
  /// Hierarchies made so far (Made::Built).
  long long builds() const { return builds_; }
  WarpedAmg& amg() { return pair_.now(); }
  const WarpedAmg& amg() const { return pair_.now(); }

 private:
  RestPair<WarpedAmg> pair_;
  KeptStiffness stiffness_;
  long long builds_ = 0;
};

}  // namespace corofem::detail
