// The warped precomputed Cholesky preconditioner ("warped_cholesky" of SolverDesc), after SOFA's
// PrecomputedWarpPreconditioner and Courtecuisse et al. 2010.
//
// The co-rotational tangent is K_t = sum_e R_e K_e R_e^T (Eq. 11). Where the elements around each
// node share one rotation R_n, K_t = W K_0 W^T with W = blockdiag(R_n), and with M lumped (R m I
// R^T = m I) the whole operator is A_t = m M + s K_t = W A_0 W^T, so
//
//   z = M^-1 r = W A_0^-1 W^T r
//
// is its exact inverse. A_0 = m M + s K_0 on the free dofs is the REST operator: it does not change
// while the body moves, so it is factored once (a sparse LDL^T in nested dissection order,
// precond/nested_dissection.hpp, by supernodes on the host's threads, precond/supernodal_ldlt.hpp)
// and each PCG iteration costs two triangular solves (by the same supernodes) and 2 N 3x3 products. Only the
// differences of the element rotations around a node (bending over a node's elements) and the
// strain the co-rotational tangent leaves out are left for PCG to correct: on issue 29's curled
// 12,960-tet beam 6-11 iterations to 1e-6 where Jacobi needs about 600 (bench_warped_cholesky).
//
// W: R_n is the polar rotation of the sum of the rotations of the elements around node n (the
// co-rotational formulation's R_e; a hyperelastic one's polar rotations of F_e; the linear
// formulation has none, W = I). On the free dofs W is block diagonal with one block per node; a
// node with one or two dofs constrained (a slip condition) gets the nearest orthogonal matrix to
// its free dofs' block of R_n (their polar factor), not the block itself: that block turned by 90
// degrees is zero, and W singular would make the preconditioner singular. W stays orthogonal, so
// z = W A_0^-1 W^T r is symmetric positive definite whatever the rotations.
//
// The factor is deterministic (its order depends on the matrix and the rest positions alone, its
// sums on the order and on the dense kernels' blocking for the CPU, and its solves' on the factor,
// not on the threads) and it costs memory: the
// factor of the 12,960-tet beam holds 1.71 M entries (about 16 MB in its panels), and a direct
// factor's fill grows faster than the mesh (docs/performance.md).
#pragma once

#include "model/element.hpp"
#include "model/problem.hpp"
#include "precond/rest_system.hpp"
#include "precond/supernodal_ldlt.hpp"

#include <Eigen/SparseCore>

#include <string>
#include <vector>

namespace corofem::detail {

class WarpedCholesky {
 public:
  /// Factors the rest operator `A0` on the free dofs `freeDofs` (strictly ascending dof indices of
  /// a body at rest positions `rest`, 3N entries). Throws Error(SolveFailed) naming `body` where A0
  /// is singular: a rigid motion of the body on its free dofs costs it no energy (statics of a body
  /// too few fixed nodes hold: the smallest Rayleigh quotient v.A0 v / v.D v over the rigid
  /// motions v, D = diag(A0), below 1e-13; the .cpp has what it is for held and free bodies), a
  /// free dof has no stiffness and no mass (a free node in no element), or a pivot of the factor is
  /// not positive. Error(Internal) for inconsistent sizes.
  void build(const AmgMatrix& A0, const std::vector<Eigen::Index>& freeDofs, const Eigen::VectorXd& rest,
             const std::string& body);
  bool built() const { return built_; }
  const std::vector<Eigen::Index>& builtFreeDofs() const { return freeDofs_; }
  void clear();

  /// The warp W: one rotation per node (rest.size() / 3 of build), or none (W = I).
  void setNodeRotations(std::vector<Mat3> rotations);
  /// z = W A_0^-1 W^T r on the free dofs. Not to be called on one object from two threads at once
  /// (the factor's solves keep their work vectors).
  void apply(const Eigen::VectorXd& r, Eigen::VectorXd& z) const;
  /// Entries of the factor's L below its diagonal.
  Eigen::Index factorEntries() const;

 private:
  void warp(const Eigen::VectorXd& v, Eigen::VectorXd& out, bool transpose) const;

  bool built_ = false;
  std::vector<Eigen::Index> freeDofs_;
  /// The factor and its solves.
  SupernodalLdlt factor_;
  Eigen::Index factorEntries_ = 0;
  /// Per node with a free dof: the node, and its dofs' free indices (-1: constrained).
  struct WarpNode {
    std::size_t node;
    int free[3];
  };
  std::vector<WarpNode> warpNodes_;
  std::size_t nodeCount_ = 0;
  /// Per warp node, its block of W (rows and columns of constrained dofs zero), or empty: W = I.
  std::vector<Mat3> blocks_;
};

/// The warp's node rotations: R_n the polar rotation of the sum of the rotations `elementRotations`
/// of the elements of `mesh` around node n (I for a node in no element).
std::vector<Mat3> nodeRotations(const TetMesh& mesh, const std::vector<Mat3>& elementRotations);

/// A body's factor with the coefficients it was made for (precond/rest_system.hpp: made again
/// where the ratio m / s of a solve's operator left the factor-2 window of the one it was made
/// with, or for other free dofs, or after clear(): the material changed; the one it replaces kept
/// as a spare, so a substep's or a grab's factor costs one factorisation and the return none).
class BodyCholesky {
 public:
  /// Factors where needed, or takes back the spare. Throws as WarpedCholesky::build.
  Made ensure(const Problem& p, const std::vector<Eigen::Index>& freeDofs, double massScale, double stiffScale);
  void clear() { pair_.clear(); }
  /// Factorisations made so far (Made::Built).
  long long builds() const { return builds_; }
  WarpedCholesky& cholesky() { return pair_.now(); }
  const WarpedCholesky& cholesky() const { return pair_.now(); }

 private:
  RestPair<WarpedCholesky> pair_;
  KeptStiffness stiffness_;
  long long builds_ = 0;
};

}  // namespace corofem::detail
